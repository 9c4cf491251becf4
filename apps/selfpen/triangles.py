"""Exact triangle-triangle self-intersection count of a mesh (the "mesh triangle collisions" metric
of the paper's Table 6, after Pavlakos et al. 2019).

    pairs = intersecting_pairs(vertices, faces)     # (P, 2) face ids, i < j
    n = count_intersections(vertices, faces)        # P
    mask = intersecting_faces(vertices, faces)      # (F,) bool, for highlighting

Pipeline (numpy, vectorised, float64):
1. Broad phase: sort-and-sweep of the triangles' axis-aligned boxes along the mesh's longest axis
   (closed interval overlap), then the other two axes; pairs of faces that share a vertex are
   dropped (neighbours always touch; the metric ignores them).
2. Narrow phase: Moeller's interval test (1997). Each triangle's vertices get signed distances to
   the other triangle's plane (|d| below a scale-relative tolerance counts as 0); a triangle wholly
   on one side of the other's plane cannot intersect it. Otherwise both triangles cross the line
   L = n1 x n2 of the two planes in closed intervals (from edge crossings and on-plane vertices);
   they intersect iff the intervals overlap (touching counts). Coplanar pairs get an exact 2D test
   (edge-edge crossings or a vertex inside the other triangle).

`exact_triangles_intersect` is an independent scalar reference in exact rational arithmetic
(fractions.Fraction of the float inputs) used by the tests as brute force.
Zero-area triangles are never reported as intersecting.
"""
from __future__ import annotations

from fractions import Fraction
from itertools import combinations

import numpy as np

DEFAULT_TOL = 1e-9  # plane-distance tolerance, relative to the pair's longest edge
_EDGES = ((0, 1), (1, 2), (2, 0))


# ---------------------------------------------------------------------------------------- input checks
def _check_mesh(vertices, faces) -> tuple[np.ndarray, np.ndarray]:
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces)
    if v.ndim != 2 or v.shape[1] != 3:
        raise ValueError(f"vertices must be (V, 3), got shape {v.shape}")
    if f.ndim != 2 or f.shape[1] != 3 or not np.issubdtype(f.dtype, np.integer):
        raise ValueError(f"faces must be (F, 3) integer vertex indices, got {f.dtype} {f.shape}")
    if f.size and (f.min() < 0 or f.max() >= len(v)):
        raise ValueError(f"faces index vertices outside 0..{len(v) - 1}")
    if not np.isfinite(v).all():
        raise ValueError("vertices contain NaN or Inf; cannot test intersections of an invalid mesh")
    return v, f.astype(np.int64)


# ---------------------------------------------------------------------------------------- broad phase
def candidate_pairs(tri: np.ndarray, faces: np.ndarray | None = None, chunk: int = 1 << 21) -> np.ndarray:
    """Pairs of triangles whose closed axis-aligned boxes overlap (sort and sweep).

    Args:
        tri: (F, 3, 3) triangle corners.
        faces: (F, 3) vertex ids; when given, pairs sharing a vertex are dropped.
        chunk: at most this many sweep candidates are held at once (memory bound).
    Returns: (P, 2) int64 face ids with i < j, sorted lexicographically.
    """
    F = len(tri)
    if F < 2:
        return np.zeros((0, 2), np.int64)
    lo, hi = tri.min(axis=1), tri.max(axis=1)  # (F, 3)
    axis = int(np.argmax(hi.max(0) - lo.min(0)))
    others = [a for a in range(3) if a != axis]
    order = np.argsort(lo[:, axis], kind="stable")
    lo_s, hi_s = lo[order], hi[order]
    # sorted triangle s overlaps (along `axis`) every t in (s, end[s]): lo[t] <= hi[s] and lo[t] >= lo[s]
    end = np.searchsorted(lo_s[:, axis], hi_s[:, axis], side="right")
    counts = end - np.arange(F) - 1
    out = []
    s0 = 0
    csum = np.cumsum(counts)
    while s0 < F:
        base = csum[s0 - 1] if s0 else 0
        s1 = max(s0 + 1, int(np.searchsorted(csum, base + chunk, side="right")))
        s1 = min(s1, F)
        c = counts[s0:s1]
        tot = int(c.sum())
        if tot:
            i = np.repeat(np.arange(s0, s1), c)
            start = np.repeat(np.cumsum(c) - c, c)
            j = i + 1 + (np.arange(tot) - start)
            ok = np.ones(tot, bool)
            for a in others:
                ok &= (lo_s[j, a] <= hi_s[i, a]) & (lo_s[i, a] <= hi_s[j, a])
            out.append(np.stack([order[i[ok]], order[j[ok]]], axis=1))
        s0 = s1
    pairs = np.concatenate(out) if out else np.zeros((0, 2), np.int64)
    pairs.sort(axis=1)
    if faces is not None and len(pairs):
        f = np.asarray(faces)
        shared = (f[pairs[:, 0], :, None] == f[pairs[:, 1], None, :]).any(axis=(1, 2))
        pairs = pairs[~shared]
    return pairs[np.lexsort((pairs[:, 1], pairs[:, 0]))]


# ---------------------------------------------------------------------------------------- narrow phase
def _orient2d(a, b, c):
    """Twice the signed area of (a, b, c); (..., 2) arrays -> (...)."""
    return (b[..., 0] - a[..., 0]) * (c[..., 1] - a[..., 1]) - (b[..., 1] - a[..., 1]) * (c[..., 0] - a[..., 0])


def _coplanar_intersect(P: np.ndarray, Q: np.ndarray, normal: np.ndarray) -> np.ndarray:
    """Closed 2D intersection test of coplanar triangles. P, Q (n, 3, 3); normal (n, 3) -> (n,) bool."""
    n = len(P)
    drop = np.argmax(np.abs(normal), axis=1)
    keep = np.array([[1, 2], [0, 2], [0, 1]])[drop]  # (n, 2) axes of the projection plane
    idx = np.broadcast_to(keep[:, None, :], (n, 3, 2))
    p, q = np.take_along_axis(P, idx, axis=2), np.take_along_axis(Q, idx, axis=2)  # (n, 3, 2)
    hit = np.zeros(n, bool)
    for a0, a1 in _EDGES:  # proper or touching edge crossings (collinear overlaps are caught below)
        for b0, b1 in _EDGES:
            o1, o2 = _orient2d(p[:, a0], p[:, a1], q[:, b0]), _orient2d(p[:, a0], p[:, a1], q[:, b1])
            o3, o4 = _orient2d(q[:, b0], q[:, b1], p[:, a0]), _orient2d(q[:, b0], q[:, b1], p[:, a1])
            collinear = (o1 == 0) & (o2 == 0)
            hit |= (o1 * o2 <= 0) & (o3 * o4 <= 0) & ~collinear
    for x, y in ((p, q), (q, p)):  # a vertex of x inside (closed) triangle y
        for v in range(3):
            o = np.stack([_orient2d(y[:, a], y[:, b], x[:, v]) for a, b in _EDGES], axis=1)
            hit |= (o >= 0).all(1) | (o <= 0).all(1)
    return hit


def _plane_distances(P: np.ndarray, Q: np.ndarray, tol_abs: np.ndarray):
    """Signed distances of P's corners to Q's plane (snapped to 0 within tol_abs). -> d (n, 3), unit normal (n, 3), area ok (n,)."""
    nq = np.cross(Q[:, 1] - Q[:, 0], Q[:, 2] - Q[:, 0])
    norm = np.linalg.norm(nq, axis=1)
    ok = norm > 0
    nq = nq / np.where(ok, norm, 1.0)[:, None]
    d = np.einsum("nvk,nk->nv", P - Q[:, None, 0], nq)
    d[np.abs(d) < tol_abs[:, None]] = 0.0
    return d, nq, ok


def _line_interval(P: np.ndarray, d: np.ndarray, D: np.ndarray, origin: np.ndarray):
    """Closed interval of triangle P on the line with direction D, from its edge crossings of the
    other plane and its vertices on that plane. P (n, 3, 3), d (n, 3) -> lo, hi (n,)."""
    ts, valid = [], []
    proj = np.einsum("nvk,nk->nv", P - origin[:, None], D)  # (n, 3)
    for a, b in _EDGES:
        da, db = d[:, a], d[:, b]
        cross = da * db < 0
        w = np.where(cross, da / np.where(cross, da - db, 1.0), 0.0)
        ts.append(proj[:, a] + (proj[:, b] - proj[:, a]) * w)
        valid.append(cross)
    for a in range(3):
        ts.append(proj[:, a])
        valid.append(d[:, a] == 0)
    ts, valid = np.stack(ts, 1), np.stack(valid, 1)
    lo = np.where(valid, ts, np.inf).min(1)
    hi = np.where(valid, ts, -np.inf).max(1)
    return lo, hi


def triangles_intersect(P: np.ndarray, Q: np.ndarray, tol: float = DEFAULT_TOL) -> np.ndarray:
    """Closed intersection test of triangle pairs (Moeller's interval test + coplanar 2D test).

    Args:
        P, Q: (n, 3, 3) corners of the first and second triangle of each pair.
        tol: plane distances below tol * (longest edge of the pair) count as zero.
    Returns: (n,) bool, True where the triangles share at least one point.
    """
    P, Q = np.asarray(P, np.float64), np.asarray(Q, np.float64)
    if P.shape != Q.shape or P.ndim != 3 or P.shape[1:] != (3, 3):
        raise ValueError(f"P and Q must both be (n, 3, 3), got {P.shape} and {Q.shape}")
    n = len(P)
    if n == 0:
        return np.zeros(0, bool)
    edge = lambda T: np.linalg.norm(T[:, [1, 2, 0]] - T, axis=2).max(1)  # noqa: E731
    tol_abs = tol * np.maximum(edge(P), edge(Q))
    dp, nq, okq = _plane_distances(P, Q, tol_abs)
    dq, np_, okp = _plane_distances(Q, P, tol_abs)
    one_side = lambda d: (d > 0).all(1) | (d < 0).all(1)  # noqa: E731
    alive = okp & okq & ~one_side(dp) & ~one_side(dq)
    coplanar = alive & ((dp == 0).all(1) | (dq == 0).all(1))
    general = alive & ~coplanar
    hit = np.zeros(n, bool)
    if general.any():
        g = np.nonzero(general)[0]
        D = np.cross(np_[g], nq[g])
        origin = Q[g, 0]
        lo1, hi1 = _line_interval(P[g], dp[g], D, origin)
        lo2, hi2 = _line_interval(Q[g], dq[g], D, origin)
        hit[g] = np.maximum(lo1, lo2) <= np.minimum(hi1, hi2)
    if coplanar.any():
        c = np.nonzero(coplanar)[0]
        hit[c] = _coplanar_intersect(P[c], Q[c], nq[c])
    return hit


# ---------------------------------------------------------------------------------------- mesh API
def intersecting_pairs(vertices, faces, tol: float = DEFAULT_TOL, exclude: np.ndarray | None = None,
                       chunk: int = 1 << 20) -> np.ndarray:
    """All pairs of faces of a mesh that intersect and share no vertex.

    Args: vertices (V, 3); faces (F, 3) integer; tol: see triangles_intersect;
        exclude: (E, 2) face pairs (either order) left out of the result, e.g. a shape's rest-pose
        defects (see volsmpl.apps.selfpen.optimize.CollisionCounter); chunk: pairs per narrow-phase batch.
    Returns: (P, 2) int64 face ids, i < j, sorted.
    """
    v, f = _check_mesh(vertices, faces)
    tri = v[f]
    cand = candidate_pairs(tri, f)
    hits = [cand[s:s + chunk][triangles_intersect(tri[cand[s:s + chunk, 0]], tri[cand[s:s + chunk, 1]], tol)]
            for s in range(0, len(cand), chunk)]
    pairs = np.concatenate(hits) if hits else np.zeros((0, 2), np.int64)
    if exclude is not None and len(exclude) and len(pairs):
        pairs = pairs[~np.isin(_pair_keys(pairs, len(f)), _pair_keys(np.sort(np.asarray(exclude, np.int64), axis=1), len(f)))]
    return pairs


def _pair_keys(pairs: np.ndarray, F: int) -> np.ndarray:
    return pairs[:, 0] * F + pairs[:, 1]


def count_intersections(vertices, faces, tol: float = DEFAULT_TOL, exclude: np.ndarray | None = None) -> int:
    """Number of intersecting face pairs that share no vertex (the paper's triangle collisions)."""
    return int(len(intersecting_pairs(vertices, faces, tol, exclude)))


def intersecting_faces(vertices, faces, pairs: np.ndarray | None = None) -> np.ndarray:
    """(F,) bool: faces taking part in at least one intersecting pair (pairs computed when not given)."""
    f = np.asarray(faces)
    if pairs is None:
        pairs = intersecting_pairs(vertices, f)
    mask = np.zeros(len(f), bool)
    mask[np.asarray(pairs, np.int64).ravel()] = True
    return mask


# ---------------------------------------------------------------------------------------- exact reference
def _fr(p) -> tuple:
    return tuple(Fraction(float(x)) for x in p)


def _sub(a, b):
    return tuple(x - y for x, y in zip(a, b))


def _dot(a, b):
    return sum(x * y for x, y in zip(a, b))


def _crs(a, b):
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


def _sgn(x) -> int:
    return (x > 0) - (x < 0)


def _o2(a, b, c):
    return (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])


def _seg_seg_2d(a, b, c, d) -> bool:
    o1, o2, o3, o4 = _sgn(_o2(a, b, c)), _sgn(_o2(a, b, d)), _sgn(_o2(c, d, a)), _sgn(_o2(c, d, b))
    if o1 == o2 == o3 == o4 == 0:  # collinear: 1D overlap along the longer coordinate
        k = 0 if max(a[0], b[0], c[0], d[0]) - min(a[0], b[0], c[0], d[0]) >= max(a[1], b[1], c[1], d[1]) - min(a[1], b[1], c[1], d[1]) else 1
        return max(min(a[k], b[k]), min(c[k], d[k])) <= min(max(a[k], b[k]), max(c[k], d[k]))
    return o1 * o2 <= 0 and o3 * o4 <= 0


def _point_in_tri_2d(p, t) -> bool:
    s = [_sgn(_o2(t[a], t[b], p)) for a, b in _EDGES]
    return all(x >= 0 for x in s) or all(x <= 0 for x in s)


def _tri_tri_2d(t1, t2) -> bool:
    if any(_seg_seg_2d(t1[a], t1[b], t2[c], t2[d]) for a, b in _EDGES for c, d in _EDGES):
        return True
    return any(_point_in_tri_2d(p, t2) for p in t1) or any(_point_in_tri_2d(p, t1) for p in t2)


def _project(points, normal):
    k = max(range(3), key=lambda i: abs(normal[i]))
    keep = [i for i in range(3) if i != k]
    return [(p[keep[0]], p[keep[1]]) for p in points]


def _seg_tri(a, b, t, normal) -> bool:
    """Closed segment ab vs triangle t (exact), normal = t's (nonzero) normal."""
    sa, sb = _dot(_sub(a, t[0]), normal), _dot(_sub(b, t[0]), normal)
    if (sa > 0 and sb > 0) or (sa < 0 and sb < 0):
        return False
    if sa == 0 and sb == 0:  # segment in the plane: 2D segment vs triangle
        a2, b2 = _project([a, b], normal)
        t2 = _project(t, normal)
        return any(_seg_seg_2d(a2, b2, t2[i], t2[j]) for i, j in _EDGES) or _point_in_tri_2d(a2, t2)
    w = sa / (sa - sb)
    x = tuple(ai + (bi - ai) * w for ai, bi in zip(a, b))
    return _point_in_tri_2d(_project([x], normal)[0], _project(t, normal))


def exact_triangles_intersect(t1, t2) -> bool:
    """Exact (rational arithmetic) closed test of two triangles, (3, 3) each; slow, for reference.

    Non-coplanar triangles meet iff an edge of one meets the other (the ends of their common
    segment lie on edges); coplanar ones by a 2D test. Zero-area triangles never intersect.
    """
    t1, t2 = [_fr(p) for p in t1], [_fr(p) for p in t2]
    n1 = _crs(_sub(t1[1], t1[0]), _sub(t1[2], t1[0]))
    n2 = _crs(_sub(t2[1], t2[0]), _sub(t2[2], t2[0]))
    if n1 == (0, 0, 0) or n2 == (0, 0, 0):
        return False
    if all(_dot(_sub(p, t2[0]), n2) == 0 for p in t1):
        return _tri_tri_2d(_project(t1, n2), _project(t2, n2))
    return (any(_seg_tri(t1[a], t1[b], t2, n2) for a, b in _EDGES)
            or any(_seg_tri(t2[a], t2[b], t1, n1) for a, b in _EDGES))


def brute_force_pairs(vertices, faces) -> np.ndarray:
    """Reference for intersecting_pairs: every face pair sharing no vertex, exact test. (P, 2), O(F^2)."""
    v, f = _check_mesh(vertices, faces)
    out = [(i, j) for i, j in combinations(range(len(f)), 2)
           if not set(f[i]) & set(f[j]) and exact_triangles_intersect(v[f[i]], v[f[j]])]
    return np.array(out, np.int64).reshape(-1, 2)


# ---------------------------------------------------------------------------------------- body-level metric
def body_collisions(body, betas, global_orient, body_pose, tol: float = DEFAULT_TOL) -> dict:
    """Pose-induced triangle collisions of one body (the metric of the self-intersection app).

    The default body's toes touch in the rest pose for many shapes (up to ~55 intersecting pairs,
    a template defect no pose can remove), so the metric leaves out the pairs that already intersect
    in the T-pose of the same shape.

    Args: body: volsmpl.Body (or smplx SMPL); betas (10,) or (1, 10); global_orient (3,); body_pose (69,).
    Returns: dict with 'pairs' (P, 2) pose-induced pairs, 'raw' (R, 2) all intersecting pairs of
        the posed mesh, 'rest' (S, 2) pairs of the rest-pose mesh of this shape, 'vertices' (V, 3).
    """
    import torch

    faces = np.asarray(torch.as_tensor(body.faces).cpu())
    dev = body.v_template.device
    with torch.no_grad():
        b = torch.as_tensor(betas, dtype=torch.float32).reshape(1, -1).to(dev)
        posed = body(betas=b, global_orient=torch.as_tensor(global_orient, dtype=torch.float32).reshape(1, 3).to(dev),
                     body_pose=torch.as_tensor(body_pose, dtype=torch.float32).reshape(1, -1).to(dev))
        rest = body(betas=b)
    v = posed.vertices[0].double().cpu().numpy()
    rest_pairs = intersecting_pairs(rest.vertices[0].double().cpu().numpy(), faces, tol)
    raw = intersecting_pairs(v, faces, tol)
    pairs = raw[~np.isin(_pair_keys(raw, len(faces)), _pair_keys(rest_pairs, len(faces)))] if len(rest_pairs) else raw
    return {"pairs": pairs, "raw": raw, "rest": rest_pairs, "vertices": v}


def part_pairs(pairs: np.ndarray, face_labels, collision_mask) -> list:
    """The distinct (part a, part b) pairs, a < b, of the triangle pairs (P, 2) whose faces lie on two different
    parts allowed to collide."""
    if len(pairs) == 0:
        return []
    lab = np.sort(np.asarray(face_labels)[np.asarray(pairs)], axis=1)
    mask = np.asarray(collision_mask, dtype=bool)
    keep = mask[lab[:, 0], lab[:, 1]] & (lab[:, 0] != lab[:, 1])
    return [tuple(int(x) for x in p) for p in np.unique(lab[keep], axis=0)]


def count_collidable(pairs: np.ndarray, face_labels, collision_mask) -> int:
    """Number of triangle pairs (P, 2) whose faces lie on two different parts allowed to collide."""
    if len(pairs) == 0:
        return 0
    lab = np.asarray(face_labels)[np.asarray(pairs)]  # (P, 2) part of each triangle
    mask = np.asarray(collision_mask, dtype=bool)
    return int((mask[lab[:, 0], lab[:, 1]] & (lab[:, 0] != lab[:, 1])).sum())
