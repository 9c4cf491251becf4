"""volsmpl.scene.scan's Scan and volsmpl.scene.floor.floor_level: a scene of any size read once, its points taken
where they matter at a density in metres; the floor level robust to stray points."""
import numpy as np
import pytest
import trimesh
from volsmpl.scene.floor import floor_level
from volsmpl.scene.scan import Scan, open_scan


def _floor_mesh(size: float = 100.0) -> trimesh.Trimesh:
    """A size x size m floor at y = 0 (two triangles) and a 0.2 m cube lantern at (50, 0.5, 50)."""
    floor = trimesh.Trimesh([[0, 0, 0], [size, 0, 0], [size, 0, size], [0, 0, size]], [[0, 2, 1], [0, 3, 2]])
    lantern = trimesh.creation.box(extents=(0.2, 0.2, 0.2))
    lantern.apply_translation([50.0, 0.5, 50.0])
    return trimesh.util.concatenate([floor, lantern])


def test_mesh_points_at_the_spacing_inside_the_box(tmp_path):
    """A 100 x 100 m floor with a lantern: a 2 x 2 m box around the lantern at 2 cm spacing holds ~4 m^2 / 4e-4 =
    10,000 floor points and 0.24 m^2 / 4e-4 = 600 lantern points (a whole-scene count of 16,384 gave it ~0)."""
    path = tmp_path / "temple.ply"
    _floor_mesh().export(path)
    scan = open_scan(path, units="m")
    assert scan.is_mesh
    lo, hi = np.array([49.0, -0.1, 49.0]), np.array([51.0, 2.0, 51.0])
    pts = scan.points(spacing=0.02, box=(lo, hi))
    assert ((pts >= lo) & (pts <= hi)).all()
    lantern = pts[pts[:, 1] > 0.3]
    on_floor = pts[np.abs(pts[:, 1]) < 1e-9]
    assert len(lantern) == pytest.approx(600, rel=0.15)
    assert len(on_floor) == pytest.approx(10_000, rel=0.05)


def test_units_and_up_axis(tmp_path):
    """A z-up box in mm, 2000 (x) x 3000 (y) x 1000 (z, up): in our Y-up metres it spans x 2, y 1 (up), z 3."""
    box = trimesh.creation.box(extents=(2000.0, 3000.0, 1000.0))
    box.export(tmp_path / "z.ply")
    b = open_scan(tmp_path / "z.ply", units="mm").to_y_up("z").bounds()
    assert np.allclose(b[1] - b[0], [2.0, 1.0, 3.0])


def test_cloud_thinned_to_one_point_per_voxel_nearest_its_centre():
    rng = np.random.default_rng(0)
    pts = rng.uniform(0, 1, size=(20000, 3))
    scan = Scan(pts, None)
    s = 0.25
    out = scan.points(spacing=s, box=(np.zeros(3), np.ones(3)))
    # brute force: 4^3 voxels, each holds points; the kept one is the nearest to the voxel's centre
    assert len(out) == 64
    for v in out:
        cell = np.floor(v / s)
        members = pts[(np.floor(pts / s) == cell).all(1)]
        d = np.linalg.norm(members - (cell + 0.5) * s, axis=1)
        assert np.allclose(v, members[d.argmin()])


def test_a_region_too_dense_is_refused_naming_a_spacing_that_fits(tmp_path):
    path = tmp_path / "big.ply"
    _floor_mesh().export(path)
    with pytest.raises(ValueError, match=r"big\.ply: .* make .* points \(more than 100,000\): give a spacing of "
                                         r"([\d.]+) cm or more") as e:
        open_scan(path).points(spacing=0.05, max_points=100_000)
    fit = float(str(e.value).rsplit("spacing of ", 1)[1].split(" cm")[0]) / 100
    assert len(open_scan(path).points(spacing=fit, max_points=100_000)) <= 100_000
    with pytest.raises(ValueError, match="positive number of metres"):
        open_scan(path).points(spacing=0.0)


def test_overview_and_empty_scan(tmp_path):
    path = tmp_path / "room.ply"
    _floor_mesh(10.0).export(path)
    assert open_scan(path).overview(5000).shape == (5000, 3)
    np.save(tmp_path / "empty.npy", np.zeros((0, 3)))
    with pytest.raises(ValueError, match="empty"):
        open_scan(tmp_path / "empty.npy")


def test_floor_level_ignores_strays_below_the_floor():
    """A floor at 0.30 m (4,000 points), walls up to 2.8 m, and 5 % stray points 0.5-1 m under the floor: the 1st
    percentile lands among the strays, the densest low slab on the floor."""
    rng = np.random.default_rng(1)
    h = np.r_[np.full(4000, 0.30) + rng.normal(0, 0.003, 4000), rng.uniform(0.3, 3.1, 4000),
              rng.uniform(-0.7, -0.2, 420)]
    assert np.percentile(h, 1) < 0.0
    assert floor_level(h) == pytest.approx(0.30, abs=0.01)
