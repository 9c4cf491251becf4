"""Neural building blocks of VolumetricSMPL: encoder, positional encoding, NBW decoder, box SDF, learned code
refinement."""
from .analytic import box_sdf, transform_points, union_box_sdf
from .code_refiner import LearnedCodeRefiner, refinement_losses
from .config import VolumeConfig
from .nbw import NBWDecoder, NBWWeights, count_parameters
from .pairs import PairLayout, default_chunk, group_pairs
from .pointnet import ResnetBlockFC, ResnetPointNet
from .posenc import PositionalEncoding, positional_encoding, posenc_dim

__all__ = [
    "VolumeConfig",
    "ResnetPointNet", "ResnetBlockFC", "LearnedCodeRefiner", "refinement_losses",
    "PositionalEncoding", "positional_encoding", "posenc_dim",
    "NBWDecoder", "NBWWeights", "PairLayout", "group_pairs", "default_chunk", "count_parameters",
    "box_sdf", "union_box_sdf", "transform_points",
]
