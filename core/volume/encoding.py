"""The encoding of a body output (`Encoding`: part frames, padded boxes, part codes) and its cache
(`EncodingCache`, a mixin of `volsmpl.volume.learned.Volume`).

An encoding is cached on the body output and reused only while the values of the output's tensors and of the
volume's weights are unchanged, checked by content fingerprints (volsmpl.volume.fingerprint): any edit, also
through `.data` or `.numpy()`, re-encodes. Queries encode only the parts whose padded boxes hold their points,
and a later query grows the cached encoding by the parts it needs.

    enc = volume.encode(out)                      # all parts
    enc = volume._encoding_for(out, points)       # (Volume.query) the parts that points (B, N, 3) need
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import torch

from volsmpl.geometry.boxes import box_test, parts_holding
from volsmpl.volume.engine.encode_graph import map_tensors
from volsmpl.nn.volsmpl_net import PartCode
from volsmpl.volume.fingerprint import fingerprint
from volsmpl.volume.api import check_output


@dataclass
class Encoding:
    """Per-forward-output body encoding. G (B, K, 4, 4) part-to-world; box_min/max (B, K, 3) padded
    boxes in part frames; center (B, K, 3) and scale (B, K, 1) of the part normalisation
    (config.normalize_parts), else None: these are always for all K parts (cheap, no network).
    code: PartCode (z_k and generated decoder weights) of the encoded parts: all K when parts is None;
    else of the (K',) int64 ids `parts` (K' may be 0: code None), and slot (K,) int64 maps part k to its
    index in the code (-1: not encoded). A query may only decode parts that are encoded (Volume.query
    encodes the parts whose boxes hold its points)."""

    G: torch.Tensor
    box_min: torch.Tensor
    box_max: torch.Tensor
    code: PartCode
    key: tuple | None = None  # content fingerprints of (the output, the volume's weights) when cached (Volume.cache_key)
    center: torch.Tensor | None = None
    scale: torch.Tensor | None = None
    parts: torch.Tensor | None = None
    slot: torch.Tensor | None = None
    grouped: tuple | None = None  # the code's per-group layer matrices (grouped engine), made on first use
    graph: bool = True  # made with autograd on (set when cached): one made under no_grad has no graph to serve

    def encoded(self, num_parts: int) -> torch.Tensor:
        """(K,) bool: which parts have a code."""
        if self.slot is None:
            return torch.ones(num_parts, dtype=torch.bool, device=self.G.device)
        return self.slot >= 0

    def with_constant_code(self) -> "Encoding":
        """This encoding with its part codes detached from autograd (frames and boxes keep their graph): what
        an encoding made with code_grad=False holds (Volume.selfpen_loss)."""
        if self.code is None:
            return self
        return replace(self, code=map_tensors(torch.Tensor.detach, self.code), grouped=None, key=None)


class EncodingCache:
    """The encoding cache of a Volume: needs the Volume's `net`, `refine_steps`, `refine_warm`, `warm`,
    `active_passes`, `pass_every`, `carried`, `warm_serial`, `_encode`, `_frames`, `_replays`, `_lean_chunks`,
    `num_parts`, `_last` (the last constant encoding, None at first) and `training`."""

    def encode(self, out, generator: torch.Generator | None = None, fresh: bool = False) -> Encoding:
        """Encode a body output (B bodies); cached on the output and reused while the values of its tensors
        and of the volume's weights are unchanged (checked by content: `cache_key`; any edit re-encodes, also
        through `.data` or `.numpy()`).

        Args:
            out: body forward output with vertices (B, V, 3), joints (B, >=J, 3), full_pose (B, J*3).
            generator: draw fresh surface samples (training augmentation) instead of the fixed set; not cached.
            fresh: encode anew, neither reading nor writing the cache (benchmarks time the encoder this way).
        Use with `query_encoded(enc, points)`.
        """
        check_output(out)
        use_cache = generator is None and not self.training and not fresh
        key = self.cache_key(out) if use_cache else None
        cached = self._cached(out, key) if use_cache else None
        if cached is not None and cached.parts is None:
            return cached
        frames = None if cached is None else (cached.G, cached.box_min, cached.box_max)
        enc = self._encode(out, generator, frames=frames)
        if use_cache:
            self._store(out, enc, key)
        return enc

    def cache_key(self, out) -> tuple:
        """What a cached encoding must match to be reused: content fingerprints of the output's vertices, joints
        and full_pose and of every weight and buffer of the volume (volsmpl.volume.fingerprint; ~1 ms for the
        3.6 M weights on one CPU thread), in one fingerprint: one read of device values (on a GPU, one wait); and
        the network's encoder arithmetic (`net.encoder_bf16`), the code refinement's steps (`refine_steps`), warm
        mode and warm scope (`refine_warm`, `warm_serial`), the learned passes run (`active_passes`) and their
        interval (`pass_every`) and its scope, which change the codes without changing a tensor."""
        return fingerprint((out.vertices, out.joints, out.full_pose, *self.parameters(), *self.buffers())) + (
            ("encoder_bf16", bool(self.net.encoder_bf16)), ("refine_steps", int(self.refine_steps)),
            ("refine_warm", bool(self.refine_warm), self.warm_serial if self.warm is not None else -1),
            ("passes", int(self.active_passes)),
            ("pass_every", int(self.pass_every), self.warm_serial if self.carried is not None else -1))

    def _store(self, out, enc: Encoding, key: tuple) -> None:
        """Cache `enc` on the output (and, for a constant output, as the last encoding for value reuse)."""
        enc.key = key
        enc.graph = torch.is_grad_enabled()
        try:
            out._volsmpl_encoding = (self, enc)
        except AttributeError:  # outputs that take no attributes are re-encoded on every call
            pass
        if not (out.vertices.requires_grad or out.joints.requires_grad or out.full_pose.requires_grad):
            self._last = enc  # may answer an equal new constant output (value reuse)

    def _encoding_for(self, out, points: torch.Tensor, frames=None, holding=None) -> Encoding:
        """An encoding of `out` that answers queries at `points` (B, N, 3): the cached one when it has a code
        for every part whose padded box holds a point, else a new one of those parts (and the cached
        ones), cached in turn. A part whose box holds no point only contributes its analytic box
        distance, so encoding it would change nothing: queries near a few parts (a hand and an object)
        run the encoder on those parts only; where the encode is a CUDA-graph replay (`_replays`), all parts are
        encoded at once and no frames or box test are made here. frames: `_frames(out)` when the caller has them.
        holding: a function (G, box_min, box_max) -> (K,) bool of the parts whose box holds a point, in place of
        `_parts_holding` (the lean query's, which keeps its box test for the query)."""
        check_output(out)
        key = None if self.training else self.cache_key(out)
        enc = None if self.training else self._cached(out, key)
        if enc is not None and enc.parts is None:
            return enc
        if enc is None and self._replays(out):  # the replay makes its own frames and encodes every part
            enc = self._encode(out, None)
            if not self.training:
                self._store(out, enc, key)
            return enc
        if enc is not None:
            frames = (enc.G, enc.box_min, enc.box_max)
        elif frames is None:
            frames = self._frames(out)
        need = self._parts_holding(points, *frames) if holding is None else holding(*frames)
        if enc is not None:
            have = enc.encoded(self.num_parts)
            if not (need & ~have).any():
                return enc
            need |= have
        parts = None if need.all() else need.nonzero()[:, 0]
        enc = self._encode(out, None, parts=parts, frames=frames)
        if not self.training:
            self._store(out, enc, key)
        return enc

    @torch.no_grad()
    def _parts_holding(self, points: torch.Tensor, G: torch.Tensor, box_min: torch.Tensor, box_max: torch.Tensor) -> torch.Tensor:
        """(K,) bool: parts whose padded box holds at least one of the points (B, N, 3) of some body."""
        need = torch.zeros(self.num_parts, dtype=torch.bool, device=G.device)
        B, N = points.shape[:2]
        G, box_min, box_max = G.detach(), box_min.detach(), box_max.detach()
        for b0, b1, s, e in self._lean_chunks(B, N, G.device):
            need |= parts_holding(box_test(points[b0:b1, s:e].detach(), G[b0:b1], box_min[b0:b1], box_max[b0:b1])[1])
        return need

    def _cached(self, out, key: tuple | None = None) -> Encoding | None:
        """The encoding made earlier of `out` (or of an equal constant output) by this volume with the same
        weights: same content fingerprints (`key` = cache_key(out), computed here when not given and only when
        there is a candidate: a new output of a body that moves costs no fingerprint), else None. One made under
        torch.no_grad() is not served where gradients may flow (the output or a weight requires grad): it has no
        graph, and the gradients of the poses, shapes or weights would be lost (None or 0)."""
        constant = not (out.vertices.requires_grad or out.joints.requires_grad or out.full_pose.requires_grad)
        cached = getattr(out, "_volsmpl_encoding", None)
        if (cached is None or cached[0] is not self) and not (constant and self._last is not None):
            return None
        key = self.cache_key(out) if key is None else key
        found = cached[1] if cached is not None and cached[0] is self and cached[1].key == key else None
        last = self._last
        if found is None and constant and last is not None and last.key == key:
            found = last  # same pose, shape and translation as the previous constant output, same weights
        if found is not None and not found.graph and torch.is_grad_enabled() and not (
                constant and not any(p.requires_grad for p in self.parameters())):
            return None
        return found


__all__ = ["Encoding", "EncodingCache"]
