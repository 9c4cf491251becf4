"""A user's scene of any size: the example's room (examples/egohmr/room.ply) and the same room in one corner of a
100 x 100 m floor (its floor rectangle replaced by the big one) give the same points in the 2 m cube around the
body, as many as the surface inside the cube over spacing^2. The reference area is the room's surface clipped by
the cube's six planes (each triangle, by hand), independent of the sampler."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import trimesh

from volsmpl.cli import main

EXAMPLE = Path(__file__).resolve().parents[3] / "examples" / "egohmr"
#: a point above the example's chair (Y-up world, metres): where the regressed pelvis lies
ABOVE_SEAT = np.array([0.4, 0.7, -0.55])


def room_y_up() -> trimesh.Trimesh:
    """The example's room in the Y-up world, metres (its file: millimetres, z up)."""
    m = trimesh.load(EXAMPLE / "room.ply", process=False)
    v = np.asarray(m.vertices, np.float64) / 1000.0
    return trimesh.Trimesh(np.stack([v[:, 0], v[:, 2], -v[:, 1]], 1), np.asarray(m.faces), process=False)


def big_floor(room: trimesh.Trimesh) -> trimesh.Trimesh:
    """The room with its floor rectangle (the faces at y = 0 larger than 1 m^2) replaced by a 100 x 100 m floor
    with the room in its corner."""
    tri = room.vertices[room.faces]
    floor = (np.abs(tri[:, :, 1]).max(1) < 1e-9) & (room.area_faces > 1.0)
    assert floor.sum() == 2
    rest = trimesh.Trimesh(room.vertices, room.faces[~floor], process=False)
    x0, z0 = -2.5, -2.0
    v = np.array([[x0, 0, z0], [x0 + 100, 0, z0], [x0 + 100, 0, z0 + 100], [x0, 0, z0 + 100]], dtype=np.float64)
    return trimesh.util.concatenate([rest, trimesh.Trimesh(v, [[0, 3, 2], [0, 2, 1]], process=False)])


def write_mm_z_up(mesh: trimesh.Trimesh, path: Path) -> Path:
    v = np.asarray(mesh.vertices)
    trimesh.Trimesh(np.stack([v[:, 0], -v[:, 2], v[:, 1]], 1) * 1000.0, mesh.faces, process=False).export(path)
    return path


def area_in_cube(mesh: trimesh.Trimesh, T: np.ndarray, centre: np.ndarray, size: float) -> float:
    """The area of `mesh` (Y-up world) inside the camera-frame cube of edge `size` at `centre`: each triangle
    clipped by the cube's six planes (Sutherland-Hodgman), the clipped polygons' areas summed."""
    tris = (np.asarray(mesh.vertices)[mesh.faces] @ T[:3, :3].T + T[:3, 3]) - centre
    h, total = 0.5 * size, 0.0
    for tri in tris:
        poly = list(tri)
        for axis in range(3):
            for sign in (1.0, -1.0):
                d = [sign * p[axis] - h for p in poly]            # <= 0: inside this plane
                nxt = []
                for i in range(len(poly)):
                    a, b, da, db = poly[i], poly[(i + 1) % len(poly)], d[i], d[(i + 1) % len(poly)]
                    if da <= 0:
                        nxt.append(a)
                    if (da < 0 < db) or (db < 0 < da):
                        nxt.append(a + (b - a) * da / (da - db))
                poly = nxt
                if len(poly) < 3:
                    break
            if len(poly) < 3:
                break
        if len(poly) >= 3:
            total += 0.5 * np.linalg.norm(sum(np.cross(poly[i], poly[(i + 1) % len(poly)]) for i in range(len(poly))))
    return total


@pytest.fixture(scope="module")
def scans(tmp_path_factory):
    d = tmp_path_factory.mktemp("scans")
    room = room_y_up()
    return room, write_mm_z_up(room, d / "room.ply"), write_mm_z_up(big_floor(room), d / "big.ply")


def test_points_in_the_cube_are_area_over_spacing_squared_on_any_size(scans):
    from volsmpl.apps.egohmr.user_scene import cube_points
    from volsmpl.apps.egohmr.userframe import load_user_frame
    from volsmpl.scene.scan import open_scan

    room, room_file, big_file = scans
    frame = load_user_frame(EXAMPLE / "frame.json")
    T = frame.world_to_camera
    centre = T[:3, :3] @ ABOVE_SEAT + T[:3, 3]
    area = area_in_cube(room, T, centre, 2.0)
    assert 4.0 < area < 12.0                                    # the floor across the cube, the chair, a wall part
    for path in (room_file, big_file):
        scan = open_scan(path, "mm").to_y_up("z")
        if path == big_file:
            assert np.ptp(scan.vertices, axis=0).max() >= 100.0
        for spacing in (0.02, 0.04):
            pts = cube_points(frame, scan, centre, 2.0, spacing, seed=1)
            want = area / spacing ** 2
            assert abs(len(pts) - want) < 0.03 * want + 3 * np.sqrt(want), (path.name, spacing, len(pts), want)
            assert (np.abs(pts - centre) <= 1.0 + 1e-9).all()   # cropped exactly to the camera-frame cube
            world = (pts[:500] - T[:3, 3]) @ T[:3, :3]          # on the room's surfaces
            assert np.abs(trimesh.proximity.signed_distance(room, world)).max() < 1e-6


def test_big_scan_runs_like_its_cropped_room(scans, tmp_path):
    """The whole pipeline on the 100 m scan and on its room: both run, see as many points in the cube (area over
    spacing^2 at the default spacing) and regress the same pelvis, the camera's place passes the check on both;
    the big scan's body lies on the room's chair."""
    from volsmpl.apps.egohmr.user_scene import DEFAULT_SPACING

    room, room_file, big_file = scans
    T = np.asarray(json.loads((EXAMPLE / "frame.json").read_text())["world_to_camera"])
    res = {}
    for name, path in (("room", room_file), ("big", big_file)):
        out = tmp_path / name
        assert main(["egohmr", "sample", "--frame", str(EXAMPLE / "frame.json"), "--scene", str(path), "--units",
                     "mm", "--up", "z", "--model", "none", "--render", "0", "--out", str(out)]) == 0
        res[name] = json.loads((out / "results.json").read_text())
        assert res[name]["cases"]["none"][0]["body"] is not None and (out / "meshes").is_dir()
    assert np.allclose(res["room"]["pelvis"], res["big"]["pelvis"])
    # the camera is judged against the room around it: the big floor (99.5 % of the scan) does not flatten its box
    assert res["room"]["warnings"] == [] and not any("world_to_camera" in w for w in res["big"]["warnings"])
    want = area_in_cube(room, T, np.asarray(res["big"]["pelvis"]), 2.0) / DEFAULT_SPACING ** 2
    for name in res:
        n = res[name]["config"]["cube_points"]
        assert abs(n - want) < 0.03 * want + 3 * np.sqrt(want), (name, n, want)
    pelvis = np.asarray(res["big"]["cases"]["none"][0]["body"]["pelvis"])       # mm, z up
    assert np.linalg.norm(pelvis[:2] - [400.0, 600.0]) < 250 and 416 < pelvis[2] < 800
