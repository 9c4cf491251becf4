"""Learned refinement of the part codes z_k: an amortised correction of the encoder's one-pass codes.

The PointNet encoder lands 30-50 % of a code's norm away from the best code for a body: codes fitted per body with
the decoders fixed score ~95 mean IoU where the encoder's score ~91 (docs/code_refinement.md). Fitting by gradient
steps at test time closes much of that, at ~27 ms per body and step on one CPU thread. `LearnedCodeRefiner` makes
the correction in `iters` learned passes instead. Each pass reads, per (body, part):

- the code z_k and the part's one-hot id;
- the gradient g_k of the part's refinement loss (`refinement_losses`) with respect to z_k: one forward and
  backward of the part's decoder at its refinement points, as one step of test-time refinement computes it,
  given as the direction g / |g|, the per-coordinate ratio g / max |g| and log |g|;
- a PointNet summary of the decoder's residuals at those points: features (x, t / sigma, r) per point, where x is
  the point in the decoder's input frame, t its target signed distance, sigma = RESIDUAL_SIGMA, and r the residual
  clamp((d - t) / sigma) of the prediction d (an occupancy model: the occupancy minus the label t < 0);

and adds a correction z_k <- z_k + head([z_k, summary, one-hot, g features]). The head's last layer starts at
zero, so an untrained refiner leaves the codes as they are. The refinement points are the partition's tight-face
samples moved along their normals by +-t (`volsmpl.volume.code_refinement.refinement_points`): part k's own surface,
which other parts overlapping it cannot mislead.

Autograd: the gradient features and the residuals are computed on detached codes and are inputs of the pass, not
differentiated (the codes' dependence on them is first order in a small correction); gradients reach the head, the
PointNet, and the codes' own input z_k.

    refiner = LearnedCodeRefiner(num_parts=16, latent_dim=128, hidden=64, blocks=3, iters=1)
    z = refiner(net, z, xin, target, scale, parts)     # z (B, K', 128), xin (B, K', m, 3), target (B, K', m)
    z1 = refiner(net, z, xin, target, scale, parts, passes=1)   # the first pass only
"""
from __future__ import annotations

import torch
from torch import nn

from .pointnet import ResnetPointNet

__all__ = ["LearnedCodeRefiner", "refinement_losses", "RESIDUAL_SIGMA", "RESIDUAL_CLAMP"]

#: the scale (metres) of targets and residuals as the PointNet reads them: the refinement points' offsets' std
RESIDUAL_SIGMA = 0.003
#: residuals beyond this many RESIDUAL_SIGMA are read as this many (a far-off prediction says only "far off")
RESIDUAL_CLAMP = 10.0
#: the SDF refinement loss's weights (the training configs' abs_weight, sign_weight, sign_tau)
ABS_WEIGHT = 1e4
SIGN_WEIGHT = 0.25
SIGN_TAU = 1e-3


def refinement_losses(output: str, pred: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
    """Per-(body, part) refinement losses, means over the points: for output 'sdf' the training objective's form
    SIGN_WEIGHT softplus(-sgn(t) d / SIGN_TAU) + ABS_WEIGHT (d - t)^2 (d, t in metres), for 'occupancy' the binary
    cross-entropy of the occupancy against t < 0.

    Shape: pred, target (B, K', m) -> (B, K').
    Example: >>> refinement_losses('sdf', torch.zeros(1, 2, 4), torch.zeros(1, 2, 4))   # 0.25 log 2 per part
    """
    if output == "sdf":
        sign = torch.nn.functional.softplus(-torch.sign(target) * pred / SIGN_TAU)
        return (SIGN_WEIGHT * sign + ABS_WEIGHT * (pred - target).square()).mean(dim=-1)
    if output != "occupancy":
        raise ValueError(f"refinement_losses: output {output!r} is neither 'sdf' nor 'occupancy'")
    label = (target < 0).to(pred.dtype)
    return torch.nn.functional.binary_cross_entropy(pred.clamp(1e-6, 1 - 1e-6), label, reduction="none").mean(dim=-1)


def _residual(output: str, pred: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
    """What the PointNet reads of a prediction: for 'sdf' clamp((d - t) / RESIDUAL_SIGMA, +-RESIDUAL_CLAMP), for
    'occupancy' the occupancy minus the label t < 0 (in [-1, 1])."""
    if output == "sdf":
        return ((pred - target) / RESIDUAL_SIGMA).clamp(-RESIDUAL_CLAMP, RESIDUAL_CLAMP)
    return pred - (target < 0).to(pred.dtype)


def _pairs(B: int, Kc: int, m: int, device) -> tuple[torch.Tensor, torch.Tensor]:
    """(body, part-slot) ids of B * Kc * m points laid out as (B, Kc, m)."""
    b = torch.arange(B, device=device).repeat_interleave(Kc * m)
    k = torch.arange(Kc, device=device).repeat_interleave(m).repeat(B)
    return b, k


def decode_targets(net, z: torch.Tensor, xin: torch.Tensor, scale, parts) -> torch.Tensor:
    """The decoders of codes z (B, K', latent) of `parts` at their points xin (B, K', m, 3) -> (B, K', m), SDF in
    metres (scale (B, K', 1) of normalised part frames, or None) or occupancy."""
    B, Kc, m = xin.shape[:3]
    b, k = _pairs(B, Kc, m, z.device)
    pred = net.decode_pairs(xin.reshape(-1, 3), b, k, net.code_from_z(z, parts)).view(B, Kc, m)
    return pred * scale if scale is not None and net.output == "sdf" else pred


class LearnedCodeRefiner(nn.Module):
    """`iters` learned correction passes of part codes (module docstring).

    Args:
        num_parts: K (the one-hot ids).
        latent_dim: size of z_k.
        hidden: the residual PointNet's width (its summary has 2 hidden features).
        blocks: the PointNet's ResNet blocks.
        iters: passes, each with its own weights.
        head: width of the head's two hidden layers.
    """

    def __init__(self, num_parts: int, latent_dim: int = 128, hidden: int = 64, blocks: int = 3, iters: int = 1,
                 head: int = 256):
        super().__init__()
        if iters < 1:
            raise ValueError(f"LearnedCodeRefiner needs iters >= 1, got {iters}")
        self.num_parts, self.latent_dim, self.iters = int(num_parts), int(latent_dim), int(iters)
        self.point = nn.ModuleList([ResnetPointNet(2 * hidden, hidden, blocks, in_dim=5) for _ in range(iters)])
        width = 3 * latent_dim + 1 + 2 * hidden + num_parts
        self.head = nn.ModuleList()
        for _ in range(iters):
            h = nn.Sequential(nn.Linear(width, head), nn.ReLU(), nn.Linear(head, head), nn.ReLU(),
                              nn.Linear(head, latent_dim))
            nn.init.zeros_(h[-1].weight)
            nn.init.zeros_(h[-1].bias)
            self.head.append(h)

    def forward(self, net, z: torch.Tensor, xin: torch.Tensor, target: torch.Tensor, scale,
                parts: torch.Tensor | None = None, passes: int | None = None) -> torch.Tensor:
        """The refined codes after the first `passes` passes (None: all `iters`; 0: z as it is).

        Shape: z (B, K', latent) codes of `parts` ((K',) ids; None: all K), xin (B, K', m, 3) refinement points in
        the decoders' input frames, target (B, K', m) metres, scale (B, K', 1) or None -> (B, K', latent).
        """
        passes = self.iters if passes is None else passes
        if isinstance(passes, bool) or not isinstance(passes, int) or not 0 <= passes <= self.iters:
            raise ValueError(f"LearnedCodeRefiner: passes {passes!r} is not an integer in 0..{self.iters}")
        B, Kc, m = target.shape
        if z.shape[:2] != (B, Kc) or xin.shape[:3] != (B, Kc, m):
            raise ValueError(f"LearnedCodeRefiner: codes {tuple(z.shape)}, points {tuple(xin.shape)} and targets "
                             f"{tuple(target.shape)} disagree on (bodies, parts, points)")
        if Kc == 0 or passes == 0:
            return z
        ids = torch.arange(self.num_parts, device=z.device) if parts is None else parts
        onehot = torch.nn.functional.one_hot(ids, self.num_parts).to(z.dtype).expand(B, -1, -1)
        t_feat = (target / RESIDUAL_SIGMA)[..., None]
        for it in range(passes):
            with torch.enable_grad():
                zg = z.detach().requires_grad_(True)
                pred = decode_targets(net, zg, xin, scale, parts)
                (g,) = torch.autograd.grad(refinement_losses(net.output, pred, target).sum(), zg)
            pred = pred.detach()
            norm = g.norm(dim=-1, keepdim=True).clamp_min(1e-12)
            ratio = g / g.abs().amax(dim=-1, keepdim=True).clamp_min(1e-12)
            res = _residual(net.output, pred, target)[..., None]
            feats = torch.cat([xin.detach(), t_feat, res], dim=-1).reshape(B * Kc, m, 5)
            summary = self.point[it](feats).view(B, Kc, -1)
            z = z + self.head[it](torch.cat([z, summary, onehot, g / norm, ratio, norm.log()], dim=-1))
        return z
