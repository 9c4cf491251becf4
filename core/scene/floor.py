"""The floor of a scene cloud: which axis or direction is up, and at what level the floor lies.

- `estimate_floor(points)`: across which of the file's axes the floor lies (the axis whose lowest slab holds the
  most points, less half its highest slab's: walls come in pairs, a floor rarely has a ceiling as full) and its
  level; used to check a scan's --up before anything else reads it.
- `floor_up(points)`: the up direction from the surfaces' normals (PCA of each point's neighbours): the direction
  that the most flat surfaces face minus the most face against it, trusted only where the scan shows a room around
  it; also finds a tilted floor.
- `floor_level(heights)`: the floor's height in a Y-up cloud: the densest slab among the lower part of the heights
  (robust to stray points under the floor, which move a low percentile).

The generated rooms (volsmpl.scene, 7.5 x 7.0 m, 2.8 m tall, no ceiling) hold 36% of their points in the floor
slab and at most 15% in a wall's, a score ratio of about 5.

    est = estimate_floor(pts)               # FloorEstimate(axis='y', level=0.0, share=0.36, clear=True, ...)
    print(est.line())                       # 'floor: axis y, level 0.00 m, 36% of points'
    up, asym, walls = floor_up(pts)         # (3,) unit vector or None when no room shows around the floor
    y0 = floor_level(pts[:, 1])             # metres
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

__all__ = ["FLOOR_BAND_M", "CLEAR_RATIO", "FLOOR_MIN", "WALLS_MAX", "FLAT_SIDES", "FloorEstimate", "estimate_floor",
           "point_normals", "floor_up", "floor_level"]

FLOOR_BAND_M = 0.05    # the floor slab: points within 5 cm of an axis's 1st-percentile level
CLEAR_RATIO = 1.5      # the floor axis's score is at least 1.5x every other axis's
#: a normal-based estimate is clear where the up direction's asymmetry is at least FLOOR_MIN, both horizontal
#: directions' at most WALLS_MAX, and each horizontal direction is faced by at least FLAT_SIDES of the flat points
FLOOR_MIN, WALLS_MAX, FLAT_SIDES = 0.15, 0.10, 0.03
AXES = "xyz"


@dataclass
class FloorEstimate:
    """The floor found in a cloud: `axis` ('x', 'y' or 'z': the file's axis across the floor), `level` (metres:
    the axis's 1st-percentile value), `share` (the points within FLOOR_BAND_M of it), `shares` and `scores` per
    axis, `clear` (the best score is CLEAR_RATIO times the next or more)."""

    axis: str
    level: float
    share: float
    clear: bool
    shares: dict = field(default_factory=dict)
    scores: dict = field(default_factory=dict)

    def line(self) -> str:
        """One line for the console: 'floor: axis y, level 0.00 m, 36% of points'."""
        return (f"floor: axis {self.axis}, level {self.level:.2f} m, {100 * self.share:.0f}% of points"
                + ("" if self.clear else " (unclear: " + ", ".join(f"{a} {100 * s:.0f}%" for a, s in
                                                                   self.shares.items()) + ")"))


def estimate_floor(points: np.ndarray, band: float = FLOOR_BAND_M) -> FloorEstimate:
    """Which axis of a cloud (metres, its own axes) is up: the one across the floor. Per axis, the share of the
    points within `band` of its 1st-percentile level (its lowest slab: the floor, or a wall) minus half the share
    within `band` of its 99th-percentile level (the opposite slab: walls come in pairs, a floor rarely has a
    ceiling as full); the best score is the floor's, clear when it is CLEAR_RATIO times the next or more."""
    p = np.asarray(points, dtype=np.float64)
    shares, scores, levels = {}, {}, {}
    for i, a in enumerate(AXES):
        v = p[:, i]
        lo, hi = np.percentile(v, [1.0, 99.0])
        low = float(np.mean(np.abs(v - lo) <= band))
        high = float(np.mean(np.abs(v - hi) <= band))
        shares[a], levels[a], scores[a] = low, float(lo), max(low - 0.5 * high, 0.0)
    order = sorted(AXES, key=lambda a: -scores[a])
    best, second = order[0], order[1]
    clear = len(p) >= 100 and scores[best] > 0 and scores[best] >= CLEAR_RATIO * scores[second]
    return FloorEstimate(best, levels[best], shares[best], bool(clear), shares, scores)


def point_normals(points: np.ndarray, k: int = 16) -> tuple[np.ndarray, np.ndarray]:
    """Unit normals by PCA of each point's k nearest neighbours and their flatness (smallest eigenvalue over the
    sum: 0 on a plane, 1/3 in a ball). Shape: (N, 3) -> (N, 3), (N,)."""
    from scipy.spatial import cKDTree

    _, idx = cKDTree(points).query(points, k=min(k, len(points)))
    nb = points[idx] - points[idx].mean(1, keepdims=True)
    w, v = np.linalg.eigh(np.einsum("nki,nkj->nij", nb, nb))
    return v[:, :, 0], w[:, 0] / np.maximum(w.sum(1), 1e-30)


def floor_up(points: np.ndarray, n: int = 20000, seed: int = 0, cone_deg: float = 15.0, towards=None):
    """The scene's up direction from its floor (module docstring): (up (3,) unit, or None when the scan does not
    show a floor clearly; the up direction's asymmetry; the largest asymmetry across the horizontal directions).

    A direction d's asymmetry: the fraction of the flat points whose normal (turned towards `towards`, a point
    inside the room such as the camera centre; default the centre of the scene's box) lies within `cone_deg` of d
    minus that within `cone_deg` of -d. (The box's centre of a room in a corner of a large open floor lies outside
    the room, so its walls' normals turn the same way and no room shows: give the camera.) The up direction is the one of
    largest asymmetry (the floor and the seats and tops below the middle face up). It is clear only where the scan
    shows a room around it: flat surfaces facing both horizontal directions (FLAT_SIDES of the flat points each,
    walls) that cancel (asymmetry at most WALLS_MAX: walls on opposite sides), while the up direction's asymmetry
    is at least FLOOR_MIN. A view of a single wall, or of a corner, is not clear: a wall cannot be told from a floor.
    Shape: points (N, 3) in the file's frame (a random `n` of them are used)."""
    rng = np.random.default_rng(seed)
    p = points[rng.choice(len(points), n, replace=False)] if len(points) > n else np.asarray(points, np.float64)
    if len(p) < 50:
        return None, 0.0, 0.0
    nrm, flat = point_normals(p)
    keep = flat < 0.02
    if keep.sum() < 50:
        return None, 0.0, 0.0
    nrm, p = nrm[keep], p[keep]
    if towards is None:
        lo, hi = np.percentile(p, [1, 99], axis=0)
        towards = 0.5 * (lo + hi)
    nrm *= np.where(((np.asarray(towards, np.float64) - p) * nrm).sum(1) < 0, -1.0, 1.0)[:, None]
    c = np.cos(np.radians(cone_deg))

    def facing(d):   # (fraction within the cone of d, of -d) for directions d (M, 3)
        dots = d @ nrm.T
        return (dots > c).mean(1), (dots < -c).mean(1)

    cand = np.concatenate([np.eye(3), -np.eye(3), nrm[rng.choice(len(nrm), min(256, len(nrm)), replace=False)]])
    pos, neg = facing(cand)
    asym = pos - neg
    best = int(asym.argmax())
    up, a = cand[best], float(asym[best])
    side = np.abs(cand @ up) < np.sin(np.radians(cone_deg))     # horizontal candidates
    if not side.any():
        return None, a, 0.0
    w1 = cand[side][int((pos + neg)[side].argmax())]
    w1 = w1 - (w1 @ up) * up
    w1 /= np.linalg.norm(w1)
    walls = np.stack([w1, np.cross(up, w1)])
    wpos, wneg = facing(walls)
    other = float(np.abs(wpos - wneg).max())
    if a < FLOOR_MIN or other > WALLS_MAX or (wpos + wneg).min() < FLAT_SIDES:
        return None, a, other
    u = nrm[nrm @ up > c].mean(0)
    return u / np.linalg.norm(u), a, other


def floor_level(heights, band: float = 0.03, low_share: float = 0.4) -> float:
    """The floor's height (metres) from the heights of a Y-up cloud: the centre of the densest `band`-thick slab
    among the heights in the lowest `low_share` of their robust range (0.5th to 99.5th percentile), refined to the
    median height of that slab's points. Stray points below the floor (a scan's noise, a basement's few points) do
    not move it, as they move a low percentile. Shape: (N,) -> float.

    Example:
        >>> h = np.r_[np.zeros(1000), np.full(30, -0.8), np.linspace(0.0, 2.5, 500)]   # 3 % strays 0.8 m below
        >>> round(floor_level(h), 3)
        0.0
    """
    h = np.asarray(heights, dtype=np.float64).reshape(-1)
    h = h[np.isfinite(h)]
    if len(h) == 0:
        raise ValueError("no finite heights to find a floor in")
    lo, hi = np.percentile(h, [0.5, 99.5])
    top = lo + low_share * max(hi - lo, band)
    low = h[(h >= lo - band) & (h <= top)]
    edges = np.arange(lo - band, top + band, band / 4.0)
    if len(edges) < 2:
        return float(np.median(low))
    counts = np.array([np.count_nonzero(np.abs(low - e) <= band / 2) for e in edges])
    centre = float(edges[int(counts.argmax())])
    slab = low[np.abs(low - centre) <= band / 2]
    return float(np.median(slab))
