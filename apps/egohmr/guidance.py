"""The collision score J of EgoHMR's guided sampling (supp. D.2) for any model kind, and its gradient.

    guide = CollisionScore(body, volume, betas, pelvis, points)     # points (B, N, 3): N scene points per frame
    J = guide.score(x)                                              # (B,) for pose vectors x (B, 144)
    g = guide.gradient(x_t, x0_hat, t)                              # dJ/dx (B, 144), for diffusion.Guidance

J is the kind's `collision_loss` per scene point (VolumetricSMPL and 'mesh': ReLU(-sdf); COAP: the occupancy
where above 0.5, the paper's sigmoid(f) 1[f > 0]) averaged over the frame's N points, as the paper writes it for
both models. Points outside every padded part box are left out of the evaluation (their penetration is exactly 0
for every kind) while the mean still divides by N, so J is unchanged.

Options (the authors' released code departs from the paper; each is a flag, not the default):
- `wrt`: 'denoised' (default: J of the denoiser's clean estimate, "given a denoised SMPL body", main text
  Sec. 4.2.2) or 'noisy' (J of the noisy sample theta_t itself, as the code does);
- `joints`: 'all' (default) or 'legs' (the gradient kept on the hip and leg joints only, as the code);
- `reduce`: 'mean' (default, the paper's 1/|P| sum for both models) or 'code' (COAP a mean over the batch's
  frames and points, VolumetricSMPL and 'mesh' a sum over points and frames: the effective scale then depends
  on the batch size and the number of points).

The pelvis (the paper keeps the regressed one fixed; pelvis_step 0 and no support give its guidance):
- `pelvis_step` (metres, > 0): each guided step also moves the pelvis by pelvis_step down J's gradient with respect
  to the body's translation, normalised (a frame with J = 0 stays); the same J of the same kind as the pose's
  gradient, from the same evaluation;
- `support` (support.SupportGap): after the pelvis step, each guided step moves the pelvis so that the body's
  lowest points rest on the scene's support below it (the gap g of support.py closed): always where they have sunk
  into it (g < 0), where they float (g > 0) only if J was 0 (a body that penetrates the scene elsewhere, e.g. a
  seat, is not pulled down into it); a support step may not raise J above its value before the guided step: along
  the ray, a move that does is replaced by the vertical move of the same change of height, and that, if it does
  too, by none (the ray of a body leaning on the wall behind it runs into that wall);
- `along`: 'ray' (default) moves the pelvis only along the camera ray through it (the camera at the origin): the
  pelvis step is J's gradient projected on the ray, the support step the move along the ray that changes the height
  by -g (at most RAY_MAX, none where the ray is within 6 degrees of horizontal); 'free': the pelvis step in 3D and
  the support step along up.
`placed()` is the pelvis these moves reached (pelvis + offset), the one the sample's body is made with.

Why: MPJPE aligns the pelvises, so moving the whole body costs no MPJPE, while the pose-only guidance at the paper's
scale raised MPJPE by 2.8 mm for 21 % fewer penetrating points (test split, 200 frames: docs/egohmr/results.json).
The keypoints fix the pelvis's image position; its depth is what they leave uncertain. With the pose unguided and
pelvis steps of 1 cm ('mesh' guide, first 64 val frames, `volsmpl egohmr tune --split val --frames 64 --model mesh
--factors 0 --pelvis-step 0.01 --pelvis-along A`), 'ray' / 'free' take the collision ratio from 0.00424 to 0.00071 /
0.00104, contact from 75 to 100 / 100 %, the pelvis error from 107 to 100 / 103 mm and the mean reprojection error
of the joints (status.py) from 0.0432 to 0.0461 / 0.0536; on all 200 val frames (`--frames` left out) collision
0.00579 -> 0.00211 / 0.00148, contact 70 -> 96 / 96 %, pelvis error 122 -> 124 / 127 mm, reprojection 0.0394 ->
0.0440 / 0.0553. 'ray' keeps the bodies consistent with the keypoints; it resolves less of the penetration of
bodies leaning on a wall (lateral to the ray: collision 0.0178 -> 0.0047 / 0.0011, pelvis error 134 -> 169 / 137 mm,
30 frames).
J's own gradient cannot lift deeply sunk feet: for points nearer the top of a thin part (toes 3 cm into a floor)
it points down, deeper (tests/apps/egohmr/test_support.py); the support term's inside test lifts them.
"""
from __future__ import annotations

import torch

from volsmpl.geometry.boxes import inside_boxes
from volsmpl.body.partition import Partition

from .pose import identity_pose, leg_mask, pose_body

WRT = ("denoised", "noisy")
JOINTS = ("all", "legs")
REDUCE = ("mean", "code")
ALONG = ("ray", "free")
RAY_MAX = 0.3  # metres a support step may move the pelvis along its ray
FAR = 100.0  # metres above the pelvis where padding points sit (outside every part box)


class CollisionScore:
    """J(x) of one batch of frames (module docstring). betas (B, 10), pelvis (B, 3) the regressed pelvis (moved by
    `pelvis_step` and `support` when given); points (B, N, 3)."""

    def __init__(self, body, volume, betas: torch.Tensor, pelvis: torch.Tensor, points: torch.Tensor,
                 wrt: str = "denoised", joints: str = "all", reduce: str = "mean", margin: float = 0.5,
                 pelvis_step: float = 0.0, support=None, along: str = "ray"):
        for name, v, ok in (("wrt", wrt, WRT), ("joints", joints, JOINTS), ("reduce", reduce, REDUCE)):
            if v not in ok:
                raise ValueError(f"guidance {name}={v!r}; choose one of {', '.join(ok)}")
        if points.ndim != 3 or points.shape[-1] != 3 or points.shape[0] != betas.shape[0]:
            raise ValueError(f"guidance points must be (B, N, 3) with B = {betas.shape[0]} frames, got {tuple(points.shape)}")
        if points.shape[1] == 0:
            raise ValueError("no scene points near the body to guide with: give a scene with points around the person")
        self.body, self.volume, self.betas, self.pelvis, self.points = body, volume, betas, pelvis, points
        if not pelvis_step >= 0:
            raise ValueError(f"guidance pelvis_step={pelvis_step!r}: metres per guided step, >= 0")
        if along not in ALONG:
            raise ValueError(f"guidance along={along!r}; choose one of {', '.join(ALONG)}")
        self.wrt, self.joints, self.reduce, self.margin = wrt, joints, reduce, margin
        self.pelvis_step, self.support, self.along = float(pelvis_step), support, along
        self.offset = torch.zeros_like(pelvis)
        self.last = None

    @property
    def moves_pelvis(self) -> bool:
        """Whether a guided step moves the pelvis (pelvis_step or support given)."""
        return self.pelvis_step > 0 or self.support is not None

    def placed(self) -> torch.Tensor:
        """The pelvis the guided steps reached: the regressed one plus their moves. Shape: (B, 3)."""
        return self.pelvis + self.offset

    @torch.no_grad()
    def settle(self, x: torch.Tensor, free: torch.Tensor | None = None,
               limit: torch.Tensor | None = None) -> torch.Tensor:
        """One support step for poses x (B, 144): the pelvis moved by -g * up where the body has sunk into its
        support (g < 0), and where it floats (g > 0) only in the frames `free` (B,) bool (None: all); frames whose
        pose is not finite stay. limit (B,): the largest J a frame may have after the step (None: no check): a move
        along the ray that ends above it is replaced by the vertical move of the same change of height, and that,
        if it ends above it too, by none. Returns `placed()`."""
        if self.support is None:
            return self.placed()
        ok = torch.isfinite(x).all(-1)
        safe = torch.where(ok[:, None], x, identity_pose(len(x), x.dtype, x.device))
        g = self.support.gap(pose_body(self.body, self.betas, safe, self.placed()).vertices)
        g = torch.where(torch.isfinite(g), g, 0.0)
        move = ok & ((g < 0) | (True if free is None else free.to(ok.device)))
        if not bool(move.any()):
            return self.placed()
        up = self.support.up.to(g.dtype)
        shifts = []
        if self.along == "ray":      # along the camera ray through the pelvis, by the same change of height
            r = self._ray()
            ru = (r * up).sum(-1)
            run = torch.where(ru.abs() > 0.1, g / ru.abs().clamp_min(0.1), 0.0).clamp(-RAY_MAX, RAY_MAX)
            shifts.append((run * torch.sign(ru))[:, None] * r)
        if self.along == "free" or limit is not None:  # 'free', or the fallback of a ray move that raised J
            shifts.append(g[:, None] * up)
        start, new, open_ = self.offset, self.offset, move
        for shift in shifts:
            if not bool(open_.any()):  # every moving frame took an earlier move
                break
            cand = start - shift.to(start.dtype)
            take = open_
            if limit is not None:
                self.offset = cand
                take = take & (self.score(safe) <= limit.to(g.dtype))
            new = torch.where(take[:, None], cand, new)
            open_ = open_ & ~take
        self.offset = new
        return self.placed()

    def _ray(self) -> torch.Tensor:
        """Unit camera rays through the current pelvises (the camera at the origin). Shape: (B, 3)."""
        p = self.placed()
        return p / p.norm(dim=-1, keepdim=True).clamp_min(1e-6)

    @torch.no_grad()
    def _near(self, out) -> torch.Tensor:
        """Each frame's points inside one of its body's padded part boxes, padded with far points. (B, M, 3).
        Points outside every box penetrate by exactly 0 for every kind (the analytic box SDF is positive there,
        COAP's occupancy 0, and the mesh lies inside its parts' boxes), so leaving them out changes no value."""
        part, P = self.volume.partition, self.points
        V = out.vertices.detach()
        lo, hi = V.amin(1, keepdim=True) - self.margin, V.amax(1, keepdim=True) + self.margin
        cand = ((P >= lo) & (P <= hi)).all(-1)  # (B, N): a cheap first cut
        G = part.part_transforms(out.full_pose.detach(), out.joints.detach())
        bmin, bmax = part.boxes(V, G)
        kept = []
        for b in range(len(P)):
            c = P[b][cand[b]]
            ins = inside_boxes(Partition.canonicalize(c[None], G[b:b + 1]), bmin[b:b + 1], bmax[b:b + 1])[0]
            kept.append(c[ins.any(0)])
        m = max(max(len(k) for k in kept), 1)
        far = self.pelvis[:, None].to(P.dtype) + torch.tensor([0.0, -FAR, 0.0], dtype=P.dtype, device=P.device)
        near = far.expand(len(P), m, 3).clone()
        for b, k in enumerate(kept):
            near[b, : len(k)] = k
        return near

    def per_point(self, out) -> torch.Tensor:
        """Penetration of the near points into the bodies of `out`: (B, M), far padding 0."""
        return self.volume.collision_loss(out, self._near(out), reduction="none")

    def score(self, x: torch.Tensor) -> torch.Tensor:
        """J per frame. Shape: (B, 144) -> (B,)."""
        out = pose_body(self.body, self.betas, x, self.placed())
        return self.per_point(out).sum(1) / self.points.shape[1]

    def gradient(self, x_t: torch.Tensor, x0_hat: torch.Tensor, t: int) -> torch.Tensor:
        """dJ/dx at the denoised estimate (wrt='denoised') or the noisy sample ('noisy'); 0 for a frame whose pose
        holds NaN or Inf (a diverged sample stays diverged, the batch's other frames go on). From the same
        evaluation of J, moves the pelvis by a pelvis step, then by a support step (class docstring).
        Shape: -> (B, 144)."""
        x = (x0_hat if self.wrt == "denoised" else x_t).detach()
        ok = torch.isfinite(x).all(-1, keepdim=True)
        x = torch.where(ok, x, identity_pose(len(x), x.dtype, x.device)).requires_grad_(True)
        offset = self.offset.detach().clone().requires_grad_(self.pelvis_step > 0)
        with torch.enable_grad():
            out = pose_body(self.body, self.betas, x, self.pelvis + offset)
            pen = self.per_point(out)
            per_frame = pen.sum(1) / self.points.shape[1]
            self.last = per_frame.detach()
            if self.reduce == "mean":
                total = per_frame.sum()  # frames are independent: each gets its own mean's gradient
            elif self.volume.kind == "coap":
                total = pen.sum() / (pen.shape[0] * self.points.shape[1])  # the code's mean over batch and points
            else:
                total = pen.sum()  # the code's sum over points and frames
            if self.pelvis_step > 0:
                g, gp = torch.autograd.grad(total, (x, offset))
                if self.along == "ray":
                    r = self._ray()
                    gp = (gp * r).sum(-1, keepdim=True) * r
                n = gp.norm(dim=-1, keepdim=True)
                move = ok & (n > 0)
                self.offset = self.offset - torch.where(move, self.pelvis_step * gp / n.clamp_min(1e-30), 0.0)
            else:
                (g,) = torch.autograd.grad(total, x)
        if self.support is not None:
            self.settle(torch.where(ok, x.detach(), float("nan")), free=self.last <= 0, limit=self.last)
        if self.joints == "legs":
            g = g * leg_mask(g.dtype, g.device)
        return torch.where(ok, g, 0.0)


__all__ = ["CollisionScore", "WRT", "JOINTS", "REDUCE", "ALONG"]
