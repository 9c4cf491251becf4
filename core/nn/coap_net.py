"""COAP baseline network (Mihajlovic et al., ECCV 2022): compositional part occupancy.

Same interface as :class:`volsmpl.nn.volsmpl_net.VolumetricSMPLNet`, so :class:`volsmpl.volume.learned.Volume`
can swap the two (``kind``, ``output``, ``config``, ``num_parts``, ``encoder_bf16``, ``encode``,
``decode_dense``, ``decode_pairs``). Architecture, following COAP's released code:

    z_k   = ResnetPointNet(part-k surface samples)                    (latent 128, hidden 128, 4 blocks)
    u     = [x_k (3), inside-box flag (1), one-hot(k) (K), z_k (128)]  query-encoder input
    q     = QueryMLP(u)     widths 256, 256, 256 -> 128, skip (concatenate u again) into layer 2
    o     = OccMLP([x_k, q]) widths 256 x 6 -> 1,      skip (concatenate [x_k, q] again) into layer 3
    occ_k = sigmoid(-o)                                                occupancy probability in [0, 1]

Both MLPs are IGR-style ``ImplicitNet``s as in COAP: with ``dims = [d_in, *hidden, d_out]`` the layer
feeding a skip layer outputs ``dims[l] - d_in`` features, so the skip layer reads exactly
``dims[l]`` columns ``[h, u] / sqrt(2)``; the activation is Softplus(beta=100) (``softplus_beta``;
0 selects ReLU). The decoder uses IGR's geometric initialisation (radius 1) and COAP's sign
convention ``occupancy = sigmoid(-o)`` (the decoder output is a negated logit, SDF-like: negative
inside). Note COAP's actual code layer widths differ from the nominal "3 x 256": at K=16 the
query-encoder input has 148 columns, so its layer 1 outputs 256 - 148 = 108 features.

Folding (exact re-association, as nbw.py does for z): one-hot(k) and z_k are constant per
(body, part), and the inside flag is 1 for every pair (pairs are only formed inside boxes), so for the
query-encoder layers that read u (layer 0 and the skip layers), with W = [W_pt | W_flag | W_hot | W_z]
split by input columns and s = 1 (layer 0) or 1/sqrt(2) (skip layers),

    s W [h; x; flag; onehot_k; z_k] + b  =  s W_pt [h; x] + (b + s (W_flag flag + W_hot[:, k] + W_z z_k)).

:meth:`CoapNet.encode` returns these per-(body, part) biases; per point only the x (and h)
columns are multiplied. ``tests/nn/test_coap_net.py`` checks this against the naive concatenation.
The decoder weights are shared by all parts, so the pair path needs no grouping: each pair gathers
its (body, part) bias rows and all pairs go through the same matmuls.

Parameter count at K=16 (defaults): 0.840M (encoder 0.346M + query encoder 0.165M + decoder 0.329M).
FLOPs per pair (folded, flag folded): 835,072 at K=16 (query encoder 179,200 + decoder 655,872),
~18.6x the 44,928 of the VolumetricSMPL NBW decoder. Measured (CPU, 1 thread, no grad, B=1, K=16,
100k pairs): ~50-70k pairs/s vs ~850k pairs/s for VolumetricSMPLNet.decode_pairs; Softplus(100) costs
~25% over ReLU.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import List, NamedTuple, Optional, Sequence, Tuple

import torch
from torch import nn
from torch.nn import functional as F

from .config import JsonConfig
from .nbw import check_code_parts, check_part_subset, count_parameters
from .pairs import check_pairs
from .pointnet import ResnetPointNet

_INV_SQRT2 = 1.0 / math.sqrt(2.0)


@dataclass
class CoapConfig(JsonConfig):
    """Hyperparameters of the COAP network (defaults: COAP's released model).

    Attributes:
        model: always "coap"; stored in checkpoints so they say which model they hold.
        latent_dim: part code size (128).
        encoder_hidden: ResNet-PointNet width (128).
        encoder_blocks: ResNet-PointNet blocks (4).
        n_surface_samples: surface points per part fed to the encoder (1000).
        encoder_draws: sets of n_surface_samples per part whose codes are averaged (1; VolumeConfig's).
        box_padding: relative padding of the part boxes (COAP: 1.125 x the tight box).
        query_dims: hidden widths of the query encoder ((256, 256, 256)).
        query_skip: query-encoder layers that read [h, u] / sqrt(2) ((2,)).
        query_out: query feature size (128).
        decoder_dims: hidden widths of the occupancy decoder ((256,) * 6).
        decoder_skip: decoder layers that read [h, x, q] / sqrt(2) ((3,)).
        level_set: occupancy level of the surface (0.5).
        softplus_beta: activation Softplus(beta) (COAP/IGR: 100); 0 selects ReLU.
        geometric_init: IGR geometric initialisation of the decoder (COAP: True).
        geometric_radius: radius of the initial sphere of the geometric initialisation (1.0).
    """

    model: str = "coap"
    latent_dim: int = 128
    encoder_hidden: int = 128
    encoder_blocks: int = 4
    n_surface_samples: int = 1000
    encoder_draws: int = 1
    box_padding: float = 0.125
    query_dims: Tuple[int, ...] = (256, 256, 256)
    query_skip: Tuple[int, ...] = (2,)
    query_out: int = 128
    decoder_dims: Tuple[int, ...] = (256,) * 6
    decoder_skip: Tuple[int, ...] = (3,)
    level_set: float = 0.5
    softplus_beta: float = 100.0
    geometric_init: bool = True
    geometric_radius: float = 1.0

    def __post_init__(self):
        if self.model != "coap":
            raise ValueError(f"CoapConfig.model must be 'coap', got {self.model!r}")
        for name in ("query_dims", "query_skip", "decoder_dims", "decoder_skip"):
            setattr(self, name, tuple(int(v) for v in getattr(self, name)))
        for name in ("latent_dim", "encoder_hidden", "encoder_blocks", "n_surface_samples", "encoder_draws",
                     "query_out"):
            v = getattr(self, name)
            if not isinstance(v, int) or isinstance(v, bool) or v < 1:
                raise ValueError(f"CoapConfig.{name} must be a positive integer, got {v!r}")
        for name in ("query_dims", "decoder_dims"):
            dims = getattr(self, name)
            if len(dims) < 1 or any(d < 1 for d in dims):
                raise ValueError(f"CoapConfig.{name} must be a non-empty tuple of positive widths, got {dims}")
        for dims_name, skip_name in (("query_dims", "query_skip"), ("decoder_dims", "decoder_skip")):
            n = len(getattr(self, dims_name))
            for s in getattr(self, skip_name):
                if not 1 <= s <= n:
                    raise ValueError(f"CoapConfig.{skip_name} entry {s} is out of range: skips go into "
                                     f"layers 1..{n} ({dims_name} has {n} hidden layers)")
        self.box_padding = float(self.box_padding)
        if not self.box_padding >= 0.0:
            raise ValueError(f"CoapConfig.box_padding must be >= 0, got {self.box_padding!r}")
        self.level_set = float(self.level_set)
        if not 0.0 < self.level_set < 1.0:
            raise ValueError(f"CoapConfig.level_set must lie in (0, 1), got {self.level_set!r}")
        self.softplus_beta = float(self.softplus_beta)
        if not self.softplus_beta >= 0.0:
            raise ValueError(f"CoapConfig.softplus_beta must be >= 0 (0 = ReLU), got {self.softplus_beta!r}")
        self.geometric_init = bool(self.geometric_init)
        self.geometric_radius = float(self.geometric_radius)



class CoapCode(NamedTuple):
    """Encoding of B bodies.

    Attributes:
        z: (B, K, latent) part codes.
        biases: one tensor per query-encoder layer that reads the input u (layer 0, then the skip
            layers in order), (B, K, out_l) = b + s (W_hot[:, k] + W_z z_k); the inside flag is
            NOT folded in (added per call: 1 for pairs, per point on the dense path).
        parts: None for all K parts; else (K',) int64 ids of the part subset the code is for.
    """
    z: torch.Tensor
    biases: Tuple[torch.Tensor, ...]
    parts: Optional[torch.Tensor] = None


def _igr_shapes(d_in: int, dims: Sequence[int], d_out: int, skips: Sequence[int]) -> List[Tuple[int, int]]:
    """(in, out) of the linear layers of an IGR ImplicitNet: the layer feeding a skip layer outputs
    dims[l] - d_in features, so the skip layer reads [h, u] with exactly dims[l] columns."""
    full = [d_in, *dims, d_out]
    shapes = []
    for l in range(len(full) - 1):
        out = full[l + 1] - d_in if (l + 1) in skips else full[l + 1]
        shapes.append((full[l], out))
    return shapes


class CoapNet(nn.Module):
    """ResNet-PointNet part encoder + COAP query encoder + occupancy decoder.

    Args:
        num_parts: K.
        config: CoapConfig (COAP defaults).
    """

    kind = "coap"
    output = "occupancy"
    refiner = None  # no learned code refinement (volsmpl.nn.code_refiner) in this model
    TILE_ROWS = 2048  # rows per cache tile on the no-grad path (1 CPU thread, 100k pairs: ~1.4x faster than untiled)

    def __init__(self, num_parts: int, config: Optional[CoapConfig] = None):
        super().__init__()
        self.config = config or CoapConfig()
        if not isinstance(self.config, CoapConfig):
            raise TypeError(f"CoapNet expects a CoapConfig, got {type(self.config).__name__}")
        if int(num_parts) < 1:
            raise ValueError(f"CoapNet needs num_parts >= 1, got {num_parts}")
        cfg = self.config
        self.num_parts = K = int(num_parts)
        self.query_in = 3 + 1 + K + cfg.latent_dim               # u = [x, flag, one-hot, z]
        self.decoder_in = 3 + cfg.query_out                      # v = [x, q]
        self.query_skip = tuple(sorted(set(cfg.query_skip)))
        self.decoder_skip = tuple(sorted(set(cfg.decoder_skip)))
        for name, d_in, dims, skips in (("query", self.query_in, cfg.query_dims, self.query_skip),
                                        ("decoder", self.decoder_in, cfg.decoder_dims, self.decoder_skip)):
            for s in skips:
                if dims[s - 1] <= d_in:
                    raise ValueError(
                        f"CoapNet {name} skip into layer {s} needs width {name}_dims[{s - 1}]={dims[s - 1]} "
                        f"> input size {d_in} (IGR layout: the previous layer outputs width - input); "
                        f"with K={K} parts widen {name}_dims or use fewer parts/latent dims")

        self.encoder = ResnetPointNet(cfg.latent_dim, cfg.encoder_hidden, cfg.encoder_blocks)
        self.query_layers = nn.ModuleList(
            nn.Linear(i, o) for i, o in _igr_shapes(self.query_in, cfg.query_dims, cfg.query_out, self.query_skip))
        self.decoder_layers = nn.ModuleList(
            nn.Linear(i, o) for i, o in _igr_shapes(self.decoder_in, cfg.decoder_dims, 1, self.decoder_skip))
        if cfg.geometric_init:
            self._geometric_init(cfg.geometric_radius)
        # bfloat16 autocast of the PointNet encoder (float32 inputs only), as in VolumetricSMPLNet.
        self.encoder_bf16 = False

    @torch.no_grad()
    def _geometric_init(self, radius: float) -> None:
        """IGR geometric initialisation of the decoder: output ~ |v| - radius at start."""
        last = len(self.decoder_layers) - 1
        for l, lin in enumerate(self.decoder_layers):
            if l == last:
                lin.weight.normal_(math.sqrt(math.pi) / math.sqrt(lin.in_features), 1e-5)
                lin.bias.fill_(-radius)
            else:
                lin.weight.normal_(0.0, math.sqrt(2.0) / math.sqrt(lin.out_features))
                lin.bias.zero_()

    # ------------------------------------------------------------------ encoding
    def _act(self, h: torch.Tensor) -> torch.Tensor:
        beta = self.config.softplus_beta
        return torch.relu(h) if beta == 0.0 else F.softplus(h, beta=beta)

    def _reads_input(self, l: int) -> bool:
        return l == 0 or l in self.query_skip

    def _scale(self, l: int) -> float:
        return 1.0 if l == 0 else _INV_SQRT2

    def _pt_cols(self, l: int) -> int:
        """Columns before [flag, one-hot, z] in query layer l's input: x (layer 0) or [h, x]."""
        lin = self.query_layers[l]
        return 3 if l == 0 else lin.in_features - self.query_in + 3

    def fold(self, z: torch.Tensor, parts: Optional[torch.Tensor] = None) -> CoapCode:
        """Per-(body, part) folded biases of the input-reading query layers.

        Args:
            z: (B, K, latent) part codes; with parts (K',) int64 ids, (B, K', latent) codes of those parts.
        Returns:
            :class:`CoapCode` with biases (B, K, out_l) = b + s (W_hot[:, k] + W_z z_k).
        """
        L = self.config.latent_dim
        K = self.num_parts if parts is None else check_part_subset(parts, self.num_parts)
        if z.dim() != 3 or z.shape[1] != K or z.shape[2] != L:
            raise ValueError(f"CoapNet expects part codes z of shape (B, K={K}, {L}), got {tuple(z.shape)}")
        biases = []
        for l, lin in enumerate(self.query_layers):
            if not self._reads_input(l):
                continue
            c = self._pt_cols(l) + 1                               # first one-hot column
            W_hot = lin.weight[:, c:c + self.num_parts]             # (out, K)
            if parts is not None:
                W_hot = W_hot[:, parts]
            W_z = lin.weight[:, c + self.num_parts:]                # (out, latent)
            s = self._scale(l)
            biases.append(lin.bias + s * (W_hot.t() + z @ W_z.t()))  # (B, K, out)
        return CoapCode(z, tuple(biases), parts)

    def code_from_z(self, z: torch.Tensor, parts: Optional[torch.Tensor] = None) -> CoapCode:
        """The CoapCode of given codes z (B, K', latent) of `parts` (None: all K): `fold`."""
        return self.fold(z, parts)

    def encode(self, local_surface: torch.Tensor, parts: Optional[torch.Tensor] = None, draws: int = 1) -> CoapCode:
        """local_surface (B, K, P, 3) part surface samples in part frames -> CoapCode: `code_from_z(encode_z(...))`.

        parts: (K',) int64 ids when local_surface holds only those parts (B, K', P, 3).
        draws: the P samples are `draws` sets, and each part's code is the mean of theirs
        (ResnetPointNet.encode_parts)."""
        return self.code_from_z(self.encode_z(local_surface, parts, draws), parts)

    def encode_z(self, local_surface: torch.Tensor, parts: Optional[torch.Tensor] = None, draws: int = 1) -> torch.Tensor:
        """The codes z (B, K', latent) alone, as `encode` makes them (no biases folded)."""
        K = self.num_parts if parts is None else check_part_subset(parts, self.num_parts)
        if local_surface.dim() != 4 or local_surface.shape[1] != K or local_surface.shape[-1] != 3:
            raise ValueError(f"CoapNet.encode expects local_surface of shape (B, K={K}, P, 3), "
                             f"got {tuple(local_surface.shape)}")
        return self.encoder.encode_parts(local_surface, draws, self.encoder_bf16)

    # ------------------------------------------------------------------ decoding core
    def _check_code(self, code: CoapCode) -> Tuple[int, int]:
        n_in = sum(1 for l in range(len(self.query_layers)) if self._reads_input(l))
        if not isinstance(code, CoapCode) or len(code.biases) != n_in:
            raise TypeError("CoapNet decoding expects the CoapCode returned by CoapNet.encode/fold of this model")
        B, K = code.z.shape[:2]
        check_code_parts(K, self.num_parts, code.parts, "the code's latents", "this network")
        return B, K

    def _tables(self, code: CoapCode, with_flag_column: bool) -> List[torch.Tensor]:
        """(B*K, out_l) bias tables; the flag (= 1) is folded in unless it stays a per-point column."""
        tabs, i = [], 0
        for l, lin in enumerate(self.query_layers):
            if not self._reads_input(l):
                continue
            b = code.biases[i]
            i += 1
            if not with_flag_column:
                b = b + self._scale(l) * lin.weight[:, self._pt_cols(l)]
            tabs.append(b.reshape(-1, b.shape[-1]))
        return tabs

    def _rows(self, x: torch.Tensor, group: torch.Tensor, tabs: List[torch.Tensor],
              flag: Optional[torch.Tensor]) -> torch.Tensor:
        """Query encoder + decoder on R rows.

        Args:
            x: (R, 3) points in their part frames.
            group: (R,) int64 row of ``tabs`` (body * K + part).
            tabs: bias tables from :meth:`_tables`.
            flag: (R, 1) inside flag as a per-point column, or None when folded into ``tabs``.
        Returns:
            (R,) decoder outputs o (occupancy = sigmoid(-o)).
        """
        xu = x if flag is None else torch.cat([x, flag], dim=-1)   # per-point columns of u
        p = xu.shape[1]
        h, t = None, 0
        nq = len(self.query_layers)
        for l, lin in enumerate(self.query_layers):
            W = lin.weight
            if l == 0:
                h = torch.addmm(tabs[0].index_select(0, group), xu, W[:, :p].t())
                t = 1
            elif l in self.query_skip:
                hw = h.shape[1]
                s = _INV_SQRT2
                b = tabs[t].index_select(0, group)
                t += 1
                h = torch.addmm(torch.addmm(b, h, W[:, :hw].t(), alpha=s), xu, W[:, hw:hw + p].t(), alpha=s)
            else:
                h = torch.addmm(lin.bias, h, W.t())
            if l < nq - 1:
                h = self._act(h)
        q = h                                                       # (R, query_out)
        nd = len(self.decoder_layers)
        for l, lin in enumerate(self.decoder_layers):
            W = lin.weight
            if l == 0:
                h = torch.addmm(torch.addmm(lin.bias, x, W[:, :3].t()), q, W[:, 3:].t())
            elif l in self.decoder_skip:
                hw = h.shape[1]
                s = _INV_SQRT2
                h = torch.addmm(lin.bias, h, W[:, :hw].t(), alpha=s)
                h = torch.addmm(h, x, W[:, hw:hw + 3].t(), alpha=s)
                h = torch.addmm(h, q, W[:, hw + 3:].t(), alpha=s)
            else:
                h = torch.addmm(lin.bias, h, W.t())
            if l < nd - 1:
                h = self._act(h)
        return h.squeeze(-1)

    def _run(self, x: torch.Tensor, group: torch.Tensor, tabs: List[torch.Tensor],
             flag: Optional[torch.Tensor]) -> torch.Tensor:
        """:meth:`_rows` then sigmoid(-o); tiled over rows when no gradient is needed on the CPU (a GPU gains
        nothing from cache tiles and pays a launch per tile)."""
        R = x.shape[0]
        needs_grad = torch.is_grad_enabled() and (
            x.requires_grad or any(t.requires_grad for t in tabs) or any(p.requires_grad for p in self.parameters()))
        if needs_grad or self.TILE_ROWS is None or R <= self.TILE_ROWS or x.device.type != "cpu":
            return torch.sigmoid(-self._rows(x, group, tabs, flag))
        out = x.new_empty(R)
        for s in range(0, R, self.TILE_ROWS):
            e = min(R, s + self.TILE_ROWS)
            out[s:e] = self._rows(x[s:e], group[s:e], tabs, None if flag is None else flag[s:e])
        return torch.sigmoid_(out.neg_())

    # ------------------------------------------------------------------ public decoding
    def decode_dense(self, x_local: torch.Tensor, code: CoapCode,
                     inside: Optional[torch.Tensor] = None) -> torch.Tensor:
        """Every part on every point (not masked by boxes; the Volume masks).

        Args:
            x_local: (B, K, N, 3) points in each part's frame.
            code: from :meth:`encode` for the same B bodies.
            inside: optional (B, K, N) bool/float inside-box flag fed to the query encoder; 1 if None.
        Returns:
            (B, K, N) per-part occupancy probabilities in [0, 1].
        """
        B, K = self._check_code(code)
        if x_local.dim() != 4 or tuple(x_local.shape[:2]) != (B, K) or x_local.shape[-1] != 3:
            raise ValueError(f"decode_dense expects x_local of shape (B={B}, K={K}, N, 3), got {tuple(x_local.shape)}")
        N = x_local.shape[2]
        flag = None
        if inside is not None:
            if tuple(inside.shape) != (B, K, N):
                raise ValueError(f"decode_dense expects inside of shape (B={B}, K={K}, N={N}), got {tuple(inside.shape)}")
            flag = inside.to(x_local.dtype).reshape(-1, 1)
        group = torch.arange(B * K, device=x_local.device).repeat_interleave(N)
        out = self._run(x_local.reshape(-1, 3), group, self._tables(code, flag is not None), flag)
        return out.reshape(B, K, N)

    def decode_pairs(self, x_local: torch.Tensor, body_idx: torch.Tensor, part_idx: torch.Tensor,
                     code: CoapCode) -> torch.Tensor:
        """Each point with its own (body, part) only, inside flag 1 (pairs lie inside part boxes).

        The decoder weights are shared by all parts, so pairs are not grouped: each pair gathers its
        (body, part) folded bias rows and all pairs share the matmuls. Equals ``decode_dense`` (with
        inside = 1) on the same pairs; differentiable w.r.t. ``x_local`` and (through ``code``) z.

        Args:
            x_local: (M, 3) points, each in the frame of its part.
            body_idx: (M,) int64 body index in [0, B).
            part_idx: (M,) int64 part index in [0, K).
            code: from :meth:`encode`.
        Returns:
            (M,) occupancy probabilities in [0, 1].
        """
        B, K = self._check_code(code)
        group = check_pairs(x_local, body_idx, part_idx, B, K)
        if x_local.shape[0] == 0:
            return x_local.sum(-1) + code.z.sum() * 0               # (0,), keeps the graph
        return self._run(x_local, group, self._tables(code, False), None)

    # ------------------------------------------------------------------ costs
    def set_tile_rows(self, rows: int | None) -> None:
        """Rows per cache tile of the no-grad path on the CPU; None: no tiles (benchmarks of one-pass evaluation)."""
        self.TILE_ROWS = None if rows is None else int(rows)

    def flops_per_pair(self) -> int:
        """2 x multiply-accumulates of one pair through query encoder + decoder, after folding
        (one-hot, z and the inside flag folded into biases)."""
        macs = 0
        for l, lin in enumerate(self.query_layers):
            cols = self._pt_cols(l) if self._reads_input(l) else lin.in_features
            macs += lin.out_features * cols
        macs += sum(lin.out_features * lin.in_features for lin in self.decoder_layers)
        return 2 * macs

    def num_parameters(self) -> int:
        """Total number of parameters (encoder + query encoder + decoder)."""
        return count_parameters(self)

    def extra_repr(self) -> str:
        return (f"num_parts={self.num_parts}, query_in={self.query_in}, decoder_in={self.decoder_in}, "
                f"softplus_beta={self.config.softplus_beta}")
