"""A learned volume's code refinement setting (`Volume` inherits it): cold refinement of every fresh encoding, or
refinement carried from one encoding to the next inside an optimisation's `warm_start()` scope.

    vol.set_code_refinement(40)                     # every fresh encoding: 40 steps from the encoder's codes
    vol.set_code_refinement(1, warm=True)
    with vol.warm_start() as warm:                  # the optimisation harness opens one per run
        with vol.warm_keys(rows): ...               # the next encodings hold the bodies `rows`
"""
from __future__ import annotations

import contextlib

from volsmpl.volume.code_refinement import check_refine_steps
from volsmpl.volume.warm_codes import WarmCodes

__all__ = ["CodeRefinementSetting"]


class CodeRefinementSetting:
    """The setting's methods; needs the volume's `num_parts` and the attributes `refine_steps`, `refine_warm`,
    `warm` (the open scope's WarmCodes, else None) and `warm_serial` (scopes opened so far: part of the encoding
    cache's key), set by the volume's constructor."""

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
        self.refine_steps, self.refine_warm = steps, bool(warm)
        return self

    @contextlib.contextmanager
    def warm_start(self):
        """One optimisation's scope of warm code refinement (`set_code_refinement(steps, warm=True)`): the
        encodings inside carry their bodies' code corrections from one to the next; yields the WarmCodes state
        (its counters), or None where the volume is not set to warm refinement. Encodings cached outside the
        scope are not reused inside it, nor the scope's outside."""
        if not (self.refine_warm and self.refine_steps):
            yield None
            return
        before = self.warm
        self.warm_serial += 1
        self.warm = WarmCodes(self.num_parts, self.refine_steps)
        try:
            yield self.warm
        finally:
            self.warm = before
            self.warm_serial += 1   # the scope's encodings are not served after it

    def warm_keys(self, ids):
        """Inside `warm_start`: the encodings inside this context hold the bodies `ids` ((B,) distinct ints,
        WarmCodes.keys); elsewhere nothing."""
        return contextlib.nullcontext() if self.warm is None else self.warm.keys(ids)
