"""Object templates: closed and outward, sizes from the prior, determinism, regions, seats and supports."""
from __future__ import annotations

import numpy as np
import pytest

from volsmpl.geometry.groundtruth import closed_mesh_problems, signed_volume
from volsmpl.scene.objects import CATEGORIES, REGIONS, SIZE_PRIOR, make_object

SEEDS = (None, 0, 1, 7)


@pytest.mark.parametrize("category", CATEGORIES)
def test_closed_outward_and_sized(category):
    for seed in SEEDS:
        obj = make_object(category, seed)
        m = obj.mesh
        assert closed_mesh_problems(m.faces) is None, (category, seed)
        assert m.is_watertight and m.is_winding_consistent
        for c in range(len(obj.component_names)):  # each component closed and wound outward
            f = m.faces[obj.component == c]
            assert closed_mesh_problems(f) is None
            assert signed_volume(m.vertices, f) > 0, (category, obj.component_names[c])
        assert signed_volume(m.vertices, m.faces) > 0
        lo, hi = m.bounds
        assert abs(lo[1]) < 1e-12 and np.allclose(0.5 * (lo + hi)[[0, 2]], 0, atol=1e-12)  # canonical frame
        ext = hi - lo
        for key, axis in (("width", 0), ("height", 1), ("depth", 2)):
            mean, std = SIZE_PRIOR[category][key]
            assert abs(ext[axis] - obj.sizes[key]) < 1e-9
            assert mean - 2 * std - 1e-9 <= ext[axis] <= mean + 2 * std + 1e-9, (category, key, ext[axis])
        if seed is None:
            assert np.allclose(ext, [SIZE_PRIOR[category][k][0] for k in ("width", "height", "depth")])


@pytest.mark.parametrize("category", ["chair", "sofa", "bed", "stool"])
def test_seat_height_matches_prior(category):
    for seed in SEEDS:
        obj = make_object(category, seed)
        seats = obj.seats()
        assert seats
        want = obj.sizes.get("seat_height", obj.sizes["height"])
        for s in seats:
            assert s["height"] == pytest.approx(want, abs=1e-9)
            assert np.allclose(s["facing"], [0, 0, 1])
            v = obj.mesh.vertices[obj.mesh.faces[obj.regions["seat"]]].reshape(-1, 3)
            assert v[:, 0].min() <= s["position"][0] <= v[:, 0].max()
            assert v[:, 2].min() <= s["position"][2] <= v[:, 2].max()


def test_determinism():
    for category in CATEGORIES:
        a, b = make_object(category, 5), make_object(category, 5)
        assert a.mesh.vertices.tobytes() == b.mesh.vertices.tobytes()
        assert a.mesh.faces.tobytes() == b.mesh.faces.tobytes()
        assert not np.array_equal(make_object(category, 6).extents, a.extents)


def test_errors():
    with pytest.raises(ValueError, match="known: cup, bottle"):
        make_object("spaceship")
    with pytest.raises(ValueError, match="scale"):
        make_object("cup", scale=-1.0)
    with pytest.raises(ValueError, match="seed"):
        make_object("cup", seed=-3)


def test_scale():
    base = make_object("table", 2)
    low = make_object("table", 2, scale=(0.5, 0.6, 2.0))
    assert np.allclose(low.extents, base.extents * [0.5, 0.6, 2.0])
    assert low.mesh.bounds[0][1] == pytest.approx(0.0, abs=1e-12)
    assert signed_volume(low.mesh.vertices, low.mesh.faces) > 0


def _region_normals(obj, name):
    return obj.mesh.face_normals[obj.regions[name]]


def test_regions_non_empty_and_meaningful():
    for category in CATEGORIES:
        obj = make_object(category, 3)
        assert set(obj.regions) == set(REGIONS[category])
        for name, faces in obj.regions.items():
            assert len(faces) > 0, (category, name)
            assert np.all(np.diff(faces) > 0) and faces.max() < len(obj.mesh.faces)
    cup = make_object("cup", 1)
    assert cup.mesh.triangles_center[cup.regions["handle"]][:, 0].min() > 0  # handle on +X, outside the body
    chair = make_object("chair", 1)
    assert np.allclose(_region_normals(chair, "seat"), [0, 1, 0])
    assert np.allclose(_region_normals(chair, "back"), [0, 0, 1])
    assert chair.mesh.triangles_center[chair.regions["back"]][:, 2].max() < 0  # backrest behind the seat centre
    assert (_region_normals(make_object("laptop", 1), "screen")[:, 2] > 0.8).all()  # the screen faces +Z
    sk = make_object("skateboard", 1)
    assert np.allclose(sk.mesh.triangles_center[sk.regions["deck"]][:, 1], sk.extents[1])
    bat = make_object("bat", 1)
    assert bat.mesh.triangles_center[bat.regions["handle"]][:, 1].min() > 0.5 * bat.extents[1]  # handle at the top


def test_region_points_on_region():
    obj = make_object("chair", 4)
    p, n = obj.region_points("seat", 300, seed=1)
    assert p.shape == (300, 3) and np.allclose(n, [0, 1, 0])
    assert np.allclose(p[:, 1], obj.seats()[0]["height"])
    p2, _ = obj.region_points("seat", 300, seed=1)
    assert np.array_equal(p, p2)
    with pytest.raises(ValueError, match="no region"):
        obj.region_points("wheels")


def test_supports():
    table = make_object("table", 0)
    (top,) = table.supports()
    assert top["height"] == pytest.approx(table.extents[1])
    assert np.allclose(top["half_size"], table.extents[[0, 2]] / 2)
    shelf = make_object("shelf", 0)
    boards = [s for s in shelf.supports() if s["name"] == "boards"]
    assert len(boards) >= 3  # bottom + at least two boards
    assert all(0 < s["height"] < shelf.extents[1] for s in boards)


def test_rotation_error_modulo_symmetry():
    from scipy.spatial.transform import Rotation

    from volsmpl.scene import SYMMETRY, rotation_error_deg

    R_true = Rotation.from_euler("xyz", [20, -35, 70], degrees=True).as_matrix()
    spin = R_true @ Rotation.from_euler("y", 50, degrees=True).as_matrix()  # a turn about the object's own axis
    tilt = R_true @ Rotation.from_euler("x", 25, degrees=True).as_matrix()
    assert abs(rotation_error_deg(spin, R_true) - 50) < 1e-6
    assert rotation_error_deg(spin, R_true, "axis_y") < 1e-4
    assert abs(rotation_error_deg(tilt, R_true, "axis_y") - 25) < 1e-6
    assert rotation_error_deg(tilt, R_true, "sphere") is None
    assert SYMMETRY["ball"] == "sphere" and "cup" not in SYMMETRY  # the cup's handle breaks its symmetry
    with pytest.raises(ValueError, match="symmetry"):
        rotation_error_deg(tilt, R_true, "axis_z")
