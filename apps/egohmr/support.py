"""The support term of EgoHMR's guided sampling: how far the body's lowest points float above, or have sunk into,
the scene's support below them, and the translation that closes the gap.

    mask = support_mask(points, up)               # (N,) the scene points on near-horizontal surfaces
    sup = SupportGap(points, masks, up, faces)    # points (B, N, 3), masks (B, N), up (B, 3): the world's up
    g = sup.gap(vertices)                         # (B,) metres: > 0 floating, < 0 sunk, NaN: no support in reach
    S, dS = sup.score(vertices)                   # S = g^2 / 2 per frame; dS/d(translation) = g * up

A person rests on what lies below them (the floor, a bed). The support points are the scene points on
near-horizontal surfaces (`support_mask`: the normal of a plane fitted to each point's NEIGHBOURS nearest points
within HORIZONTAL_DEG of up). The body's lowest points are its vertices within BAND of its lowest one along up
(BAND None: every vertex). For such a vertex v at height h_v, the support points within RADIUS of the vertical line
through v count when they lie below v by at most BELOW, or above v by at most ABOVE and inside the body (a surface
it has sunk into; one over the body, e.g. a plate above a foot, does not count); v's support height s_v is the
highest of them. The gap is g = min over those vertices with one of h_v - s_v. Moving the body by -g * up puts it on
its support: a body floating 5 cm above a floor has g = +0.05 (pulled down), one sunk 5 cm into it g = -0.05
(pushed up).

Why: the unguided samples touch the scene (a vertex within 2 cm) in 70 % of the frames, every ground-truth body
touches its support; the regressed pelvis is off by 12 cm on average, 5 cm of it along up (val split, 200 frames,
the shipped network). Pose-only guidance cannot close a gap of the whole body. Measured with the 'mesh' guide, the
pose unguided and free pelvis steps of 1 cm (guidance.py; `volsmpl egohmr tune --split val --model mesh --factors 0
--pelvis-step 0.01 --pelvis-along free`, BAND and ABOVE set here), 200 val frames, ABOVE 0.05: the lowest 3 cm (BAND
0.03) take the collision ratio from 0.00579 to 0.00182 and contact from 70 to 96 % with the pelvis error from 122 to
127 mm; every vertex (BAND None) takes the collision ratio to 0.00018 (seated bodies rest on their seats) but the
pelvis error to 137 mm (a sampled pose whose thighs or hands overlap furniture is lifted by it), so BAND is 0.03.
ABOVE 0.05 / 0.10 / 0.15 differ by less than the frames' spread (first 64 val frames: collision 0.00121 / 0.00104 /
0.00102 against 0.00424 unguided, pelvis error 103-104 mm against 107). On the val split's 200 ground-truth bodies g
lies within 2 cm for every body with BAND None; with BAND 0.03 the 30 seated ones, whose feet hang 2.6-12 cm above
the floor, get g > 2 cm: the guidance therefore pulls a body down only where it penetrates nothing (guidance.py), so
it does not sink a seated body into its seat.
"""
from __future__ import annotations

import numpy as np
import torch

#: horizontal radius (m) of a vertex's column in which support points are sought
RADIUS = 0.04
#: a support point may lie up to BELOW metres under a vertex (a larger gap is not closed)...
BELOW = 0.30
#: ... or up to ABOVE metres over it, inside the body (a deeper sinking is not seen)
ABOVE = 0.10
#: only the vertices within BAND metres (along up) of the body's lowest vertex rest on a support (None: all)
BAND = 0.03
#: scene points whose local plane's normal lies within HORIZONTAL_DEG of up are support points
HORIZONTAL_DEG = 25.0
#: nearest scene points of each point's local plane
NEIGHBOURS = 12


def support_mask(points, up, k: int = NEIGHBOURS, deg: float = HORIZONTAL_DEG) -> np.ndarray:
    """Which points lie on a near-horizontal surface: the smallest principal axis of each point's k nearest points
    (itself included) within `deg` degrees of `up`. Shape: points (N, 3), up (3,) -> (N,) bool."""
    from scipy.spatial import cKDTree

    p = np.asarray(torch.as_tensor(points).detach().cpu(), np.float64)
    u = np.asarray(torch.as_tensor(up).detach().cpu(), np.float64)
    k = min(k, len(p))
    if k < 3:
        return np.zeros(len(p), dtype=bool)
    _, idx = cKDTree(p).query(p, k=k)
    c = p[idx] - p[idx].mean(1, keepdims=True)                    # (N, k, 3)
    _, vecs = np.linalg.eigh(np.einsum("nki,nkj->nij", c, c))     # ascending: column 0 is the normal
    return np.abs(vecs[:, :, 0] @ (u / np.linalg.norm(u))) >= np.cos(np.radians(deg))


def _basis(u: np.ndarray) -> np.ndarray:
    """Two orthonormal vectors orthogonal to the unit vector u. Shape: (3,) -> (3, 2)."""
    a = np.array([1.0, 0.0, 0.0]) if abs(u[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    e1 = np.cross(u, a)
    e1 /= np.linalg.norm(e1)
    return np.stack([e1, np.cross(u, e1)], 1)


class SupportGap:
    """The support gap of each frame's body (module docstring). points (B, N, 3), masks (B, N) bool (support_mask),
    up (B, 3) any length > 0, faces (F, 3) of the body mesh (for the inside test)."""

    def __init__(self, points: torch.Tensor, masks: torch.Tensor, up: torch.Tensor, faces,
                 radius: float = RADIUS, below: float = BELOW, above: float = ABOVE, band: float | None = BAND):
        from scipy.spatial import cKDTree

        B = points.shape[0]
        if points.ndim != 3 or points.shape[-1] != 3 or masks.shape != points.shape[:2] or up.shape != (B, 3):
            raise ValueError(f"support: points must be (B, N, 3), masks (B, N) and up (B, 3), got "
                             f"{tuple(points.shape)}, {tuple(masks.shape)} and {tuple(up.shape)}")
        u = up.detach().double().cpu().numpy()
        norm = np.linalg.norm(u, axis=1, keepdims=True)
        if not (np.isfinite(u).all() and (norm > 0).all()):
            raise ValueError("support: the up direction of every frame must be a finite non-zero vector")
        u = u / norm
        self.up = torch.as_tensor(u, dtype=points.dtype, device=points.device)   # (B, 3) unit
        self.faces = torch.as_tensor(np.asarray(torch.as_tensor(faces).cpu(), np.int64))
        self.radius, self.below, self.above, self.band = radius, below, above, band
        self.frames = []
        for p, m, ub in zip(points.detach().double().cpu().numpy(), masks.detach().cpu().numpy().astype(bool), u):
            s, E = p[m], _basis(ub)
            self.frames.append((cKDTree(s @ E) if len(s) else None, s, s @ ub, E, ub))

    def _heights(self, b: int, body: np.ndarray, low: np.ndarray) -> np.ndarray:
        """Support height s_v of the vertices `low` (M,) of frame b's body (V, 3) float64, NaN where one has none.
        Shape: -> (M,)."""
        from scipy.spatial import cKDTree

        from volsmpl.geometry.point_mesh_distance import winding_numbers

        tree, s, hs, E, ub = self.frames[b]
        v = body[low]
        out = np.full(len(v), np.nan)
        if tree is None:
            return out
        h = v @ ub
        pairs = tree.sparse_distance_matrix(cKDTree(v @ E), self.radius, output_type="ndarray")
        if not len(pairs):
            return out
        pi, vi = pairs["i"].astype(np.int64), pairs["j"].astype(np.int64)
        dh = hs[pi] - h[vi]                                           # support point's height over the vertex
        keep = (dh >= -self.below) & (dh <= self.above)
        vi, pi, dh = vi[keep], pi[keep], dh[keep]
        over = dh > 0
        if over.any():                                                # above v: a support only inside the body
            cand = np.unique(pi[over])
            w = winding_numbers(torch.as_tensor(body), self.faces, torch.as_tensor(s[cand])).numpy()
            inside = np.zeros(len(s), dtype=bool)
            inside[cand] = w > 0.5
            ok = ~over | inside[pi]
            vi, pi = vi[ok], pi[ok]
        best = np.full(len(v), -np.inf)
        np.maximum.at(best, vi, hs[pi])
        return np.where(np.isfinite(best), best, np.nan)

    def gap(self, vertices: torch.Tensor) -> torch.Tensor:
        """g per frame (metres, module docstring), differentiable in the vertices (through the vertex that attains
        the minimum); NaN where no vertex has a support point in reach or the body is not finite.
        Shape: (B, V, 3) -> (B,)."""
        h = (vertices * self.up[:, None].to(vertices.dtype)).sum(-1)          # (B, V)
        out = []
        for b in range(len(vertices)):
            s = np.full(h.shape[1], np.nan)
            if torch.isfinite(h[b]).all():
                low = np.arange(h.shape[1]) if self.band is None else \
                    (h[b] <= h[b].min() + self.band).nonzero().flatten().cpu().numpy()
                s[low] = self._heights(b, vertices[b].detach().double().cpu().numpy(), low)
            has = np.flatnonzero(np.isfinite(s))
            if not len(has):
                out.append(h.new_tensor(float("nan")))
                continue
            sel = torch.as_tensor(has, device=h.device)
            out.append((h[b, sel] - torch.as_tensor(s[has], dtype=h.dtype, device=h.device)).min())
        return torch.stack(out)

    def score(self, vertices: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """S = g^2 / 2 per frame and its gradient with respect to the body's translation, g * up (a translation moves
        every vertex alike); both 0 where g is NaN. Shape: (B, V, 3) -> (B,), (B, 3)."""
        g = self.gap(vertices.detach())
        g = torch.where(torch.isfinite(g), g, 0.0)
        return 0.5 * g ** 2, g[:, None] * self.up.to(g.dtype)


__all__ = ["SupportGap", "support_mask", "RADIUS", "BELOW", "ABOVE", "HORIZONTAL_DEG", "NEIGHBOURS"]
