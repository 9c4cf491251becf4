"""Per-(body key, part) state carried across the encodings of one optimisation: the rows of `WarmCodes` (warm
code refinement) and `CarriedPasses` (learned passes at every N-th encoding).

The B bodies of an encoding are keyed 0..B-1, which is right when every encoding holds the same batch of problems
in the same order (the harness's apps). A caller that encodes other groupings names its bodies with `keys(ids)`
around the calls that encode them (motion: frame rows). The codes alone cannot tell bodies apart: two bodies'
codes can be closer than one body's codes after one optimisation step (docs/code_refinement.md).

    state = WarmCodes(num_parts=16)                 # a KeyedPartState
    with state.keys(torch.tensor([4, 9])): ...      # the next encodings hold bodies 4 and 9
    rows, kk, had, jumped = state.lookup(z, parts)  # where codes z (B, K', L) of `parts` stand in state.state
"""
from __future__ import annotations

import contextlib

import torch

__all__ = ["KeyedPartState", "code_change"]


def code_change(z: torch.Tensor, zref: torch.Tensor) -> torch.Tensor:
    """|z - zref| / |zref| per code: how far codes moved relative to where they were.

    Shape: z, zref (..., L) -> (...).
    Example: >>> code_change(torch.tensor([[3.0, 4.0]]), torch.tensor([[0.0, 5.0]]))   # |(3, -1)| / 5
    """
    return (z - zref).norm(dim=-1) / zref.norm(dim=-1).clamp_min(torch.finfo(z.dtype).tiny)


class KeyedPartState:
    """Tensors of per-(body key, part) state, grown by a row when a new body key appears (module docstring).

    Subclasses name their fields in `FIELDS`: name -> trailing shape, where 'L' stands for the code's length
    (every field starts at zero); a bool field `have` (B, K) says which (key, part) holds state.

    Args:
        num_parts: K, the volume's parts.
        max_change: relative change of a (key, part)'s code since its state was made above which it jumped (> 0;
            inf: never).
    """

    FIELDS: dict[str, tuple] = {}

    def __init__(self, num_parts: int, max_change: float):
        if not max_change > 0:
            raise ValueError(f"max_change must be > 0 (a relative code change), got {max_change}")
        self.num_parts, self.max_change = int(num_parts), float(max_change)
        self._ids: torch.Tensor | None = None
        self._rows: dict[int, int] = {}
        self.state: dict[str, torch.Tensor] = {}

    @property
    def known(self) -> list[int]:
        """The body keys seen so far, in the order first seen."""
        return list(self._rows)

    @contextlib.contextmanager
    def keys(self, ids):
        """The encodings inside hold the bodies `ids` ((B,) distinct ints, in the output's order)."""
        ids = torch.as_tensor(ids).reshape(-1)
        if ids.is_floating_point() or len(torch.unique(ids)) != len(ids):
            raise ValueError(f"{type(self).__name__}.keys: give distinct integer ids, one per body of the encoded "
                             f"output")
        before, self._ids = self._ids, ids.cpu()
        try:
            yield self
        finally:
            self._ids = before

    def rows_of(self, B: int, like: torch.Tensor) -> torch.Tensor:
        """The state rows (B,) of the next encoding's B bodies; new keys get new rows of zeros. like: the codes
        (B, K', L): state of another device, dtype or code length is dropped (another network or precision)."""
        ids = torch.arange(B) if self._ids is None else self._ids
        if len(ids) != B:
            raise ValueError(f"{type(self).__name__}.keys named {len(ids)} bodies but the encoded output has {B}")
        s = self.state
        if s and (s["have"].device != like.device or s["zref"].dtype != like.dtype
                  or s["zref"].shape[-1] != like.shape[-1]):
            self._rows, self.state, s = {}, {}, {}
        new = [int(i) for i in ids.tolist() if int(i) not in self._rows]
        if new:
            K, L = self.num_parts, like.shape[-1]
            for i in new:
                self._rows[i] = len(self._rows)
            for name, tail in {"zref": ("L",), **self.FIELDS}.items():
                pad = like.new_zeros(len(new), K, *(L if d == "L" else d for d in tail))
                s[name] = pad if name not in s else torch.cat([s[name], pad])
            have = torch.zeros(len(new), K, dtype=torch.bool, device=like.device)
            s["have"] = have if "have" not in s else torch.cat([s["have"], have])
        return torch.tensor([self._rows[int(i)] for i in ids.tolist()], device=like.device)

    def lookup(self, z: torch.Tensor, parts: torch.Tensor | None) -> tuple:
        """Where an encoding's codes z (B, K', L) of `parts` ((K',) ids; None: all K) stand in the state: (rows
        (B, 1) and part ids (1, K') that index it, had (B, K'): which (body, part) holds state, jumped (B, K'):
        which of those moved by more than `max_change` of its code's norm since its state was made)."""
        zd = z.detach()
        rows = self.rows_of(z.shape[0], zd)[:, None]
        kk = (torch.arange(self.num_parts, device=zd.device) if parts is None else parts.to(zd.device))[None]
        had = self.state["have"][rows, kk]
        return rows, kk, had, had & (code_change(zd, self.state["zref"][rows, kk]) > self.max_change)
