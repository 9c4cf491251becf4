"""Test-time refinement of the part codes z_k on the posed mesh's own surface (`Volume.set_code_refinement`).

The encoder maps each part's surface samples to z_k in one pass. Codes fitted to a body do far better: with the
decoders fixed, codes fitted to exact distances on held-out points lift the validation IoU from ~90 to ~95
(docs/code_refinement.md, `docs/scripts/code_oracle.py`). The same gain needs no ground truth beyond the mesh
itself: a point s on part k's own faces, moved along its face normal n by t, is at signed distance ~t from the
surface (first order, for |t| of a few millimetres), and that holds for part k's own decoder whatever other parts
overlap it (self-intersecting poses), since the parts' minimum is taken afterwards.

So `refine_codes` takes R steps of Adam on z (cosine-decayed step size from REFINE_LR, scaled by min(1, i / 10) at
the i-th step: REFINE_WARMUP), each part k fitted on
its own points: the partition's fixed tight-face samples (`Partition.tight_samples`, those the encoder reads),
each moved by +t and -t along its posed face normal, t ~ N(0, REFINE_SIGMA^2) from a fixed seed (deterministic,
smooth in pose). The loss per (body, part) is the training objective's form on those points: for SDF models
0.25 softplus(-sgn(t) d / 1 mm) + 1e4 (d - t)^2 (the training configs' weights), for occupancy models (COAP) the
binary cross-entropy of the occupancy against t < 0 (`volsmpl.nn.code_refiner.refinement_losses`); means over the
part's points, summed over parts and bodies, so each part's code follows its own loss alone (Adam is per
coordinate): refining some parts gives the same codes as refining all.

Autograd: the refined code is z + delta with delta a constant, so gradients reach the body through the encoder
and the part frames as without refinement (the correction's own dependence on the pose is not differentiated).

    z_ref = refine_codes(net, z, xin, target, scale, parts, steps=40)    # (B, K', latent)
"""
from __future__ import annotations

import math

import torch

from volsmpl.nn.code_refiner import decode_targets, refinement_losses

__all__ = ["REFINE_LR", "REFINE_SIGMA", "REFINE_WARMUP", "refinement_points", "adam_steps", "refine_codes", "check_refine_steps"]

#: Adam's initial step size on z (cosine-decayed to 0 over the steps)
REFINE_LR = 1e-2
#: std of the offsets t along the normals, metres
REFINE_SIGMA = 0.003
#: seed of the fixed offsets
REFINE_SEED = 20260127
#: steps over which the step size rises linearly to its schedule's value (per (body, part)): Adam's first steps
#: move every coordinate by about the full step size whatever its gradient (one cold step from the encoder's codes:
#: 91.36 -> 85.79 mean IoU on 16 validation bodies; R = 40: 93.79 without, 94.01 with, docs/code_refinement.md)
REFINE_WARMUP = 10


def check_refine_steps(steps, name: str = "code refinement steps") -> int:
    """steps as an int >= 0; ValueError (one line, headed by `name`, e.g. '--refine-steps') otherwise."""
    if not isinstance(steps, int) or isinstance(steps, bool) or steps < 0:
        raise ValueError(f"{name} {steps!r}: give an integer >= 0 (0: the encoder's codes as they are).")
    return steps


def refinement_points(partition, vertices: torch.Tensor, G: torch.Tensor, center, scale,
                      parts: torch.Tensor | None = None):
    """Each part's fitting points in its decoder's input frame, with their targets.

    Shape: vertices (B, V, 3) posed; G (B, K', 4, 4), center / scale (B, K', 3) / (B, K', 1) or None (no part
    normalisation) of the parts `parts` ((K',) ids; None: all K) -> xin (B, K', 2n, 3), target t (B, K', 2n)
    metres, scale (B, K', 1) or None; n = draws * n_samples // 2 tight-face samples per part, each at +t and -t.
    """
    faces, bary = partition.tight_samples()                              # (K, n), (K, n, 3)
    if parts is not None:
        faces, bary = faces[parts], bary[parts]
    v = vertices.detach()
    B = v.shape[0]
    tri = v[torch.arange(B, device=v.device)[:, None, None, None], partition.faces[faces]]   # (B, K', n, 3, 3)
    s = (bary.to(v.dtype)[..., None] * tri).sum(dim=-2)                   # (B, K', n, 3)
    normal = torch.linalg.cross(tri[..., 1, :] - tri[..., 0, :], tri[..., 2, :] - tri[..., 0, :], dim=-1)
    normal = normal / normal.norm(dim=-1, keepdim=True).clamp_min(1e-30)
    g = torch.Generator().manual_seed(REFINE_SEED)
    t = (torch.randn(partition.num_parts, faces.shape[1], generator=g, dtype=torch.float64) * REFINE_SIGMA)
    t = (t if parts is None else t[parts.cpu()]).to(v.device, v.dtype)  # a part's offsets do not depend on parts
    t = torch.cat([t, -t], dim=-1).expand(B, -1, -1)                      # (B, K', 2n)
    x = torch.cat([s, s], dim=2) + t[..., None] * torch.cat([normal, normal], dim=2)
    local = partition.to_part_frames(x, G.detach())
    if scale is not None:
        local = (local - center.detach()[:, :, None]) / scale.detach()[:, :, None]
        scale = scale.detach()
    return local, t, scale


def adam_steps(net, z: torch.Tensor, xin: torch.Tensor, target: torch.Tensor, scale, parts, steps: int,
               m1: torch.Tensor, m2: torch.Tensor, t: torch.Tensor, lr: float = REFINE_LR,
               cosine: bool = True, warmup: int = 0) -> torch.Tensor:
    """`steps` Adam steps (torch.optim.Adam's update, betas 0.9 / 0.999, eps 1e-8) on the parts' refinement losses
    from the codes z, with the moments m1, m2 and the step counts t updated in place; returns the codes reached
    (detached). cosine: the step size decays from lr to 0 over these steps (cold refinement); else constant.
    warmup: each (body, part)'s step size is scaled by min(1, t / warmup) at its t-th step (0: not scaled).

    Shape: z, m1, m2 (B, K', latent) of `parts` ((K',) ids, None: all K); t (B, K', 1) steps taken so far per
    (body, part) (Adam's bias correction); xin / target / scale from `refinement_points` -> (B, K', latent).
    """
    var = z.detach().clone().requires_grad_(True)
    beta1, beta2, eps = 0.9, 0.999, 1e-8
    with torch.enable_grad():
        for i in range(steps):
            pred = decode_targets(net, var, xin, scale, parts)
            (grad,) = torch.autograd.grad(refinement_losses(net.output, pred, target).sum(), var)
            t.add_(1)
            m1.mul_(beta1).add_(grad, alpha=1 - beta1)
            m2.mul_(beta2).addcmul_(grad, grad, value=1 - beta2)
            step_lr = lr * 0.5 * (1 + math.cos(math.pi * i / steps)) if cosine else lr
            denom = (m2 / (1 - beta2 ** t)).sqrt_().add_(eps)
            rise = (t / warmup).clamp(max=1.0) if warmup else 1.0
            with torch.no_grad():
                var.addcdiv_(m1 * rise / (1 - beta1 ** t), denom, value=-step_lr)
    return var.detach()


def refine_codes(net, z: torch.Tensor, xin: torch.Tensor, target: torch.Tensor, scale, parts, steps: int,
                 lr: float = REFINE_LR) -> torch.Tensor:
    """z + delta: the codes after `steps` Adam steps (cosine-decayed step size, warmed up over REFINE_WARMUP steps)
    on the parts' refinement losses (module docstring), from fresh moments, the correction delta a constant for autograd; z itself for steps = 0.

    Shape: z (B, K', latent) codes of `parts` ((K',) ids, None: all K), xin / target / scale from
    `refinement_points` -> (B, K', latent).
    """
    if check_refine_steps(steps) == 0 or z.shape[1] == 0:
        return z
    m1, m2 = torch.zeros_like(z.detach()), torch.zeros_like(z.detach())
    t = z.new_zeros(*z.shape[:2], 1)
    var = adam_steps(net, z, xin, target, scale, parts, steps, m1, m2, t, lr, cosine=True, warmup=REFINE_WARMUP)
    return z + (var - z.detach())
