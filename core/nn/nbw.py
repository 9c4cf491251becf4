"""Neural Blend Weights (NBW) generator and the narrow SDF decoder it drives (paper Sec. 3.3, A.1).

For every decoder layer l the weight of body part k is blended from a base matrix and R
part-specific shape matrices, with coefficients predicted from the part's latent code z_k:

    v_k^l      = Linear_l(z_k)                                   in R^R
    W_k^l      = W^l + sum_r v_k^l[r] * S_k^l[r]                 (out_l, in_l)
    phi_l(h)   = relu(W_k^l h + b^l)                             (identity on the last layer)

The decoder of part k maps the decoder input u = [gamma(x_k), z_k] to a signed distance; layer 0
reads u and every skip layer reads [h, u] (DeepSDF/COAP-style concatenation).

Latent folding (an exact re-association, used by every decode path here): z_k is the same for all
points of a (body, part), so with W_k^l = [W_pt | W_z] split by input columns,

    W_k^l [h; gamma(x); z_k] + b^l  =  W_pt [h; gamma(x)] + (b^l + W_z z_k).

:meth:`NBWDecoder.generate` therefore returns per-(body, part) point weights W_pt and folded biases
b^l + W_z z_k; the 128 latent columns are never multiplied per point. ``tests/nn/test_nbw.py``
checks this against the naive per-point concatenation.

Everything is body-agnostic: the number of parts K is a constructor argument.

Parameter count at the paper's defaults (R=80, width 64, 7 layers, latent 128) including the
ResNet-PointNet encoder (0.346M): K=15 -> 47.08M with per-part shape matrices (K, R, out, in),
K=16 -> 50.18M; with ``share_shapes=True`` 3.57M for any K. The paper reports 4.0M, which is only
reachable if the R shape matrices are (mostly) shared across parts.
"""
from __future__ import annotations

import math
from typing import NamedTuple, Optional, Sequence, Tuple

import torch
from torch import nn

from .group_rows import decode_rows
from .grouped import augmented_matrices, grouped_mlp, grouped_supported
from .pairs import check_pairs, default_chunk, group_counts, group_pairs
from .posenc import positional_encoding, posenc_dim


def check_part_subset(parts: torch.Tensor, n_parts: int) -> int:
    """Validate a part subset: (K',) int64 ids, strictly increasing, in [0, n_parts). Returns K'."""
    if not torch.is_tensor(parts) or parts.dim() != 1 or parts.dtype != torch.int64:
        raise ValueError(f"parts must be a 1-D int64 tensor of part ids, got {parts!r}")
    if parts.numel() and (int(parts.min()) < 0 or int(parts.max()) >= n_parts or bool((parts[1:] <= parts[:-1]).any())):
        raise ValueError(f"parts must be strictly increasing ids in [0, {n_parts}), got {parts.tolist()}")
    return parts.numel()


def check_code_parts(K: int, n_parts: int, parts: Optional[torch.Tensor], what: str, owner: str) -> None:
    """A decoding code (`what`, e.g. 'generated weights') made for K parts must match the network's n_parts,
    or the length of its part subset `parts`; `owner` names the network in the message."""
    expect = n_parts if parts is None else len(parts)
    if K != expect:
        raise ValueError(f"{what} are for K={K} parts, expected {expect} "
                         f"({owner if parts is None else 'the part subset'})")


class NBWWeights(NamedTuple):
    """Generated decoder weights for B bodies x K parts, latent already folded into the biases.

    Attributes:
        weights: one tensor per layer l, (B, K, out_l, in_pt_l), where in_pt_l counts only the
            per-point input columns (gamma(x) for layer 0, [h, gamma(x)] for skip layers, h otherwise).
        biases: one tensor per layer l, (B, K, out_l) = b^l + W_z z_k (just b^l on layers without z).
        parts: None for all K parts of the body; else (K',) int64 ids of the parts these weights are for
            (a part subset: decoding then indexes parts 0..K'-1 of this subset).
    """
    weights: Tuple[torch.Tensor, ...]
    biases: Tuple[torch.Tensor, ...]
    parts: Optional[torch.Tensor] = None

    @property
    def batch_shape(self) -> Tuple[int, int]:
        """(B, K)."""
        return tuple(self.biases[0].shape[:2])


class NBWDecoder(nn.Module):
    """NBW generator + K-part SDF decoder.

    Args:
        n_parts: number of body parts K.
        latent_dim: size of z_k (paper: 128).
        hidden: decoder width (paper: 64).
        n_layers: number of linear layers, output included (paper: 7).
        skip_layers: layers whose input is [h, gamma(x), z] (paper: (3,)).
        pe_levels: positional-encoding levels of x_k (paper: 2).
        rank: number R of shape matrices per layer and part (paper: 80). 0 disables blending.
        out_dim: decoder outputs (1 = signed distance).
        shape_init_std: std of the initial shape matrices (small: the initial decoder is ~ the base MLP).
        share_shapes: if True one set of R shape matrices is shared by all parts (shape (1, R, out, in))
            instead of one set per part (K, R, out, in). The paper's reported 4.0M parameters are only
            reachable with shared shape matrices; the default follows the paper's notation W_k^l[r].
    """

    def __init__(self, n_parts: int, latent_dim: int = 128, hidden: int = 64, n_layers: int = 7,
                 skip_layers: Sequence[int] = (3,), pe_levels: int = 2, rank: int = 80,
                 out_dim: int = 1, shape_init_std: float = 1e-3, share_shapes: bool = False):
        super().__init__()
        if n_parts < 1:
            raise ValueError(f"NBWDecoder needs n_parts >= 1, got {n_parts}")
        if n_layers < 2:
            raise ValueError(f"NBWDecoder needs n_layers >= 2 (input and output layer), got {n_layers}")
        skip_layers = tuple(int(s) for s in skip_layers)
        for s in skip_layers:
            if not 0 < s < n_layers:
                raise ValueError(f"skip layer {s} out of range 1..{n_layers - 1}")
        self.n_parts = int(n_parts)
        self.latent_dim = int(latent_dim)
        self.hidden = int(hidden)
        self.n_layers = int(n_layers)
        self.skip_layers = skip_layers
        self.pe_levels = int(pe_levels)
        self.rank = int(rank)
        self.out_dim = int(out_dim)
        self.share_shapes = bool(share_shapes)
        self.x_dim = posenc_dim(3, self.pe_levels)                      # 15 at 2 levels

        # Per-layer sizes. pt_dims = per-point input columns; has_z = layer reads z_k.
        self.in_dims, self.pt_dims, self.out_dims, self.has_z = [], [], [], []
        for l in range(self.n_layers):
            if l == 0:
                pt = self.x_dim
            elif l in self.skip_layers:
                pt = self.hidden + self.x_dim
            else:
                pt = self.hidden
            z = l == 0 or l in self.skip_layers
            self.pt_dims.append(pt)
            self.has_z.append(z)
            self.in_dims.append(pt + (self.latent_dim if z else 0))
            self.out_dims.append(self.out_dim if l == self.n_layers - 1 else self.hidden)

        S = 1 if self.share_shapes else self.n_parts
        self.base_weight = nn.ParameterList()
        self.base_bias = nn.ParameterList()
        self.shape_weight = nn.ParameterList()
        self.blend = nn.ModuleList()
        for l in range(self.n_layers):
            o, i = self.out_dims[l], self.in_dims[l]
            w = torch.empty(o, i)
            if l < self.n_layers - 1:
                nn.init.kaiming_normal_(w, nonlinearity="relu")
                b = torch.zeros(o)
            else:
                nn.init.uniform_(w, -0.1 / math.sqrt(i), 0.1 / math.sqrt(i))
                b = torch.full((o,), 0.01)                              # small positive initial SDF
            self.base_weight.append(nn.Parameter(w))
            self.base_bias.append(nn.Parameter(b))
            self.shape_weight.append(nn.Parameter(torch.randn(S, self.rank, o, i) * shape_init_std))
            if self.rank > 0:
                self.blend.append(nn.Linear(self.latent_dim, self.rank))

    @classmethod
    def from_config(cls, cfg, n_parts: int, **kwargs) -> "NBWDecoder":
        """Build from a :class:`volsmpl.nn.config.VolumeConfig` for a body with ``n_parts`` parts."""
        return cls(n_parts, latent_dim=cfg.latent_dim, hidden=cfg.decoder_hidden,
                   n_layers=cfg.decoder_layers, skip_layers=cfg.skip_layers,
                   pe_levels=cfg.pe_levels, rank=cfg.nbw_rank, **kwargs)

    # ------------------------------------------------------------------ generation
    def _check_z(self, z: torch.Tensor, parts: Optional[torch.Tensor] = None) -> None:
        K = self.n_parts if parts is None else check_part_subset(parts, self.n_parts)
        if z.dim() != 3 or z.shape[1] != K or z.shape[2] != self.latent_dim:
            raise ValueError(f"NBWDecoder expects latent codes z of shape (B, K={K}, "
                             f"{self.latent_dim}), got {tuple(z.shape)}")

    def blended_weights(self, z: torch.Tensor, parts: Optional[torch.Tensor] = None) -> Tuple[torch.Tensor, ...]:
        """Full blended weights W_k^l = W^l + sum_r v_k^l[r] S_k^l[r] (latent columns included).

        Args:
            z: (B, K, latent_dim); with parts, (B, K', latent_dim) codes of those K' parts.
        Returns:
            tuple over layers of (B, K, out_l, in_l); input columns ordered
            [gamma(x), z] on layer 0, [h, gamma(x), z] on skip layers, [h] otherwise.
        """
        self._check_z(z, parts)
        out = []
        for l in range(self.n_layers):
            W = self.base_weight[l]
            if self.rank == 0:
                out.append(W.expand(z.shape[0], z.shape[1], *W.shape))
                continue
            v = self.blend[l](z)                                        # (B, K, R)
            S = self.shape_weight[l].flatten(2)                         # (S, R, o*i)
            if self.share_shapes:
                delta = v @ S[0]                                        # (B, K, o*i)
            else:                                                       # batched over k
                if parts is not None:
                    S = S[parts]
                delta = torch.bmm(v.transpose(0, 1), S).transpose(0, 1)  # (B, K, o*i)
            out.append(W + delta.view(*z.shape[:2], *W.shape))
        return tuple(out)

    def generate(self, z: torch.Tensor, parts: Optional[torch.Tensor] = None) -> NBWWeights:
        """Generate per-(body, part) decoder weights with the latent folded into the biases.

        Args:
            z: (B, K, latent_dim) part codes; with parts (K',) int64 part ids, the codes of those parts only
                (B, K', latent_dim): the weights are then for that subset (cheap partial re-encoding).
        Returns:
            :class:`NBWWeights` (weights (B, K, out_l, in_pt_l), biases (B, K, out_l)).
        """
        full = self.blended_weights(z, parts)
        weights, biases = [], []
        for l, W in enumerate(full):
            b = self.base_bias[l]
            if self.has_z[l]:
                pt = self.pt_dims[l]
                Wz = W[..., pt:]                                        # (B, K, o, latent)
                b = b + (Wz @ z.unsqueeze(-1)).squeeze(-1)              # (B, K, o)
                W = W[..., :pt]
            else:
                b = b.expand(*z.shape[:2], b.shape[0])
            weights.append(W)
            biases.append(b)
        return NBWWeights(tuple(weights), tuple(biases), parts)

    def _check_gen(self, gen: NBWWeights) -> Tuple[int, int]:
        if not isinstance(gen, NBWWeights) or len(gen.weights) != self.n_layers:
            raise TypeError("decode expects the NBWWeights returned by NBWDecoder.generate(z) of this model")
        B, K = gen.batch_shape
        check_code_parts(K, self.n_parts, gen.parts, "generated weights", "this decoder")
        return B, K

    # ------------------------------------------------------------------ decoding
    def decode_dense(self, x_local: torch.Tensor, gen: NBWWeights) -> torch.Tensor:
        """Evaluate every part's decoder on every point (reference path).

        Args:
            x_local: (B, K, N, 3) points in each part's canonical frame.
            gen: weights from :meth:`generate` for the same B bodies.
        Returns:
            (B, K, N) signed distances (out_dim == 1) or (B, K, N, out_dim) otherwise.
        """
        B, K = self._check_gen(gen)
        if x_local.dim() != 4 or tuple(x_local.shape[:2]) != (B, K) or x_local.shape[-1] != 3:
            raise ValueError(f"decode_dense expects x_local of shape (B={B}, K={K}, N, 3), got {tuple(x_local.shape)}")
        p = positional_encoding(x_local, self.pe_levels)                 # (B, K, N, x_dim)
        h = p
        for l in range(self.n_layers):
            if l in self.skip_layers:
                h = torch.cat([h, p], dim=-1)
            h = h @ gen.weights[l].transpose(-1, -2) + gen.biases[l].unsqueeze(-2)
            if l < self.n_layers - 1:
                h = torch.relu(h)
        return h.squeeze(-1) if self.out_dim == 1 else h

    def decode_pairs(self, x_local: torch.Tensor, body_idx: torch.Tensor, part_idx: torch.Tensor,
                     gen: NBWWeights, chunk: Optional[int] = None, counts_host: Optional[list] = None,
                     group_sorted: bool = False) -> torch.Tensor:
        """Evaluate each point only with its own (body, part) decoder.

        Pairs are grouped by (body, part) and cut into equal chunks (:func:`group_pairs`), so every layer is a
        single batched matmul over chunks; without gradients on the CPU, each group's rows run through its own
        weights instead, in cache tiles (volsmpl.nn.group_rows). Equals ``decode_dense`` on the same pairs and is
        differentiable w.r.t. ``x_local`` and (through ``gen``) the latent codes.

        Args:
            x_local: (M, 3) points, each in the frame of its part.
            body_idx: (M,) int64 body index in [0, B).
            part_idx: (M,) int64 part index in [0, K).
            gen: weights from :meth:`generate`.
            chunk: rows per matmul chunk of the batched form; default :func:`default_chunk`.
            counts_host: pairs per (body, part) group (B * K ints, body-major) when the caller holds them on the
                host already (the lean query counts them in its one sync): the indices are then taken as in
                range and the call makes no host sync; without it, two (bounds, then the layout).
            group_sorted: the caller guarantees the pairs are sorted by (body, part) (`group_pairs` skips its sort).
        Returns:
            (M,) signed distances (out_dim == 1) or (M, out_dim).
        """
        B, K = self._check_gen(gen)
        group = check_pairs(x_local, body_idx, part_idx, B, K, bounds=counts_host is None)
        M = x_local.shape[0]
        G = B * K
        if counts_host is not None and (len(counts_host) != G or sum(counts_host) != M):
            raise ValueError(f"decode_pairs: counts_host must hold {G} group counts summing to the {M} pairs, got "
                             f"{len(counts_host)} summing to {sum(counts_host)}")
        if M == 0:
            out = x_local.sum(-1)
            return out if self.out_dim == 1 else out.unsqueeze(-1).expand(0, self.out_dim)
        counts = group_counts(group, G) if counts_host is None else None
        if counts_host is None:
            counts_host = counts.tolist()  # the layout's host sync: group sizes, chunk size and number of chunks
        tile_rows = self.tile_rows(x_local.device)
        needs_grad = torch.is_grad_enabled() and (x_local.requires_grad or any(
            t.requires_grad for t in gen.weights + gen.biases))
        if not needs_grad and tile_rows is not None:
            # Inference on the CPU: each group's contiguous rows through its own weights, tile by tile (in cache)
            order = None if group_sorted else torch.argsort(group, stable=True)
            p = positional_encoding(x_local if order is None else x_local[order], self.pe_levels)
            h = decode_rows(p, counts_host, [w.reshape(G, *w.shape[2:]) for w in gen.weights],
                            [b.reshape(G, -1) for b in gen.biases], self.skip_layers, self.hidden, tile_rows)
            if order is not None:
                h = torch.empty_like(h).index_put_((order,), h)
            return h.squeeze(-1) if self.out_dim == 1 else h
        if chunk is None:
            chunk = default_chunk(M, sum(c > 0 for c in counts_host))
        lay = group_pairs(group, G, int(chunk), counts, counts_host, group_sorted)
        n_chunks = lay.chunk_group.shape[0]
        xs = x_local[lay.src].view(n_chunks, lay.chunk, 3)
        Ws = [gen.weights[l].reshape(G, self.out_dims[l], self.pt_dims[l])[lay.chunk_group].transpose(1, 2)
              for l in range(self.n_layers)]                            # (n_chunks, in_pt, out)
        bs = [gen.biases[l].reshape(G, 1, self.out_dims[l])[lay.chunk_group] for l in range(self.n_layers)]
        h = self.mlp_chunks(xs, Ws, bs)
        h = h.reshape(n_chunks * lay.chunk, self.out_dim)[lay.slot]
        return h.squeeze(-1) if self.out_dim == 1 else h

    TILE_ROWS = 4096  # rows per cache tile on the no-grad path of decode_pairs (CPU, volsmpl.nn.group_rows)

    def tile_rows(self, device) -> Optional[int]:
        """Rows per cache tile of `decode_pairs` without gradients: TILE_ROWS on the CPU (volsmpl.nn.group_rows),
        None on a GPU: one batched matmul per layer, as loops over groups and tiles only multiply launches there."""
        return self.TILE_ROWS if torch.device(device).type == "cpu" else None    # TILE_ROWS None: batched too

    # ------------------------------------------------------------------ grouped decoding (volsmpl.nn.grouped)
    def grouped_supported(self, dtype: torch.dtype, device=None) -> bool:
        """Whether `decode_grouped` runs in `dtype` on `device` here (else use `decode_pairs`)."""
        return grouped_supported(dtype, device)

    def grouped_matrices(self, gen: NBWWeights) -> Tuple[torch.Tensor, ...]:
        """Layer matrices of every (body, part) group for `decode_grouped` (make once per encoding).

        Shape: gen for B bodies x K parts -> tuple over layers of (B*K, rows_l, cols_l) (volsmpl.nn.grouped.augmented_matrices)."""
        B, K = self._check_gen(gen)
        W = [gen.weights[l].reshape(B * K, self.out_dims[l], self.pt_dims[l]) for l in range(self.n_layers)]
        b = [gen.biases[l].reshape(B * K, self.out_dims[l]) for l in range(self.n_layers)]
        return tuple(augmented_matrices(W, b, self.skip_layers, self.hidden))

    def decode_grouped(self, x_local: torch.Tensor, offs: torch.Tensor, gen: NBWWeights, mats=None,
                       compute_dtype: Optional[torch.dtype] = None) -> torch.Tensor:
        """Evaluate group-sorted pairs, each with its own (body, part) decoder: one grouped matmul per layer
        (no padding, no loop over groups; volsmpl.nn.grouped). Equals ``decode_pairs`` on the same pairs.

        Shape: x_local (M, 3) rows sorted by group g = body * K + part (part: index into gen's parts),
        offs (B*K,) int32 cumulative group sizes (offs[-1] == M), gen for B x K -> (M,) (out_dim 1) or (M, out_dim).
        mats: `grouped_matrices(gen)` when already made. compute_dtype: run the layers in this dtype (e.g.
        torch.bfloat16: the positional encoding is computed in x_local's dtype, then it and the layer matrices are
        rounded to it; the result returns in x_local's dtype). Needs `grouped_supported` of the dtype the layers run in.
        """
        B, K = self._check_gen(gen)
        if x_local.dim() != 2 or x_local.shape[1] != 3:
            raise ValueError(f"decode_grouped expects x_local of shape (M, 3), got {tuple(x_local.shape)}")
        if offs.shape != (B * K,) or offs.dtype != torch.int32:
            raise ValueError(f"decode_grouped expects int32 offs of shape ({B * K},), got {offs.dtype} {tuple(offs.shape)}")
        run = compute_dtype or x_local.dtype
        if not self.grouped_supported(run, x_local.device):
            raise TypeError(f"decode_grouped: no grouped matmul for {run} on {x_local.device.type} in this torch; "
                            f"use decode_pairs")
        mats = self.grouped_matrices(gen) if mats is None else mats
        p = positional_encoding(x_local, self.pe_levels)
        if run != x_local.dtype:
            p, mats = p.to(run), [m.to(run) for m in mats]
        h = grouped_mlp(p, offs, mats, self.skip_layers)[:, :self.out_dim].to(x_local.dtype)
        return h.squeeze(-1) if self.out_dim == 1 else h

    def mlp_chunks(self, xs: torch.Tensor, Ws, bs) -> torch.Tensor:
        """The decoder on chunks of points, each chunk with its own weights (one batched matmul per layer).

        Shape: xs (C, n, 3); Ws[l] (C, in_pt_l, out_l) (a layer's weights transposed); bs[l] (C, 1, out_l) -> (C, n,
        out_dim). Used by `decode_pairs` and the static lean query (volsmpl.volume.engine.query_graph)."""
        p = positional_encoding(xs, self.pe_levels)                     # (C, n, x_dim)
        h = p
        for l in range(self.n_layers):
            W = Ws[l]
            if l in self.skip_layers:
                # [h, p] @ W == h @ W_h + p @ W_p: no per-point concatenation copy.
                h = torch.baddbmm(bs[l], h, W[:, :self.hidden])
                h = h.baddbmm_(p, W[:, self.hidden:])
            else:
                h = torch.baddbmm(bs[l], h, W)                          # (C, n, out)
            if l < self.n_layers - 1:
                # in place is autograd-safe: baddbmm saves its inputs, not its output.
                h = h.relu_()
        return h

    def flops_per_pair(self) -> int:
        """Multiply-add FLOPs (2 per MAC) of one decoder evaluation, latent folded."""
        return sum(2 * o * i for o, i in zip(self.out_dims, self.pt_dims))

    def extra_repr(self) -> str:
        return (f"n_parts={self.n_parts}, latent_dim={self.latent_dim}, hidden={self.hidden}, "
                f"n_layers={self.n_layers}, skip_layers={self.skip_layers}, pe_levels={self.pe_levels}, "
                f"rank={self.rank}, share_shapes={self.share_shapes}")


def count_parameters(*modules: nn.Module, trainable_only: bool = False) -> int:
    """Total number of parameters of ``modules`` (shared tensors counted once)."""
    seen, n = set(), 0
    for m in modules:
        for p in m.parameters():
            if id(p) in seen or (trainable_only and not p.requires_grad):
                continue
            seen.add(id(p))
            n += p.numel()
    return n
