"""Learned code-refinement passes at every N-th encoding of an optimisation, their correction carried between:
`Volume.set_pass_interval(N)`.

A model with learned passes (`VolumeConfig.refiner_iters`, volsmpl.nn.code_refiner) corrects the encoder's codes
at every encoding; an app that re-encodes its bodies at every iteration pays for the passes at every iteration.
From one iteration to the next a body moves little, and so does the correction the passes make. `CarriedPasses`
keeps, per (body key, part), the correction delta = passes' code - encoder's code of the last encoding that ran
the passes on it, and adds it to the encoder's codes of the encodings between. A (body, part) of an encoding is
passed anew when

- it has no correction yet (a new body key, or a part not encoded before),
- its last pass is N - 1 encodings old (so the passes run at every N-th encoding), or
- its encoder code moved by more than `max_change` of its norm since that pass (the body jumped there);

the passes then run on the bodies and parts holding such a (body, part) (each pass reads a part of a body alone, so
the others are not needed), whose corrections they renew. Measured on 16 validation bodies moving along a path
(docs/scripts/warm_refinement.py --pass-every, docs/learned_refinement.md): with N = 4 to 16 the carried correction
scores 92.79-92.81 mean IoU against 92.79 with the passes at every encoding; without the jump rule a correction 3
encodings old loses 0.15 points where the body moves 1/19 of a 0.3 rad pose change per encoding.

Keys: as `volsmpl.volume.keyed_state.KeyedPartState` says (0..B-1, or the ids given by `keys(ids)`).

Autograd: the returned code is z + delta with delta a constant, also at the encodings that run the passes: the
gradient reaches the body through the encoder, not through the passes (which run without autograd here).

    carried = CarriedPasses(num_parts=16, every=4)
    z = carried.apply(net, z, points, parts)     # z (B, K', latent); points() -> (xin, target, scale)
"""
from __future__ import annotations

from typing import Callable

import torch

from volsmpl.volume.keyed_state import KeyedPartState
from volsmpl.volume.warm_codes import WARM_MAX_CHANGE

__all__ = ["CarriedPasses", "check_pass_interval"]


def check_pass_interval(every, name: str = "pass interval") -> int:
    """`every` as an int >= 1 (1: the passes at every encoding), else ValueError (one line, headed by `name`)."""
    if isinstance(every, bool) or not isinstance(every, int) or every < 1:
        raise ValueError(f"{name} {every!r}: give an integer >= 1 (1: the learned passes at every encoding)")
    return every


class CarriedPasses(KeyedPartState):
    """Per-(body key, part) corrections of the learned passes carried across encodings (module docstring).

    Args:
        num_parts: K, the volume's parts.
        every: the passes run at every `every`-th encoding (>= 1).
        max_change: relative encoder-code change since the last pass that runs the passes again (> 0; inf: never).
    Counters: `encoded` (body, part) codes made so far, `passed` of them by running the passes, `restarted` the
    bodies of encodings where a code of theirs jumped; `known`: the body keys seen.
    """

    FIELDS = {"delta": ("L",), "age": ()}

    def __init__(self, num_parts: int, every: int, max_change: float = WARM_MAX_CHANGE):
        super().__init__(num_parts, max_change)
        self.every = check_pass_interval(every)
        self.encoded = self.passed = self.restarted = 0

    def apply(self, net, z: torch.Tensor, points: Callable[[], tuple], parts: torch.Tensor | None,
              passes: int | None = None) -> torch.Tensor:
        """z + delta, delta each (body, part)'s carried correction, or a new one from the first `passes` passes
        (`net.refiner`; None: all) when the encoding is due (module docstring); the state updated.

        Shape: z (B, K', latent) encoder codes of `parts` ((K',) ids, None: all K); points() -> the refinement
        points (xin, target, scale) of `refinement_points`, called only when the passes run -> (B, K', latent).
        """
        B, Kc = z.shape[:2]
        if Kc == 0:
            return z
        zd = z.detach()
        rows, kk, had, jumped = self.lookup(zd, parts)
        s = self.state
        age, delta = s["age"][rows, kk], s["delta"][rows, kk]
        due = ~had | jumped | (age + 1 >= self.every)                       # (B, K') codes to pass anew
        self.encoded += B * Kc
        bodies, due_parts = due.any(dim=1), due.any(dim=0)
        fresh = bodies[:, None] & due_parts[None]                           # the block of bodies x parts passed
        if bool(due.any()):
            xin, target, scale = points()
            bi, pi = bodies.nonzero()[:, 0], due_parts.nonzero()[:, 0]
            sub = (bi[:, None], pi[None])
            with torch.no_grad():
                new = net.refiner(net, zd[sub], xin[sub], target[sub], None if scale is None else scale[sub], kk[0, pi],
                                  passes=passes)
            delta = delta.index_put(sub, new - zd[sub])
            self.passed += int(fresh.sum())
            self.restarted += int(jumped.any(dim=1).sum())
        s["delta"][rows, kk] = delta
        s["zref"][rows, kk] = torch.where(fresh[..., None], zd, s["zref"][rows, kk])
        s["have"][rows, kk] = had | fresh
        s["age"][rows, kk] = torch.where(fresh, 0, age + 1)
        return z + delta
