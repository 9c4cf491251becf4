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
"""
from __future__ import annotations

import torch

from volsmpl.geometry.boxes import inside_boxes
from volsmpl.body.partition import Partition

from .pose import identity_pose, leg_mask, pose_body

WRT = ("denoised", "noisy")
JOINTS = ("all", "legs")
REDUCE = ("mean", "code")
FAR = 100.0  # metres above the pelvis where padding points sit (outside every part box)


class CollisionScore:
    """J(x) of one batch of frames (module docstring). betas (B, 10), pelvis (B, 3) fixed; points (B, N, 3)."""

    def __init__(self, body, volume, betas: torch.Tensor, pelvis: torch.Tensor, points: torch.Tensor,
                 wrt: str = "denoised", joints: str = "all", reduce: str = "mean", margin: float = 0.5):
        for name, v, ok in (("wrt", wrt, WRT), ("joints", joints, JOINTS), ("reduce", reduce, REDUCE)):
            if v not in ok:
                raise ValueError(f"guidance {name}={v!r}; choose one of {', '.join(ok)}")
        if points.ndim != 3 or points.shape[-1] != 3 or points.shape[0] != betas.shape[0]:
            raise ValueError(f"guidance points must be (B, N, 3) with B = {betas.shape[0]} frames, got {tuple(points.shape)}")
        if points.shape[1] == 0:
            raise ValueError("no scene points near the body to guide with: give a scene with points around the person")
        self.body, self.volume, self.betas, self.pelvis, self.points = body, volume, betas, pelvis, points
        self.wrt, self.joints, self.reduce, self.margin = wrt, joints, reduce, margin
        self.last = None

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
        out = pose_body(self.body, self.betas, x, self.pelvis)
        return self.per_point(out).sum(1) / self.points.shape[1]

    def gradient(self, x_t: torch.Tensor, x0_hat: torch.Tensor, t: int) -> torch.Tensor:
        """dJ/dx at the denoised estimate (wrt='denoised') or the noisy sample ('noisy'); 0 for a frame whose pose
        holds NaN or Inf (a diverged sample stays diverged, the batch's other frames go on). Shape: -> (B, 144)."""
        x = (x0_hat if self.wrt == "denoised" else x_t).detach()
        ok = torch.isfinite(x).all(-1, keepdim=True)
        x = torch.where(ok, x, identity_pose(len(x), x.dtype, x.device)).requires_grad_(True)
        with torch.enable_grad():
            out = pose_body(self.body, self.betas, x, self.pelvis)
            pen = self.per_point(out)
            per_frame = pen.sum(1) / self.points.shape[1]
            self.last = per_frame.detach()
            if self.reduce == "mean":
                total = per_frame.sum()  # frames are independent: each gets its own mean's gradient
            elif self.volume.kind == "coap":
                total = pen.sum() / (pen.shape[0] * self.points.shape[1])  # the code's mean over batch and points
            else:
                total = pen.sum()  # the code's sum over points and frames
            (g,) = torch.autograd.grad(total, x)
        if self.joints == "legs":
            g = g * leg_mask(g.dtype, g.device)
        return torch.where(ok, g, 0.0)


__all__ = ["CollisionScore", "WRT", "JOINTS", "REDUCE"]
