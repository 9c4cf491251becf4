"""The self-penetration loss of a learned volume (`Volume` inherits it): paper eq. 5 on the part decoders, its
sampling and reduction in volsmpl.volume.self_penetration.

    loss = volume.selfpen_loss(out)                     # (B,)
    loss = volume.selfpen_loss(out, code_grad=False)    # part codes held constant: rigid part motion only
"""
from __future__ import annotations

import torch

from volsmpl.volume.api import check_output
from volsmpl.volume.self_penetration import SELFPEN_TAU, overlap_samples, reduce_selfpen, sdf_penalty

__all__ = ["LearnedSelfPenetration"]


class LearnedSelfPenetration:
    """The loss's methods; needs the volume's `training`, `partition`, `num_parts`, `dense`, `is_sdf`, `level`,
    `occupied`, `_cached`, `_frames`, `_encode` and `_part_values`."""

    def selfpen_loss(self, out, n_points: int = 300, generator: torch.Generator | None = None,
                     return_points: bool = False, tau: float = SELFPEN_TAU, code_grad: bool = True):
        """Self-penetration loss (paper eq. 5, supplementary D.4), per body (steps in volsmpl.volume.self_penetration).

        Samples in overlapping boxes of parts that may collide are kept when inside two such parts (part value
        < 0 for SDF models, > level for occupancy models). SDF models: loss = sum over kept samples and over the
        colliding parts containing them of sigmoid(-d_k(x) / tau): the paper's sigma(f(x)) with f read as
        positive inside (our SDF is negative inside), so that minimising it pushes the parts apart. f in metres
        (tau = 1 m, eq. 5 to the letter) makes the sigmoid nearly flat (slope 0.25 per metre), so the loss reads
        the SDF in units of tau; the default 1 cm gives the soft occupancy the sharpness of an occupancy
        network's surface, and one set of optimiser settings then suits both models. Occupancy models (COAP):
        sum over kept samples of (sum of the colliding parts' occupancies - 0.5), as COAP; tau is not used.
        code_grad=False treats the part codes as constants: the pose gradient then flows through the part
        frames only (rigid part motion), not through the change of each part's shape code, and the backward
        pass skips the encoder (about half of a step's time; its cosine with the full gradient on the
        self-intersection cases: >= 0.97, docs/history/readme.md).
        Only the parts of overlapping box pairs are encoded (unless the output is encoded already): a
        sample lies in two parts' boxes, and a part that forms no overlapping pair with the sample's
        other parts can neither be involved nor be a partner, so the loss and its gradients are those
        of the full encoding at a fraction of the encoder's cost.
        Returns: loss (B,); with return_points also a list of B tensors (M_b, 3) of kept samples.
        """
        if not tau > 0:
            raise ValueError(f"tau must be > 0 (metres: the SDF scale of the soft occupancy), got {tau}")
        check_output(out)
        enc = None if self.training else self._cached(out)
        G, box_min, box_max = self._frames(out) if enc is None else (enc.G, enc.box_min, enc.box_max)
        mask = self.partition.collision_mask
        overl, samples, padded = overlap_samples(G, box_min, box_max, mask, n_points, generator)
        if padded is None:
            zero = out.vertices.sum() * 0  # keeps the graph (and device/dtype)
            loss = zero.expand(G.shape[0]).clone()
            return (loss, samples) if return_points else loss
        need = overl.any(dim=0).any(dim=0)
        if enc is None or (need & ~enc.encoded(self.num_parts)).any():
            # encode only the parts of overlapping pairs: no other part can be involved (docstring)
            parts = None if need.all() else need.nonzero()[:, 0]
            enc = self._encode(out, None, parts=parts, frames=(G, box_min, box_max), code_grad=code_grad)
        elif not code_grad:
            enc = enc.with_constant_code()  # a cached encoding made by a query has its codes' graph
        part, _ = self._part_values(enc, padded, self.dense)  # (B, K, M)
        return reduce_selfpen(part, self.occupied(part), mask, samples, self.selfpen_penalty(tau), return_points)

    def selfpen_penalty(self, tau: float = SELFPEN_TAU):
        """penalty(part (K, n), involved (K, n)) -> scalar of one body's kept samples (selfpen_loss)."""
        if self.is_sdf:
            return sdf_penalty(tau)

        def occupancy_penalty(part, inv):
            keep = inv.any(dim=0)
            return ((part * inv).sum(dim=0) - self.level)[keep].sum()
        return occupancy_penalty
