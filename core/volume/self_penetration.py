"""The self-penetration loss's two model-independent steps (paper eq. 5, supplementary D.4), shared by every
model kind: where to look (samples in overlapping part boxes) and how to turn part values into a loss.

1. `overlap_samples`: intersecting padded part boxes (exact oriented-box test) of part pairs that may collide
   (not kinematically adjacent, not COAP's ignored pairs), n_points uniform samples in each box of a pair,
   kept when inside the other box.
2. The model evaluates its per-part values at those samples (its own business).
3. `reduce_selfpen`: keep the samples inside at least two parts that may collide with each other, and sum a
   per-(sample, part) penalty over the involved parts (the model's `selfpen_penalty`).
"""
from __future__ import annotations

import torch

from volsmpl.geometry.boxes import boxes_overlap, sample_overlaps

__all__ = ["SELFPEN_TAU", "overlap_samples", "reduce_selfpen", "sdf_penalty"]

SELFPEN_TAU = 0.01  # metres: SDF scale of the soft occupancy of signed-distance kinds (sdf_penalty)


def overlap_samples(G: torch.Tensor, box_min: torch.Tensor, box_max: torch.Tensor, mask: torch.Tensor,
                    n_points: int, generator: torch.Generator | None = None):
    """Samples in the overlaps of colliding part boxes of each body.

    Shape: G (B, K, 4, 4), box_min/max (B, K, 3), mask (K, K) bool (pairs that may collide) ->
    overlapping (B, K, K) bool, samples: list of B tensors (M_b, 3) (no gradient), padded (B, M, 3) with
    M = max M_b (rows past M_b hold a point outside every box), or None when no body has a sample.
    """
    if not isinstance(n_points, int) or isinstance(n_points, bool) or n_points < 1:
        raise ValueError(f"n_points must be a positive integer (samples per box of an overlapping pair), got {n_points!r}")
    B = G.shape[0]
    with torch.no_grad():
        overl = boxes_overlap(G, box_min, box_max) & mask
    samples = []
    for b in range(B):
        pairs = torch.triu(overl[b]).nonzero()
        pts, _ = sample_overlaps(G[b].detach(), box_min[b].detach(), box_max[b].detach(), pairs, n_points, generator)
        samples.append(pts)
    M = max([s.shape[0] for s in samples] + [0])
    if M == 0:
        return overl, samples, None
    # a padding point beyond every box (a box corner moved out along its diagonal): costs no network evaluation
    far = G[..., :3, 3].detach().amax(dim=(0, 1)) + (box_max - box_min).detach().norm(dim=-1).amax() + 10.0
    padded = far.expand(B, M, 3).clone()
    for b, s in enumerate(samples):
        padded[b, : s.shape[0]] = s
    return overl, samples, padded


def sdf_penalty(tau: float = SELFPEN_TAU):
    """The penalty of signed-distance kinds: sum over kept samples and involved parts of sigmoid(-d_k(x) / tau)."""
    return lambda part, inv: (torch.sigmoid(-part / tau) * inv).sum()


def reduce_selfpen(part: torch.Tensor, occupied: torch.Tensor, mask: torch.Tensor, samples: list, penalty,
                   return_points: bool = False):
    """The loss per body from per-part values at the padded samples.

    Shape: part (B, K, M) values, occupied (B, K, M) bool (the sample is inside part k), mask (K, K) bool ->
    loss (B,); with return_points also the kept samples, a list of B tensors (M'_b, 3).
    penalty(part_b (K, n), involved_b (K, n) bool) -> scalar: the model's penalty of one body's kept samples.
    A sample is kept when it is inside a part k and inside a part l that may collide with k.
    """
    occ = occupied.to(part.dtype)
    partner = torch.einsum("kl,blm->bkm", mask.to(part.dtype), occ) > 0  # part k has a colliding partner occupied
    involved = occupied & partner
    losses, kept = [], []
    for b, s in enumerate(samples):
        n = s.shape[0]
        inv = involved[b, :, :n]
        losses.append(penalty(part[b, :, :n], inv))
        kept.append(s[inv.any(dim=0)])
    loss = torch.stack(losses)
    return (loss, kept) if return_points else loss
