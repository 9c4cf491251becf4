"""Ground truth (volsmpl.geometry.groundtruth) against closed-form and brute-force references."""
from __future__ import annotations

import numpy as np
import pytest
import torch
import trimesh

from volsmpl.geometry import groundtruth as gt
from volsmpl.train import queries as tq
try:
    import open3d  # noqa: F401
    HAS_O3D, O3D_ERR = True, ""
except ImportError as e:  # e.g. missing libusb-1.0-0 on slim images
    HAS_O3D, O3D_ERR = False, str(e)
needs_o3d = pytest.mark.skipif(not HAS_O3D, reason=f"open3d unavailable: {O3D_ERR}")


# ------------------------------------------------------------------ independent references
def box_sdf(p, half):
    """Exact SDF of an axis-aligned box centred at 0 with half extents `half`."""
    q = np.abs(p) - half
    return np.linalg.norm(np.maximum(q, 0), axis=-1) + np.minimum(q.max(axis=-1), 0)


def closest_point_on_triangles(p, a, b, c):
    """Closest points (N, F, 3) of points p (N, 3) to triangles (a, b, c) each (F, 3), by Voronoi regions."""
    p = p[:, None]
    ab, ac, ap = b - a, c - a, p - a
    d1, d2 = (ab * ap).sum(-1), (ac * ap).sum(-1)
    bp = p - b
    d3, d4 = (ab * bp).sum(-1), (ac * bp).sum(-1)
    cp = p - c
    d5, d6 = (ab * cp).sum(-1), (ac * cp).sum(-1)
    va, vb, vc = d3 * d6 - d5 * d4, d5 * d2 - d1 * d6, d1 * d4 - d3 * d2
    with np.errstate(divide="ignore", invalid="ignore"):
        denom = va + vb + vc
        v_in, w_in = vb / denom, vc / denom
        out = a + ab * v_in[..., None] + ac * w_in[..., None]  # interior
        t_ab = d1 / (d1 - d3)
        t_ac = d2 / (d2 - d6)
        t_bc = (d4 - d3) / ((d4 - d3) + (d5 - d6))
    bc = c - b
    region = [  # Ericson's order: the first region that applies wins
        ((d1 <= 0) & (d2 <= 0), lambda: np.broadcast_to(a, out.shape)),
        ((d3 >= 0) & (d4 <= d3), lambda: np.broadcast_to(b, out.shape)),
        ((vc <= 0) & (d1 >= 0) & (d3 <= 0), lambda: a + ab * t_ab[..., None]),
        ((d6 >= 0) & (d5 <= d6), lambda: np.broadcast_to(c, out.shape)),
        ((vb <= 0) & (d2 >= 0) & (d6 <= 0), lambda: a + ac * t_ac[..., None]),
        ((va <= 0) & ((d4 - d3) >= 0) & ((d5 - d6) >= 0), lambda: b + bc * t_bc[..., None]),
    ]
    for mask, value in reversed(region):  # applied last = highest priority
        with np.errstate(divide="ignore", invalid="ignore"):
            out = np.where(mask[..., None], value(), out)
    return out


def brute_distance(p, vertices, faces):
    tri = vertices[faces]
    cp = closest_point_on_triangles(p, tri[:, 0], tri[:, 1], tri[:, 2])
    return np.linalg.norm(cp - p[:, None], axis=-1).min(axis=1)


def voxel_mesh(cells):
    """Closed, outward-oriented surface of a union of unit cubes at integer `cells` (shared grid vertices)."""
    occ = {tuple(c) for c in cells}
    verts, faces = {}, []
    vid = lambda x: verts.setdefault(tuple(x), len(verts))
    for c in occ:
        for axis in range(3):
            for s in (-1, 1):
                nb = list(c)
                nb[axis] += s
                if tuple(nb) in occ:
                    continue
                u, w = [(axis + 1) % 3, (axis + 2) % 3]
                base = np.array(c, float)
                base[axis] += (s + 1) / 2
                corners = []
                for du, dw in ((0, 0), (1, 0), (1, 1), (0, 1)):
                    x = base.copy()
                    x[u] += du
                    x[w] += dw
                    corners.append(vid(x))
                q = corners if s > 0 else corners[::-1]
                faces += [[q[0], q[1], q[2]], [q[0], q[2], q[3]]]
    v = np.zeros((len(verts), 3))
    for x, i in verts.items():
        v[i] = x
    return v, np.array(faces)


L_CELLS = [(0, 0, 0), (1, 0, 0), (2, 0, 0), (0, 1, 0), (0, 2, 0), (0, 2, 1)]  # non-convex, L with a raised arm


def inside_cells(p, cells):
    return np.isin(np.floor(p).astype(int).view([("", int)] * 3).ravel(),
                   np.array(cells).view([("", int)] * 3).ravel())


def off_surface(p, vertices, faces, eps=1e-3):
    return brute_distance(p, vertices, faces) > eps


@pytest.fixture(scope="module")
def rng():
    return np.random.default_rng(0)


@pytest.fixture(scope="module")
def cube():
    m = trimesh.creation.box(extents=(1.0, 1.0, 1.0))
    return np.asarray(m.vertices), np.asarray(m.faces)


@pytest.fixture(scope="module")
def sphere():
    m = trimesh.creation.icosphere(subdivisions=2, radius=0.5)
    return np.asarray(m.vertices), np.asarray(m.faces)


# ------------------------------------------------------------------ the reference itself
def test_brute_reference_on_cube(cube, rng):
    p = rng.uniform(-1, 1, (400, 3))
    np.testing.assert_allclose(brute_distance(p, *cube), np.abs(box_sdf(p, 0.5)), atol=1e-12)


# ------------------------------------------------------------------ winding numbers
WINDING = {"igl": gt.winding_number, "igl_fast": lambda v, f, p: gt.winding_number(v, f, p, fast=True),
           "reference": gt.winding_number_reference}


@pytest.mark.parametrize("impl", sorted(WINDING))
@pytest.mark.parametrize("shape", ["cube", "sphere", "L"])
def test_winding_number_is_indicator(shape, impl, cube, sphere, rng):
    if shape == "L":
        v, f = voxel_mesh(L_CELLS)
        p = rng.uniform(-0.5, 3.5, (1500, 3))
        inside = inside_cells(p, L_CELLS)
    else:
        v, f = cube if shape == "cube" else sphere
        p = rng.uniform(-0.65, 0.65, (1500, 3))
        inside = box_sdf(p, 0.5) < 0 if shape == "cube" else None
    keep = off_surface(p, v, f)
    p = p[keep]
    w = WINDING[impl](v, f, p)
    if inside is None:  # convex icosphere: inside iff behind every face plane
        tri = v[f]
        n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        inside = (np.einsum("nfi,fi->nf", p[:, None] - tri[None, :, 0], n) < 0).all(axis=1)
    else:
        inside = inside[keep]
    assert 0.05 < inside.mean() < 0.8
    if impl == "igl_fast":  # approximation: right side of 1/2 everywhere, close to the indicator
        np.testing.assert_array_equal(w > 0.5, inside)
        np.testing.assert_allclose(w, inside.astype(float), atol=0.02)
    else:
        np.testing.assert_allclose(w, inside.astype(float), atol=1e-9)


def test_winding_implementations_match_direct(sphere, rng):
    v, f = sphere
    p = rng.normal(0, 0.5, (300, 3))
    direct = gt._winding_direct(torch.as_tensor(v[f]), torch.as_tensor(p)).numpy()  # textbook per-pair sum
    np.testing.assert_allclose(gt.winding_number_reference(v, f, p, chunk=5000), direct, atol=1e-10)  # several blocks
    np.testing.assert_allclose(gt.winding_number(v, f, p), direct, atol=1e-10)
    np.testing.assert_allclose(gt.winding_number(v, f, p, fast=True), direct, atol=0.02)


@pytest.mark.parametrize("impl", ["igl", "reference"])
def test_winding_open_mesh_is_fractional(cube, impl):
    v, f = cube
    w = WINDING[impl](v, f[2:], np.zeros((1, 3)))  # one square side removed: the centre sees 5/6 of the sphere
    np.testing.assert_allclose(w, [5 / 6], atol=1e-12)


def test_winding_torch_in_torch_out(cube):
    v, f = cube
    p = torch.zeros(2, 5, 3, dtype=torch.float32)
    w = gt.winding_number(torch.as_tensor(v), torch.as_tensor(f), p)
    assert torch.is_tensor(w) and w.shape == (2, 5) and w.dtype == torch.float32
    assert torch.allclose(w, torch.ones(2, 5))


# ------------------------------------------------------------------ signed distance
@needs_o3d
@pytest.mark.parametrize("sign", ["raycast", "winding", "fast_winding", "ray_winding"])
def test_cube_sdf_exact(cube, sign, rng):
    p = np.concatenate([rng.uniform(-1.0, 1.0, (1500, 3)), rng.uniform(-0.52, 0.52, (500, 3))])
    d = gt.mesh_sdf(*cube, p, sign=sign)
    ref = box_sdf(p, 0.5)
    sure = np.abs(ref) > 1e-5
    np.testing.assert_allclose(d[sure], ref[sure], atol=2e-6)
    np.testing.assert_allclose(np.abs(d), np.abs(ref), atol=2e-6)


@needs_o3d
def test_sphere_sdf_matches_brute_force(sphere, rng):
    v, f = sphere
    p = rng.uniform(-0.8, 0.8, (800, 3))
    d = gt.mesh_sdf(v, f, p)
    ref = brute_distance(p, v, f)
    np.testing.assert_allclose(np.abs(d), ref, atol=2e-6)
    w = gt.winding_number(v, f, p)
    sure = ref > 1e-5
    np.testing.assert_array_equal(d[sure] < 0, w[sure] > 0.5)


@needs_o3d
@pytest.mark.parametrize("nsamples", [1, 5])
def test_raycast_sign_agrees_with_winding(nsamples, rng):
    v, f = voxel_mesh(L_CELLS)  # grid points make ray hits on edges/vertices likely: worst case for parity
    p = np.concatenate([rng.uniform(-0.5, 3.5, (2000, 3)), np.round(rng.uniform(-0.5, 3.5, (500, 3)) * 4) / 4 + 0.125])
    p = p[off_surface(p, v, f, 1e-4)]
    d = gt.mesh_sdf(v, f, p, sign="raycast", nsamples=nsamples)
    w = gt.winding_number(v, f, p)
    agree = (d < 0) == (w > 0.5)
    assert agree.mean() >= (0.995 if nsamples == 1 else 1.0)
    assert (np.round(w) == inside_cells(p, L_CELLS)).all()


@needs_o3d
@pytest.mark.parametrize("nsamples", [1, 3])
def test_ray_winding_is_the_exact_integer_winding_number(nsamples, rng):
    v, f = voxel_mesh(L_CELLS)  # grid points: rays through edges and vertices are likely, axis-aligned faces
    p = np.concatenate([rng.uniform(-0.5, 3.5, (2000, 3)), np.round(rng.uniform(-0.5, 3.5, (500, 3)) * 4) / 4 + 0.125,
                        np.round(rng.uniform(-0.5, 3.5, (500, 3)) * 2) / 2])  # also on the cells' corners and edges' lines
    p = p[off_surface(p, v, f, 1e-4)]
    w = gt.ray_winding_number(v, f, p, nsamples=nsamples)
    assert w.dtype == np.int64
    np.testing.assert_array_equal(w, inside_cells(p, L_CELLS).astype(np.int64))
    np.testing.assert_array_equal(w, np.round(gt.winding_number(v, f, p)))


@needs_o3d
def test_ray_winding_hollow_shell_and_inverted_pocket(cube, rng):
    # a hollow cube (outer cube + inward-facing inner cube): shell w = 1, cavity w = 0; a lone inverted cube: w = -1
    v, f = cube
    shell_v, shell_f = np.concatenate([v, 0.5 * v]), np.concatenate([f, f[:, ::-1] + len(v)])
    cavity = rng.uniform(-0.2, 0.2, (200, 3))
    shell = rng.uniform(-0.45, 0.45, (2000, 3))
    shell = shell[np.abs(shell).max(1) > 0.3]
    for pts, expect in ((cavity, 0), (shell, 1)):
        np.testing.assert_array_equal(gt.ray_winding_number(shell_v, shell_f, pts), expect)
        np.testing.assert_allclose(gt.winding_number(shell_v, shell_f, pts), expect, atol=1e-9)
        assert ((gt.mesh_sdf(shell_v, shell_f, pts, sign="ray_winding") < 0) == bool(expect)).all()
    np.testing.assert_array_equal(gt.ray_winding_number(v, f[:, ::-1], cavity), -1)
    d = gt.mesh_sdf(v, f[:, ::-1], cavity, sign="ray_winding", check_closed=False)
    np.testing.assert_allclose(d, np.abs(box_sdf(cavity, 0.5)), atol=2e-6)  # w = -1 is outside: positive distance


@needs_o3d
def test_ray_winding_torch_shapes_and_errors(cube):
    v, f = cube
    w = gt.ray_winding_number(torch.as_tensor(v), torch.as_tensor(f), torch.zeros(2, 5, 3))
    assert torch.is_tensor(w) and w.shape == (2, 5) and w.dtype == torch.int64 and (w == 1).all()
    assert gt.ray_winding_number(v, f, np.zeros((0, 3))).shape == (0,)
    with pytest.raises(ValueError, match="odd"):
        gt.ray_winding_number(v, f, np.zeros((1, 3)), nsamples=2)
    with pytest.raises(ValueError, match="non-finite"):
        gt.ray_winding_number(v, f, np.array([[0.0, np.inf, 0.0]]))


@needs_o3d
def test_torch_dtype_device_and_shapes(cube):
    v, f = (torch.as_tensor(x) for x in cube)
    p = torch.zeros(3, 4, 3, dtype=torch.float64)
    d = gt.mesh_sdf(v, f, p)
    assert torch.is_tensor(d) and d.shape == (3, 4) and d.dtype == torch.float64
    assert torch.allclose(d, torch.full((3, 4), -0.5, dtype=torch.float64), atol=1e-6)
    e = gt.mesh_sdf(v, f, torch.zeros(0, 3))
    assert torch.is_tensor(e) and e.shape == (0,)
    assert gt.mesh_sdf(*cube, np.zeros((0, 3))).shape == (0,)
    assert gt.batch_mesh_sdf(v[None], f, torch.zeros(1, 0, 3)).shape == (1, 0)


@needs_o3d
def test_batch_matches_single(cube, sphere, rng):
    v, f = sphere
    verts = np.stack([v, v * 1.5 + 0.1, v[:, [1, 2, 0]]])
    p = rng.uniform(-0.9, 0.9, (3, 600, 3))
    d = gt.batch_mesh_sdf(torch.as_tensor(verts), torch.as_tensor(f), torch.as_tensor(p, dtype=torch.float32))
    assert d.shape == (3, 600) and d.dtype == torch.float32
    for i in range(3):
        np.testing.assert_allclose(d[i].numpy(), gt.mesh_sdf(verts[i], f, p[i]), atol=1e-6)
    dw = gt.batch_mesh_sdf(verts, f, p, sign="winding")
    sure = np.abs(dw) > 1e-5
    np.testing.assert_array_equal(np.sign(dw[sure]), np.sign(d.numpy()[sure]))


@needs_o3d
def test_self_overlap_is_inside_for_winding_outside_for_parity(cube, rng):
    # one "mesh" of two interpenetrating closed cubes (like a hand pushed into the torso): w = 2 in the overlap
    v, f = cube
    v2, f2 = np.concatenate([v, v + [0.5, 0.1, 0.1]]), np.concatenate([f, f + len(v)])  # no coplanar faces
    p = np.stack([rng.uniform(0.05, 0.45, 200), rng.uniform(-0.35, 0.45, 200), rng.uniform(-0.35, 0.45, 200)], 1)
    np.testing.assert_allclose(gt.winding_number(v2, f2, p), 2.0, atol=1e-9)
    np.testing.assert_array_equal(gt.ray_winding_number(v2, f2, p), 2)
    for sign in ("winding", "fast_winding", "ray_winding"):
        assert (gt.mesh_sdf(v2, f2, p, sign=sign) < 0).all()
    assert (gt.mesh_sdf(v2, f2, p, sign="raycast") > 0).all()  # parity: an even number of crossings


@needs_o3d
def test_errors(cube):
    v, f = cube
    with pytest.raises(ValueError, match="non-finite"):
        gt.mesh_sdf(v, f, np.array([[0.0, np.nan, 0.0]]))
    with pytest.raises(ValueError, match="not closed.*boundary edges"):
        gt.mesh_sdf(v, f[1:], np.zeros((1, 3)))
    with pytest.raises(ValueError, match="oriented inward"):
        gt.mesh_sdf(v, f[:, ::-1], np.zeros((1, 3)))
    with pytest.raises(ValueError, match="inconsistently"):
        g = f.copy()
        g[0] = g[0, ::-1]
        gt.mesh_sdf(v, g, np.zeros((1, 3)))
    with pytest.raises(ValueError, match="odd"):
        gt.mesh_sdf(v, f, np.zeros((1, 3)), nsamples=4)
    with pytest.raises(ValueError, match="sign="):
        gt.mesh_sdf(v, f, np.zeros((1, 3)), sign="parity")
    with pytest.raises(ValueError, match="same B"):
        gt.batch_mesh_sdf(v[None], f, np.zeros((2, 5, 3)))
    # holes tolerated by the winding number when asked to
    d = gt.mesh_sdf(v, f[2:], np.array([[0.0, 0.0, 0.1]]), sign="winding", check_closed=False)
    assert d[0] < 0


# ------------------------------------------------------------------ training query sampler
def random_rotations(n, gen):
    q = torch.randn(n, 4, generator=gen, dtype=torch.float64)
    q = q / q.norm(dim=-1, keepdim=True)
    w, x, y, z = q.unbind(-1)
    return torch.stack([
        1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w),
        2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w),
        2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], -1).reshape(n, 3, 3)


@pytest.fixture(scope="module")
def two_part_scene():
    """Two disjoint boxes (2 bodies, 2 parts) with random part frames and boxes."""
    a = trimesh.creation.box(extents=(2.0, 2.0, 2.0))
    b = trimesh.creation.box(extents=(1.0, 1.0, 1.0))
    b.apply_translation((5.0, 0, 0))
    v = np.concatenate([a.vertices, b.vertices])
    f = np.concatenate([a.faces, b.faces + len(a.vertices)])
    gen = torch.Generator().manual_seed(3)
    B, K = 2, 2
    G = torch.eye(4, dtype=torch.float64).repeat(B, K, 1, 1)
    G[..., :3, :3] = random_rotations(B * K, gen).reshape(B, K, 3, 3)
    G[..., :3, 3] = torch.randn(B, K, 3, generator=gen, dtype=torch.float64)
    lo = -torch.rand(B, K, 3, generator=gen, dtype=torch.float64) - 0.1
    hi = torch.rand(B, K, 3, generator=gen, dtype=torch.float64) + 0.1
    verts = torch.as_tensor(np.stack([v, v]))
    parts = [np.arange(len(a.faces)), np.arange(len(a.faces), len(f))]
    return verts, torch.as_tensor(f), G, lo, hi, parts


def test_sampler_uniform_points_in_their_boxes(two_part_scene):
    from volsmpl.body.partition import Partition
    verts, f, G, lo, hi, parts = two_part_scene
    nu, ns = 300, 50
    q = tq.sample_training_queries(verts, f, G, lo, hi, n_uniform=nu, n_surface=ns, face_ids_per_part=parts,
                                   generator=torch.Generator().manual_seed(0))
    assert q.shape == (2, 2 * (nu + ns), 3) and q.dtype == verts.dtype
    per_part = q.reshape(2, 2, nu + ns, 3)[:, :, :nu]  # (B, K, nu, 3)
    for k in range(2):
        local = Partition.canonicalize(per_part[:, k], G)[:, k]  # into part k's frame
        assert (local >= lo[:, k, None] - 1e-9).all() and (local <= hi[:, k, None] + 1e-9).all()
        # uniform: each coordinate's mean is the box centre (300 samples: ~5 sigma band)
        centre, size = 0.5 * (lo[:, k] + hi[:, k]), hi[:, k] - lo[:, k]
        assert ((local.mean(1) - centre).abs() < 0.1 * size).all()
        # and they fill the box: the samples reach near every side
        assert ((local.amin(1) - lo[:, k]) < 0.05 * size).all() and ((hi[:, k] - local.amax(1)) < 0.05 * size).all()


@needs_o3d
def test_sampler_surface_points_on_their_part_with_sigma(two_part_scene):
    verts, f, G, lo, hi, parts = two_part_scene
    ns = 4000
    sigma = (0.01, 0.03)
    q = tq.sample_training_queries(verts, f, G, lo, hi, n_uniform=0, n_surface=ns, sigma=sigma,
                                   face_ids_per_part=parts, generator=torch.Generator().manual_seed(1))
    q = q.reshape(2, 2, ns, 3)
    a = trimesh.creation.box(extents=(2.0, 2.0, 2.0))
    for k, (centre, half) in enumerate([(np.zeros(3), 1.0), (np.array([5.0, 0, 0]), 0.5)]):
        pts = q[0, k].numpy()
        assert np.abs(pts - centre).max() < half + 0.2  # all around part k's own box, not the other part
        sdf = box_sdf(pts - centre, half)
        np.testing.assert_allclose(gt.mesh_sdf(verts[0].numpy(), f.numpy(), pts[:500]), sdf[:500], atol=2e-6)
        # normal component of isotropic noise ~ N(0, sigma^2) on (mostly) flat faces
        for (s, block) in zip(sigma, (sdf[: ns // 2], sdf[ns // 2:])):
            assert abs(block.std() / s - 1) < 0.12, (k, s, block.std())
            assert abs(block.mean()) < 0.15 * s
    assert a.area > 0


def test_sampler_without_part_faces_and_sigma_zero(two_part_scene):
    verts, f, G, lo, hi, _ = two_part_scene
    q = tq.sample_training_queries(verts, f, G, lo, hi, n_uniform=0, n_surface=3000, sigma=0.0,
                                   generator=torch.Generator().manual_seed(2))
    pts = q[1].numpy()
    d = np.minimum(np.abs(box_sdf(pts, 1.0)), np.abs(box_sdf(pts - [5.0, 0, 0], 0.5)))
    assert d.max() < 1e-9
    # whole-mesh area weighting: the big box has 4x the area of the small one
    frac_big = (pts[:, 0] < 2.5).mean()
    assert abs(frac_big - 0.8) < 0.03


def test_sampler_whole_body_block(two_part_scene):
    """n_body appends area-weighted whole-mesh samples with body_sigma offsets; the part blocks are unchanged."""
    verts, f, G, lo, hi, parts = two_part_scene
    kw = dict(n_uniform=8, n_surface=8, face_ids_per_part=parts)
    base = tq.sample_training_queries(verts, f, G, lo, hi, generator=torch.Generator().manual_seed(4), **kw)
    q = tq.sample_training_queries(verts, f, G, lo, hi, generator=torch.Generator().manual_seed(4), n_body=3000,
                                   body_sigma=0.0, **kw)
    assert q.shape == (2, 2 * 16 + 3000, 3) and torch.equal(q[:, :32], base)
    pts = q[0, 32:].numpy()
    d = np.minimum(np.abs(box_sdf(pts, 1.0)), np.abs(box_sdf(pts - [5.0, 0, 0], 0.5)))
    assert d.max() < 1e-9  # on the mesh
    assert abs((pts[:, 0] < 2.5).mean() - 0.8) < 0.03  # the big box has 4x the small one's area
    sigma = (0.01, 0.03)
    q = tq.sample_training_queries(verts, f, G, lo, hi, generator=torch.Generator().manual_seed(5), n_body=8000,
                                   body_sigma=sigma, **kw)[0, 32:].numpy()
    big = np.abs(q).max(1) < 1.2  # around the big box; its faces are flat, so the SDF ~ the normal offset
    for s, block, inside in zip(sigma, (q[:4000], q[4000:]), (big[:4000], big[4000:])):
        sdf = box_sdf(block[inside], 1.0)
        assert abs(sdf.std() / s - 1) < 0.12, (s, sdf.std())
    with pytest.raises(ValueError, match="n_body"):
        tq.sample_training_queries(verts, f, G, lo, hi, n_body=-1)


def test_sampler_reproducible_and_typed(two_part_scene):
    verts, f, G, lo, hi, parts = two_part_scene
    run = lambda seed, **kw: tq.sample_training_queries(verts, f, G, lo, hi, n_uniform=16, n_surface=16,
                                                        face_ids_per_part=parts,
                                                        generator=torch.Generator().manual_seed(seed), **kw)
    assert torch.equal(run(5), run(5))
    assert not torch.allclose(run(5), run(6))
    q32 = tq.sample_training_queries(verts.float(), f, G.float(), lo.float(), hi.float(), n_uniform=4, n_surface=6,
                                     generator=torch.Generator().manual_seed(5))
    assert q32.dtype == torch.float32 and q32.shape == (2, 20, 3)
    qn = tq.sample_training_queries(verts.numpy(), f.numpy(), G.numpy(), lo.numpy(), hi.numpy(), n_uniform=4,
                                    n_surface=6, generator=torch.Generator().manual_seed(5))
    assert isinstance(qn, np.ndarray) and qn.shape == (2, 20, 3)
    with pytest.raises(ValueError, match="box_max < box_min"):
        tq.sample_training_queries(verts, f, G, hi, lo)
    with pytest.raises(ValueError, match="sigma"):
        tq.sample_training_queries(verts, f, G, lo, hi, sigma=-1.0)
    with pytest.raises(ValueError, match="face_ids_per_part"):
        tq.sample_training_queries(verts, f, G, lo, hi, face_ids_per_part=parts[:1])


# ------------------------------------------------------------------ the default body
@pytest.fixture(scope="module")
def default_body_mesh():
    from volsmpl.body.model import DEFAULT_BODY_FILE
    if not DEFAULT_BODY_FILE.exists():
        pytest.skip("default body asset not exported yet")
    import volsmpl
    body = volsmpl.create_body()
    gen = torch.Generator().manual_seed(0)
    out = body(body_pose=0.3 * torch.randn(1, 69, generator=gen))
    return body, out


@needs_o3d
def test_default_body_raycast_sign_matches_winding(default_body_mesh):
    from volsmpl.body.partition import Partition
    body, out = default_body_mesh
    v, f = out.vertices.detach(), torch.as_tensor(np.asarray(body.faces))
    assert gt.closed_mesh_problems(f) is None
    part = Partition(body, n_samples=8)
    G = part.part_transforms(out.full_pose, out.joints)
    lo, hi = part.boxes(v, G)
    q = tq.sample_training_queries(v, f, G, lo, hi, n_uniform=42, n_surface=42, face_ids_per_part=part.tight_face_ids,
                                   generator=torch.Generator().manual_seed(0))[0]
    q = q[torch.randperm(len(q), generator=torch.Generator().manual_seed(1))[:2000]]
    d = gt.mesh_sdf(v[0], f, q)
    w = gt.winding_number(v[0], f, q)
    assert ((w - w.round()).abs() < 1e-6).all()  # closed mesh: integer winding numbers (self-intersections give 2)
    sure = d.abs() > 1e-5
    simple = sure & (w.round().abs() <= 1)
    assert simple.float().mean() > 0.95
    assert torch.equal((d[simple] < 0), (w[simple] > 0.5))
    # where the posed mesh overlaps itself (w = 2) ray parity counts an even number of crossings: only there may
    # the two disagree, and the winding number (union semantics) is the one that calls the point inside
    assert ((d[sure] < 0) != (w[sure] > 0.5)).le(w[sure].round() >= 2).all()
    assert 0.2 < (d < 0).float().mean() < 0.8
    # counted along rays, the winding number is the same integer wherever the point is off the surface
    assert torch.equal(gt.ray_winding_number(v[0], f, q[sure]), w[sure].round().long())


def test_surface_samples_uniform_on_a_triangle():
    v = torch.tensor([[[0.0, 0, 0], [2.0, 0, 0], [0.5, 1.5, 0], [9, 9, 9]]], dtype=torch.float64)
    f = torch.tensor([[0, 1, 2], [0, 1, 3]])
    pts = tq.sample_surface(v, f, 20000, face_ids_per_part=[[0]], generator=torch.Generator().manual_seed(0))[0, 0]
    assert pts.shape == (20000, 3) and (pts[:, 2] == 0).all()
    # barycentric coordinates of a uniform sample: each has mean 1/3 and second moment 1/6
    A = (v[0, :3, :2] - v[0, 2, :2])[:2].T
    lam01 = torch.linalg.solve(A, (pts[:, :2] - v[0, 2, :2]).T).T
    lam = torch.cat([lam01, 1 - lam01.sum(1, keepdim=True)], dim=1)
    assert (lam > -1e-12).all()
    assert torch.allclose(lam.mean(0), torch.full((3,), 1 / 3, dtype=torch.float64), atol=0.01)
    assert torch.allclose((lam ** 2).mean(0), torch.full((3,), 1 / 6, dtype=torch.float64), atol=0.01)


# ------------------------------------------------------------------ the torch backend (MeshQuery, batch_sdf)
def _shapes(cube, sphere):
    L = trimesh.util.concatenate([trimesh.creation.box((1, 1, 1)),
                                  trimesh.creation.box((1, 1, 1), transform=trimesh.transformations.translation_matrix((0.5, 0.5, 0)))])
    return {"cube": cube, "sphere": sphere, "overlap": (np.asarray(L.vertices), np.asarray(L.faces))}


@pytest.mark.parametrize("shape", ["cube", "sphere", "overlap"])
def test_mesh_query_against_brute_force_and_winding(shape, cube, sphere, rng):
    """Exact distances (brute force over every triangle) and integer winding numbers (our float64 solid angles;
    2 inside the overlap of two boxes) for points away from the surface, rays through vertices included."""
    from volsmpl.geometry.triangle_queries import RAY_DIRECTION, MeshQuery
    v, f = _shapes(cube, sphere)[shape]
    p = rng.uniform(-0.9, 1.4, (600, 3))
    d = np.asarray(RAY_DIRECTION)
    p = np.concatenate([p, v - 0.3 * d, v + 0.3 * d, 0.5 * (v[f[:, 0]] + v[f[:, 1]]) - 0.2 * d])  # rays through vertices/edges
    mq = MeshQuery(torch.as_tensor(v), torch.as_tensor(f), cluster_size=4, chunk=64)
    dist = mq.distances(torch.as_tensor(p)).numpy()
    assert np.abs(dist - brute_distance(p, v, f)).max() < 1e-9
    w_ref = np.round(gt.winding_number_reference(v, f, p))
    keep = off_surface(p, v, f)
    assert keep.sum() > 500
    assert np.array_equal(mq.winding_numbers(torch.as_tensor(p)).numpy()[keep], w_ref[keep])


def test_mesh_query_batch_against_brute_force(sphere, rng):
    """A batch of meshes sharing faces (the sphere moved and stretched per mesh), each with its own points: exact
    distances by brute force over every triangle of that mesh, nearest faces at those distances, integer winding
    numbers (float64 solid angles); in blocks smaller than a mesh's clusters and points, so that blocks mix meshes."""
    from volsmpl.geometry.triangle_queries import MeshQuery
    v0, f = sphere
    scale = np.array([[1.0, 1.0, 1.0], [1.4, 0.7, 1.0], [0.6, 0.6, 1.3]])
    verts = v0[None] * scale[:, None] + np.array([[0.0, 0, 0], [0.05, -0.02, 0.1], [-0.1, 0, 0]])[:, None]
    pts = rng.uniform(-1.0, 1.0, (3, 400, 3))
    mq = MeshQuery(torch.as_tensor(verts), torch.as_tensor(f), cluster_size=8, chunk=64, bound_chunk=300)
    dist, near = mq.distances(torch.as_tensor(pts)).numpy(), mq.nearest_faces(torch.as_tensor(pts)).numpy()
    wind = mq.winding_numbers(torch.as_tensor(pts)).numpy()
    assert dist.shape == near.shape == wind.shape == (3, 400)
    for b in range(3):
        ref = brute_distance(pts[b], verts[b], f)
        assert np.abs(dist[b] - ref).max() < 1e-9
        tri = verts[b][f[near[b]]]                        # each point's nearest face: at the exact distance
        cp = closest_point_on_triangles(pts[b], tri[:, 0], tri[:, 1], tri[:, 2])[np.arange(400), np.arange(400)]
        assert np.abs(np.linalg.norm(cp - pts[b], axis=-1) - ref).max() < 1e-9
        keep = off_surface(pts[b], verts[b], f)
        assert keep.sum() > 350
        assert np.array_equal(wind[b][keep], np.round(gt.winding_number_reference(verts[b], f, pts[b]))[keep])
    with pytest.raises(ValueError, match="one set per mesh"):
        mq.distances(torch.as_tensor(pts[:2]))


def test_mesh_query_chunk_bound_does_not_change_results(sphere, rng):
    from volsmpl.geometry.triangle_queries import MeshQuery
    v, f = (torch.as_tensor(x) for x in sphere)
    p = torch.as_tensor(rng.uniform(-0.8, 0.8, (300, 3)))
    a, b = MeshQuery(v, f), MeshQuery(v, f, cluster_size=8, chunk=16)
    assert torch.equal(a.nearest_faces(p), b.nearest_faces(p))
    assert torch.equal(a.crossings(p)[0], b.crossings(p)[0]) and torch.equal(a.crossings(p)[1], b.crossings(p)[1])
    with pytest.raises(ValueError, match="chunk"):
        MeshQuery(v, f, cluster_size=32, chunk=8)
    with pytest.raises(ValueError, match="NaN"):
        a.nearest_faces(torch.full((2, 3), float("nan"), dtype=torch.float64))


@needs_o3d
@pytest.mark.parametrize("sign", ["ray_winding", "raycast"])
def test_torch_backend_matches_open3d_on_self_contact_bodies(default_body_mesh, sign):
    """batch_sdf(backend='torch') against open3d (distance, ray-winding or parity sign) and libigl's exact winding
    number on posed default bodies in self-contact: equal signs farther than 1 mm from the surface, |d| to 1e-6 m."""
    from volsmpl.body.poses import named_pose
    body, _ = default_body_mesh
    with torch.no_grad():
        verts = body(body_pose=torch.cat([named_pose("arms_crossed"), named_pose("squatting")])).vertices.double()
    g = torch.Generator().manual_seed(1)
    lo, hi = verts.amin(1, keepdim=True) - 0.05, verts.amax(1, keepdim=True) + 0.05
    idx = torch.randint(verts.shape[1], (2, 1500), generator=g)
    pts = torch.cat([lo + torch.rand(2, 1500, 3, generator=g, dtype=torch.float64) * (hi - lo),
                     torch.gather(verts, 1, idx[..., None].expand(-1, -1, 3))
                     + 0.01 * torch.randn(2, 1500, 3, generator=g, dtype=torch.float64)], dim=1)
    ref = gt.batch_mesh_sdf(verts, body.faces, pts, sign=sign, nsamples=3)
    ours = gt.batch_sdf(verts, body.faces, pts, sign=sign, backend="torch")
    assert ours.dtype == pts.dtype and ours.shape == (2, 3000)
    far = ref.abs() > 1e-3
    assert far.float().mean() > 0.85
    assert torch.equal(ours[far] < 0, ref[far] < 0)
    assert (ours.abs() - ref.abs()).abs().max() < 1e-6
    if sign == "ray_winding":
        w = torch.stack([torch.as_tensor(gt.winding_number(verts[i], body.faces, pts[i])) for i in range(2)])
        assert torch.equal(ours[far] < 0, w[far] > 0.5)
        assert (w > 1.5).any()  # the poses do overlap themselves: points inside two parts at once


def test_resolve_gt_backend_and_batch_sdf_types(cube):
    assert gt.resolve_gt_backend("auto", "cuda") == "torch" and gt.resolve_gt_backend("torch", "cpu") == "torch"
    if HAS_O3D:
        assert gt.resolve_gt_backend("auto", torch.device("cpu")) == "open3d"
    with pytest.raises(ValueError, match="gt_backend"):
        gt.resolve_gt_backend("bvh", "cpu")
    v, f = cube
    p = np.array([[[0.0, 0, 0], [1.0, 0, 0]]])
    out = gt.batch_sdf(v[None], f, p, backend="torch")
    assert isinstance(out, np.ndarray) and np.allclose(out, [[-0.5, 0.5]])
    out = gt.batch_sdf(torch.as_tensor(v[None]), f, torch.as_tensor(p, dtype=torch.float32), backend="torch")
    assert out.dtype == torch.float32 and torch.allclose(out, torch.tensor([[-0.5, 0.5]]))
    with pytest.raises(ValueError, match="not closed"):
        gt.batch_sdf(v[None], f[:-1], p, backend="torch")


@pytest.mark.cuda
def test_torch_backend_on_cuda_matches_cpu(sphere, rng):
    v, f = sphere
    p = torch.as_tensor(rng.uniform(-0.8, 0.8, (1, 2000, 3)))
    cpu = gt.batch_sdf(torch.as_tensor(v)[None], f, p, backend="torch")
    gpu = gt.batch_sdf(torch.as_tensor(v)[None].cuda(), f, p.cuda(), backend="auto")
    assert gpu.device.type == "cuda" and torch.allclose(gpu.cpu(), cpu, atol=1e-12)


@pytest.mark.cuda
def test_batched_torch_ground_truth_on_cuda_matches_cpu(default_body_mesh):
    """One MeshQuery for a batch of posed bodies on CUDA (the training batch's ground truth there) against the same
    on the CPU: equal signs, distances to 1e-9 m."""
    from volsmpl.body.poses import named_pose
    body, _ = default_body_mesh
    with torch.no_grad():
        verts = body(body_pose=torch.cat([named_pose("arms_crossed"), named_pose("squatting")])).vertices.double()
    g = torch.Generator().manual_seed(2)
    pts = verts[:, torch.randint(verts.shape[1], (3000,), generator=g)] \
        + 0.02 * torch.randn(2, 3000, 3, generator=g, dtype=torch.float64)
    cpu = gt.batch_sdf(verts, body.faces, pts, backend="torch")
    gpu = gt.batch_sdf(verts.cuda(), body.faces, pts.cuda(), backend="auto")
    assert gpu.device.type == "cuda"
    assert torch.equal(gpu.cpu() < 0, cpu < 0) and (gpu.cpu() - cpu).abs().max() < 1e-9
