"""The VolumetricSMPL network: shared ResNet-PointNet part encoder + NBW-generated SDF decoders, and optionally a
learned refinement of the encoder's codes (`refiner`, VolumeConfig.refiner_iters; volsmpl.nn.code_refiner).

Body-agnostic: K (number of parts) comes from the body's partition, the rest from VolumeConfig.
"""
from __future__ import annotations

from typing import NamedTuple

import torch
from torch import nn

from .code_refiner import LearnedCodeRefiner
from .config import VolumeConfig
from .nbw import NBWDecoder, NBWWeights
from .pointnet import ResnetPointNet


class PartCode(NamedTuple):
    """Encoding of B bodies: z (B, K, latent) and the decoder weights generated from it."""

    z: torch.Tensor
    weights: NBWWeights


class VolumetricSMPLNet(nn.Module):
    """Encoder + NBW decoder.

    Args:
        num_parts: K.
        config: VolumeConfig (paper defaults).
    """

    kind = "volsmpl"
    output = "sdf"

    def __init__(self, num_parts: int, config: VolumeConfig | None = None):
        super().__init__()
        self.config = config or VolumeConfig()
        self.num_parts = num_parts
        self.encoder = ResnetPointNet.from_config(self.config)
        self.decoder = NBWDecoder.from_config(self.config, num_parts, share_shapes=self.config.nbw_shared_shapes)
        c = self.config
        self.refiner = (LearnedCodeRefiner(num_parts, c.latent_dim, c.refiner_hidden, c.refiner_blocks, c.refiner_iters)
                        if c.refiner_iters else None)   # applied by the volume, which has the refinement points
        # bfloat16 autocast of the PointNet encoder (float32 inputs only): ~3x faster on CPUs with
        # AVX512-BF16; used for training throughput, off by default (inference stays float32).
        self.encoder_bf16 = False

    def encode(self, local_surface: torch.Tensor, parts: torch.Tensor | None = None, draws: int = 1) -> PartCode:
        """local_surface (B, K, P, 3) part surface samples in part frames -> PartCode: `code_from_z(encode_z(...))`.

        parts: (K',) int64 ids when local_surface holds only those parts (B, K', P, 3); the code is then for them.
        draws: the P samples are `draws` sets, and z_k is the mean of their codes (ResnetPointNet.encode_parts)."""
        return self.code_from_z(self.encode_z(local_surface, parts, draws), parts)

    def encode_z(self, local_surface: torch.Tensor, parts: torch.Tensor | None = None, draws: int = 1) -> torch.Tensor:
        """The codes z (B, K', latent) alone, as `encode` makes them (no decoder weights generated)."""
        return self.encoder.encode_parts(local_surface, draws, self.encoder_bf16)

    def code_from_z(self, z: torch.Tensor, parts: torch.Tensor | None = None) -> PartCode:
        """The PartCode of given codes z (B, K', latent) of `parts` (None: all K): their generated decoder weights."""
        return PartCode(z, self.decoder.generate(z, parts))

    def decode_dense(self, x_local: torch.Tensor, code: PartCode) -> torch.Tensor:
        """x_local (B, K, N, 3) -> (B, K, N): every part's decoder on every point."""
        return self.decoder.decode_dense(x_local, code.weights)

    def decode_pairs(self, x_local: torch.Tensor, body_idx: torch.Tensor, part_idx: torch.Tensor, code: PartCode,
                     counts_host: list | None = None, group_sorted: bool = False) -> torch.Tensor:
        """x_local (M, 3) in the frame of part part_idx of body body_idx -> (M,); counts_host: pairs per (body,
        part) group when the caller holds them (NBWDecoder.decode_pairs: then no host sync); group_sorted: the
        caller guarantees the pairs come sorted by (body, part) (no sort)."""
        return self.decoder.decode_pairs(x_local, body_idx, part_idx, code.weights, counts_host=counts_host,
                                         group_sorted=group_sorted)

    def grouped_supported(self, dtype: torch.dtype, device=None) -> bool:
        """Whether `decode_grouped` runs in `dtype` on `device` (volsmpl.nn.grouped)."""
        return self.decoder.grouped_supported(dtype, device)

    def grouped_matrices(self, code: PartCode):
        """Per-group layer matrices of a code for `decode_grouped` (once per encoding)."""
        return self.decoder.grouped_matrices(code.weights)

    def decode_grouped(self, x_local: torch.Tensor, offs: torch.Tensor, code: PartCode, mats=None,
                       compute_dtype=None) -> torch.Tensor:
        """x_local (M, 3) sorted by group body * K' + part, offs (B*K',) int32 cumulative sizes -> (M,);
        compute_dtype: the layers' dtype (NBWDecoder.decode_grouped)."""
        return self.decoder.decode_grouped(x_local, offs, code.weights, mats, compute_dtype)

    def flops_per_pair(self) -> int:
        """FLOPs of one (point, part) decoder evaluation (the NBW decoder's)."""
        return self.decoder.flops_per_pair()

    def set_tile_rows(self, rows: int | None) -> None:
        """Rows per cache tile of the no-grad pair path on the CPU; None: no tiles, the batched form of the GPU
        (benchmarks of one-pass evaluation)."""
        self.decoder.TILE_ROWS = None if rows is None else int(rows)
