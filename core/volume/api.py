"""`BodyVolume`: what every model kind answers (volsmpl.volume.models), so the apps never branch on the kind.

    d = volume.signed(out, points)          # (B, N): negative inside, positive outside, 0 on the surface
    loss = volume.collision_loss(out, points)
    loss = volume.selfpen_loss(out)         # (B,)

Subclasses: `Volume` (the learned kinds 'volsmpl' and 'coap') and `MeshVolume` (the exact 'mesh' kind).
"""
from __future__ import annotations

import contextlib

import torch

from volsmpl.volume.collision import reduce_penetration


def check_output(out) -> None:
    """A clear error unless `out` is a body forward output: tensors vertices (B, V, 3), joints (B, J, 3) and
    full_pose (B, J*3) (or (B, J, 3)) of the same B >= 1 bodies (shapes only: no pass over the values)."""
    for name in ("vertices", "joints", "full_pose"):
        if not torch.is_tensor(getattr(out, name, None)):
            raise TypeError(f"expected a body forward output with tensor '{name}' (call body(...) first), got {type(out).__name__}")
    v, j, p = out.vertices, out.joints, out.full_pose
    if v.ndim != 3 or v.shape[-1] != 3 or j.ndim != 3 or j.shape[-1] != 3 or p.ndim not in (2, 3):
        raise ValueError(f"the body output has vertices {tuple(v.shape)}, joints {tuple(j.shape)}, full_pose "
                         f"{tuple(p.shape)}; expected (B, V, 3), (B, J, 3), (B, J*3) as body(...) returns (one body of a "
                         f"batch: volsmpl.body.view.select_body(out, b)).")
    if not v.shape[0] == j.shape[0] == p.shape[0]:
        raise ValueError(f"the body output's fields are for different numbers of bodies: vertices {tuple(v.shape)}, joints "
                         f"{tuple(j.shape)}, full_pose {tuple(p.shape)}; give all of one batch of bodies (slice "
                         f"them together, or volsmpl.body.view.select_body(out, b)).")
    if v.shape[0] == 0:
        raise ValueError("the body output holds 0 bodies; query at least one (skip the call when there is none).")


class BodyVolume(torch.nn.Module):
    """The interface (module docstring). A subclass sets `kind` and `partition` and implements `query`,
    `query_parts`, `to_signed`, `occupied`, `penetration`, `selfpen_loss` and `extract_mesh`."""

    kind: str = ""
    #: the decoders' arithmetic ('full' here; networks with reduced-precision modes override set_precision)
    precision: str = "full"

    @property
    def device(self) -> torch.device:
        return self.partition.faces.device

    def set_precision(self, precision: str) -> "BodyVolume":
        """Set the arithmetic of the queries; 'full' is the only mode of this kind (ValueError for another)."""
        if precision != "full":
            raise ValueError(f"the {self.kind} volume computes in full precision only, got precision {precision!r}; "
                             f"use 'full'")
        return self

    def set_encoder_draws(self, draws: int) -> "BodyVolume":
        """Set how many surface sample sets the encoder averages over; kinds without an encoder (the exact mesh)
        refuse any setting (ValueError, one line)."""
        raise ValueError(f"the {self.kind} volume has no encoder, so encoder draws ({draws!r}) do not apply; drop "
                         f"the setting for it.")

    def set_code_refinement(self, steps: int) -> "BodyVolume":
        """Set the test-time refinement of the part codes; kinds without codes (the exact mesh) refuse any setting
        (ValueError, one line)."""
        raise ValueError(f"the {self.kind} volume has no part codes, so code refinement ({steps!r} steps) does not "
                         f"apply; drop the setting for it.")

    def set_pass_interval(self, every: int) -> "BodyVolume":
        """Set the interval of the learned code-refinement passes; kinds without them (the exact mesh) refuse an
        interval above 1 (ValueError, one line)."""
        if every != 1:
            raise ValueError(f"the {self.kind} volume has no learned code-refinement passes, so an interval "
                             f"({every!r}) does not apply; drop the setting for it.")
        return self

    #: learned code-refinement passes each encoding runs (none: this kind has no part codes), and the count set
    active_passes: int = 0
    passes: int | None = None

    def set_passes(self, passes) -> "BodyVolume":
        """Set how many learned code-refinement passes run; kinds without them (the exact mesh) refuse a count
        above 0 (ValueError, one line) and take None or 0."""
        if passes not in (None, 0) or isinstance(passes, bool):
            raise ValueError(f"the {self.kind} volume has no learned code-refinement passes, so a count of them "
                             f"({passes!r}) does not apply; drop the setting for it.")
        return self

    @contextlib.contextmanager
    def warm_start(self):
        """One optimisation's scope of code corrections carried from one encoding to the next; kinds without part
        codes carry nothing (yields None). Every optimisation may open one, whatever the kind."""
        yield None

    def warm_keys(self, ids):
        """Inside `warm_start`: which bodies the next encodings hold; kinds without part codes ignore it."""
        return contextlib.nullcontext()

    @property
    def num_parts(self) -> int:
        return self.partition.num_parts

    def signed(self, out, points: torch.Tensor) -> torch.Tensor:
        """`query` in the sign convention every kind shares: negative inside, positive outside, 0 on the surface.
        points (B, N, 3) or (N, 3) -> (B, N)."""
        return self.to_signed(self.query(out, points))

    def collision_loss(self, out, points: torch.Tensor, reduction: str = "mean") -> torch.Tensor:
        """Penetration of points into the bodies (the kind's `penetration` of its query values, as the paper
        scores scene points, supp. D.2). reduction: 'mean' (scalar over all bodies and points), 'sum' (per
        body, (B,)) or 'none' ((B, N))."""
        return reduce_penetration(self.penetration(self.query(out, points)), reduction)
