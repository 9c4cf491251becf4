"""Code refinement carried along an optimisation: `Volume.set_code_refinement(steps, warm=True)`.

An optimisation (an app's fit, repair or motion) re-encodes its bodies at every iteration, and from one iteration
to the next a body moves little. `WarmCodes` keeps, per (body key, part), what refining that part's code reached
at the previous encoding: the correction delta = refined code - encoder's code, Adam's moments and step count, and
the encoder's code it was made from. The next encoding of that (key, part) starts from z + delta with those
moments and takes `steps` Adam steps at the step size `lr` on the part's refinement loss (the points, loss and
update of `volsmpl.volume.code_refinement`), rising linearly over the first `warmup` steps of each (body, part):
Adam's first steps move every coordinate by about the full step size whatever its gradient, which from the encoder's
codes makes them worse (one such step: 91.36 -> 85.79 mean IoU on 16 validation bodies). After T iterations a body
that moved little has had T * steps steps of refinement at the cost of `steps` per encoding.

A (key, part) whose encoder code moved by more than `max_change` of its norm since the last encoding starts
afresh (delta and moments zero): its body jumped, and the old correction was made for another shape.

Keys: the bodies of an encoding are keyed as `volsmpl.volume.keyed_state.KeyedPartState` says (0..B-1, or the
ids given by `keys(ids)`).

Autograd: as in `refine_codes`, the returned code is z + delta with delta a constant.

    warm = WarmCodes(num_parts=16, steps=1)
    z = warm.refine(net, z, xin, target, scale, parts)          # (B, K', latent), one Adam step per (body, part)
    with warm.keys(torch.tensor([4, 9])): ...                   # the next encodings hold bodies 4 and 9
"""
from __future__ import annotations

import torch

from volsmpl.volume.code_refinement import REFINE_LR, REFINE_WARMUP, adam_steps, check_refine_steps
from volsmpl.volume.keyed_state import KeyedPartState

__all__ = ["WarmCodes", "WARM_MAX_CHANGE"]

#: relative change |z - z_prev| / |z_prev| of a (body, part)'s encoder code above which its carried correction
#: is dropped (docs/code_refinement.md, "Warm-started along an optimisation")
WARM_MAX_CHANGE = 0.05
#: steps over which a (body, part)'s step size rises linearly to lr from its first (or restarted) step
WARM_WARMUP = REFINE_WARMUP


class WarmCodes(KeyedPartState):
    """Per-(body key, part) code corrections and Adam state carried across encodings (module docstring).

    Args:
        num_parts: K, the volume's parts.
        steps: Adam steps per encoding (>= 1).
        lr: the constant step size.
        max_change: relative encoder-code change that restarts a (key, part) (> 0; inf: never).
        warmup: a (key, part)'s step size is lr * min(1, t / warmup) at its t-th step since its (re)start (0: lr).
    Counters: `encoded` (body, part) codes refined so far, `restarted` of them started afresh after a jump;
    `known`: the body keys seen.
    """

    FIELDS = {"delta": ("L",), "m1": ("L",), "m2": ("L",), "t": (1,)}

    def __init__(self, num_parts: int, steps: int = 1, lr: float = REFINE_LR, max_change: float = WARM_MAX_CHANGE,
                 warmup: int = WARM_WARMUP):
        if check_refine_steps(steps) < 1:
            raise ValueError(f"warm code refinement needs steps >= 1 per encoding, got {steps}")
        if not isinstance(warmup, int) or warmup < 0:
            raise ValueError(f"warmup must be an integer >= 0 (steps), got {warmup!r}")
        super().__init__(num_parts, max_change)
        self.steps, self.lr = steps, float(lr)
        self.warmup = warmup
        self.encoded = self.restarted = 0

    def refine(self, net, z: torch.Tensor, xin: torch.Tensor, target: torch.Tensor, scale, parts) -> torch.Tensor:
        """z + delta after `steps` Adam steps from each (body, part)'s carried correction and moments, the state
        updated; delta a constant for autograd.

        Shape: z (B, K', latent) codes of `parts` ((K',) ids, None: all K), xin / target / scale from
        `refinement_points` -> (B, K', latent).
        """
        B, Kc = z.shape[:2]
        if Kc == 0:
            return z
        zd = z.detach()
        rows, kk, had, restart = self.lookup(zd, parts)
        s = self.state
        delta, m1, m2, t = (s[n][rows, kk].clone() for n in ("delta", "m1", "m2", "t"))
        fresh = (~had | restart)[..., None]
        delta, m1, m2, t = (x.masked_fill(fresh, 0) for x in (delta, m1, m2, t))
        var = adam_steps(net, zd + delta, xin, target, scale, parts, self.steps, m1, m2, t, self.lr, cosine=False,
                         warmup=self.warmup)
        s["delta"][rows, kk], s["m1"][rows, kk], s["m2"][rows, kk] = var - zd, m1, m2
        s["t"][rows, kk], s["zref"][rows, kk], s["have"][rows, kk] = t, zd, True
        self.encoded += B * Kc
        self.restarted += int(restart.sum())
        return z + (var - zd)
