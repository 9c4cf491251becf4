"""A learned volume's code refinement setting (`Volume` inherits it): cold refinement of every fresh encoding, or
refinement carried from one encoding to the next inside an optimisation's `warm_start()` scope; and for a model
with learned passes, the interval at which they run inside such a scope.

    vol.set_code_refinement(40)                     # every fresh encoding: 40 steps from the encoder's codes
    vol.set_code_refinement(1, warm=True)
    with vol.warm_start() as warm:                  # the optimisation harness opens one per run
        with vol.warm_keys(rows): ...               # the next encodings hold the bodies `rows`
    vol.set_pass_interval(4)                        # inside warm_start: the learned passes at every 4th encoding
    vol.set_passes(1)                               # the first of the model's learned passes only (0: none)
"""
from __future__ import annotations

import contextlib

from volsmpl.volume.carried_passes import CarriedPasses, check_pass_interval
from volsmpl.volume.code_refinement import check_refine_steps
from volsmpl.volume.warm_codes import WarmCodes

__all__ = ["CodeRefinementSetting", "check_passes"]


def check_passes(passes, name: str = "learned passes") -> int | None:
    """`passes` as None (all the model's learned passes) or an int >= 0, else ValueError (one line, headed by
    `name`)."""
    if passes is not None and (isinstance(passes, bool) or not isinstance(passes, int) or passes < 0):
        raise ValueError(f"{name} {passes!r}: give an integer >= 0 (0: the encoder's codes as they are)")
    return passes


class CodeRefinementSetting:
    """The setting's methods; needs the volume's `num_parts`, `net` and the attributes `refine_steps`,
    `refine_warm`, `warm` (the open scope's WarmCodes, else None), `passes` (set_passes), `pass_every`, `carried`
    (the open scope's CarriedPasses, else None) and `warm_serial` (scopes opened so far: part of the encoding
    cache's key), set by the volume's constructor."""

    @property
    def active_passes(self) -> int:
        """How many learned passes each encoding runs: `set_passes`'s count, else all the network has (0 without
        a refiner)."""
        iters = 0 if self.net.refiner is None else self.net.refiner.iters
        return iters if self.passes is None else self.passes

    def set_passes(self, passes: int | None):
        """Run only the first `passes` of the network's learned code-refinement passes at each encoding (None, the
        default: all of them; 0: the encoder's codes as they are), also in training; returns self. Encodings cached
        before are not reused. ValueError (one line) for a count that is not an integer >= 0, above the network's
        passes, or 0 while the passes run at an interval (`set_pass_interval`)."""
        passes = check_passes(passes)
        iters = 0 if self.net.refiner is None else self.net.refiner.iters
        if passes is not None and passes > iters:
            hint = (f"give --passes 0..{iters}" if iters else "drop the setting for it" if self.kind != "volsmpl"
                    else "give --passes 0, or a checkpoint with them (e.g. checkpoints/volsmpl_r3/ckpt-00057000/model)")
            raise ValueError(f"--passes {passes}: this model has {iters} learned code-refinement passes; {hint}")
        if passes == 0 and self.pass_every > 1:
            raise ValueError(f"--passes 0 runs no learned passes, so there is none to run at an interval: set the "
                             f"interval ({self.pass_every}) back to 1 (--pass-every 1) or give --passes 1 or more")
        self.passes = passes
        return self

    def set_code_refinement(self, steps: int, warm: bool = False):
        """Refine each fresh encoding's part codes by `steps` Adam steps on the posed mesh's own surface
        (volsmpl.volume.code_refinement; 0, the default: the encoder's codes as they are); returns self. Not while
        training, nor on training's fresh surface draws. Encodings cached before are not reused (their key holds
        the setting). warm: inside `warm_start()` (the optimisation harness opens one per run), each encoding
        continues the same bodies' refinement from the previous encoding (volsmpl.volume.warm_codes) with `steps`
        steps at a constant step size; outside one, each encoding is refined from the encoder's codes.
        ValueError (one line) for steps < 0, or warm with steps 0."""
        steps = check_refine_steps(steps)
        if warm and steps == 0:
            raise ValueError("warm code refinement needs steps >= 1 per encoding (e.g. --refine-steps 1)")
        if warm and self.pass_every > 1:
            raise ValueError(f"warm code refinement carries its own correction: set the learned passes' interval "
                             f"({self.pass_every}) back to 1 first (--pass-every 1)")
        self.refine_steps, self.refine_warm = steps, bool(warm)
        return self

    def set_pass_interval(self, every: int):
        """Inside `warm_start()`, run the network's learned code-refinement passes at every `every`-th encoding
        of a body only, and add the correction they made to the encoder's codes of the encodings between
        (volsmpl.volume.carried_passes); 1, the default: the passes at every encoding. Outside a scope, and in
        training, every encoding runs the passes. Returns self. ValueError (one line) for an interval that is not
        an integer >= 1, above 1 on a network without learned passes, or with warm code refinement."""
        every = check_pass_interval(every)
        if every > 1 and self.net.refiner is None:
            raise ValueError(f"--pass-every {every}: this model has no learned code-refinement passes "
                             f"(refiner_iters 0); give a checkpoint with them (e.g. checkpoints/volsmpl_r3/"
                             f"ckpt-00057000/model) or --pass-every 1")
        if every > 1 and self.active_passes == 0:
            raise ValueError(f"--pass-every {every}: the learned passes are turned off (--passes 0); give --passes 1 "
                             f"or more, or --pass-every 1")
        if every > 1 and self.refine_warm:
            raise ValueError(f"--pass-every {every} carries the learned passes' correction, and warm code refinement "
                             f"carries its own: use one of them")
        self.pass_every = every
        return self

    @contextlib.contextmanager
    def warm_start(self):
        """One optimisation's scope of warm code refinement (`set_code_refinement(steps, warm=True)`) or of
        learned passes at an interval (`set_pass_interval(N)`, N > 1): the encodings inside carry their bodies'
        code corrections from one to the next; yields the WarmCodes or CarriedPasses state (its counters), or None
        where the volume is set to neither. Encodings cached outside the scope are not reused inside it, nor the
        scope's outside."""
        warm = bool(self.refine_warm and self.refine_steps)
        carry = self.pass_every > 1 and self.active_passes > 0
        if not (warm or carry):
            yield None
            return
        before = self.warm, self.carried
        self.warm_serial += 1
        self.warm = WarmCodes(self.num_parts, self.refine_steps) if warm else None
        self.carried = CarriedPasses(self.num_parts, self.pass_every) if carry else None
        try:
            yield self.warm if warm else self.carried
        finally:
            self.warm, self.carried = before
            self.warm_serial += 1   # the scope's encodings are not served after it

    def warm_keys(self, ids):
        """Inside `warm_start`: the encodings inside this context hold the bodies `ids` ((B,) distinct ints,
        KeyedPartState.keys); elsewhere nothing."""
        state = self.warm if self.warm is not None else self.carried
        return contextlib.nullcontext() if state is None else state.keys(ids)
