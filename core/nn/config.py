"""Hyperparameters of the VolumetricSMPL network (paper Sec. 3 and supplementary A.1).

The defaults are the paper's values; a :class:`VolumeConfig` is stored in every checkpoint
(``to_dict``) and rebuilt on load (``from_dict``).
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any, Dict, Tuple


class JsonConfig:
    """to_dict/from_dict for config dataclasses stored in checkpoints: tuples become lists, missing keys
    take the defaults, unknown keys are an error naming the valid ones."""

    def to_dict(self) -> Dict[str, Any]:
        """JSON-safe dict (tuples become lists)."""
        return {k: list(v) if isinstance(v, tuple) else v for k, v in dataclasses.asdict(self).items()}

    @classmethod
    def from_dict(cls, d: Dict[str, Any]):
        """Inverse of :meth:`to_dict`."""
        if not isinstance(d, dict):
            raise TypeError(f"{cls.__name__}.from_dict expects a dict, got {type(d).__name__}")
        known = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(d) - known)
        if unknown:
            raise ValueError(
                f"unknown {cls.__name__} key(s) {unknown}; valid keys are {sorted(known)}. "
                "The config was probably written by a different volsmpl version or for another model: "
                "remove these keys or upgrade volsmpl.")
        return cls(**d)


@dataclass
class VolumeConfig(JsonConfig):
    """Architecture of encoder + Neural Blend Weights (NBW) + SDF decoder.

    Attributes:
        latent_dim: size of the per-part shape code z_k (A.1: 128).
        encoder_hidden: width of the shared ResNet-PointNet encoder (A.1: 128).
        encoder_blocks: number of ResNet blocks in the encoder (A.1: 4).
        n_surface_samples: points sampled per body part fed to the encoder (A.1: 1k).
        encoder_draws: sets of n_surface_samples per part, each encoded alone; z_k is the mean of their codes
            (`Partition.set_draws`; not in the paper: 1, the default, is its single set). A set's code varies
            with where its samples fell, and the SDF with it; the mean of several varies less, at the cost of
            as many encoder passes (measured in docs/encoder_draws.md).
        decoder_hidden: width of the SDF decoder (A.1: 64).
        decoder_layers: number of linear layers in the decoder, output layer included (A.1: 7).
        skip_layers: indices of decoder layers whose input is concatenated with the decoder
            input [gamma(x_k), z_k] (A.1: the 3rd layer).
        pe_levels: positional-encoding frequency levels of the query point (A.1: 2).
        nbw_rank: number R of blended shape matrices per layer (Sec. 3.3: 80).
        box_padding: relative padding of each part's bounding box (Sec. 3.1: 12.5%).
        nbw_shared_shapes: one set of R shape matrices per layer shared by all parts (blended with
            part-specific coefficients v_k from z_k). True reproduces the paper's parameter count
            (4.0M at R=80, Table 2: ~40k parameters per unit of R); False gives every part its own
            R matrices (K times more parameters, ~47M at K=15).
        normalize_parts: feed the encoder and the decoders part-frame coordinates mapped by the similarity
            that takes the part's padded box into [-1, 1]^3 (longest side), and scale the decoder output
            back to metres (`boxes.part_normalization`). Not in the paper (its x_k is the rigid part-frame
            point: False, the default). A 64-wide decoder reading a hand's +-5 cm coordinates must first grow
            its weights ~20x; measured from scratch (batch 2, 250 steps, same data, held-out batch of 4
            bodies): MSE 1.06e-4 vs 1.79e-4, wrong signs 23.0 % vs 27.7 %, IoU 0.59 vs 0.54.
        refiner_iters: passes of the learned code refinement after the encoder (`volsmpl.nn.code_refiner`; not in
            the paper: 0, the default, is its encoder alone). Each pass corrects the part codes from the gradient of
            the part's refinement loss and a PointNet summary of its decoder's residuals at its own surface points.
        refiner_hidden: width of the refiner's residual PointNet.
        refiner_blocks: ResNet blocks of the refiner's residual PointNet.
    """

    latent_dim: int = 128
    encoder_hidden: int = 128
    encoder_blocks: int = 4
    n_surface_samples: int = 1000
    encoder_draws: int = 1
    decoder_hidden: int = 64
    decoder_layers: int = 7
    skip_layers: Tuple[int, ...] = (3,)
    pe_levels: int = 2
    nbw_rank: int = 80
    box_padding: float = 0.125
    nbw_shared_shapes: bool = True
    normalize_parts: bool = False
    refiner_iters: int = 0
    refiner_hidden: int = 64
    refiner_blocks: int = 3

    def __post_init__(self):
        self.skip_layers = tuple(int(s) for s in self.skip_layers)
        positive = ("latent_dim", "encoder_hidden", "encoder_blocks", "n_surface_samples", "encoder_draws",
                    "decoder_hidden", "decoder_layers", "refiner_hidden", "refiner_blocks")
        for name in positive:
            v = getattr(self, name)
            if not isinstance(v, int) or isinstance(v, bool) or v < 1:
                raise ValueError(f"VolumeConfig.{name} must be a positive integer, got {v!r}")
        for name in ("pe_levels", "nbw_rank", "refiner_iters"):
            v = getattr(self, name)
            if not isinstance(v, int) or isinstance(v, bool) or v < 0:
                raise ValueError(f"VolumeConfig.{name} must be a non-negative integer, got {v!r}")
        for s in self.skip_layers:
            if not 0 < s < self.decoder_layers:
                raise ValueError(
                    f"VolumeConfig.skip_layers entry {s} is out of range: skip connections go into "
                    f"layers 1..{self.decoder_layers - 1} (decoder_layers={self.decoder_layers})")
        if not float(self.box_padding) >= 0.0:
            raise ValueError(f"VolumeConfig.box_padding must be >= 0, got {self.box_padding!r}")
        self.box_padding = float(self.box_padding)
