"""A user's scene for `volsmpl motion --scene`: the file read or refused in one line, its size checked against
--units, its up axis found from the floor and checked against --up, all before any network loads; and the
options each mode does not read refused, every number checked, before any work."""
from __future__ import annotations

import re

import numpy as np
import pytest

from volsmpl.apps.motion import scene_checks as C
from volsmpl.apps.motion import scenes as S
from volsmpl.scene.floor import estimate_floor


@pytest.fixture(scope="module")
def room():
    """Generated room 0's cloud (Y up, metres, floor at y = 0, no ceiling) and one of its free start/goal pairs."""
    sc = S.room_scene(0, 1, 80)
    return sc.points.astype(np.float64), sc.pairs[0]


def _z_up(p):
    """Y-up points (x, y, z) as a z-up file writes them: (x, -z, y) (volsmpl.scene.scan.to_y_up's inverse)."""
    return np.stack([p[:, 0], -p[:, 2], p[:, 1]], 1)


def _plane(a: np.ndarray, b: np.ndarray, axes: tuple, level: float) -> np.ndarray:
    """Grid points at the cell centres a x b of a plane where axis axes[2] == level (axes[0], axes[1]: a, b)."""
    A, B = np.meshgrid(a, b, indexing="ij")
    p = np.zeros((A.size, 3))
    p[:, axes[0]], p[:, axes[1]], p[:, axes[2]] = A.ravel(), B.ravel(), level
    return p


def _box_room(lx: float, ly: float, h: float, ceiling: bool = False, step: float = 0.04) -> np.ndarray:
    """A z-up room sampled at the centres of a 4 cm grid: floor lx x ly at z = 0, four walls h tall, and a ceiling
    at z = h if asked."""
    cx, cy, cz = (np.arange(step / 2, s, step) for s in (lx, ly, h))
    parts = [_plane(cx, cy, (0, 1, 2), 0.0), _plane(cy, cz, (1, 2, 0), 0.0), _plane(cy, cz, (1, 2, 0), lx),
             _plane(cx, cz, (0, 2, 1), 0.0), _plane(cx, cz, (0, 2, 1), ly)]
    if ceiling:
        parts.append(_plane(cx, cy, (0, 1, 2), h))
    return np.concatenate(parts)


# ------------------------------------------------------------------------------------------------ the up axis
@pytest.mark.parametrize("perm, axis", [((0, 1, 2), "z"), ((0, 2, 1), "y"), ((2, 1, 0), "x")])
def test_floor_axis_of_a_hand_made_room(perm, axis):
    """A 6 x 4 m floor (150 x 100 = 15,000 points) and 2.4 m walls (60 rows: 2 x 6,000 + 2 x 9,000), 45,000 points.
    The floor's slab (within 5 cm of z = 0) holds the floor and the walls' first row (500): 15,500; the top slab
    the walls' two top rows (1,000): score (15,500 - 1,000 / 2) / 45,000 = 1/3. The long wall's slab holds 9,000 +
    the floor's edge row (150) + the short walls' end columns (2 x 60) = 9,270, as does the opposite wall's: score
    4,635 / 45,000 = 0.103. The floor is found across whichever axis it lies."""
    p = _box_room(6.0, 4.0, 2.4)[:, perm]
    assert len(p) == 45000
    est = estimate_floor(p)
    assert est.axis == axis and est.clear
    assert est.level == pytest.approx(0.0, abs=1e-9)
    assert est.share == pytest.approx(15500 / 45000) and est.scores[axis] == pytest.approx(1 / 3)
    other = "y" if axis == "z" else "z" if axis == "y" else "y"   # the long walls' axis
    assert est.scores[other] == pytest.approx(4635 / 45000)
    assert est.line() == f"floor: axis {axis}, level 0.00 m, 34% of points"


def test_floor_axis_with_a_ceiling_and_an_unclear_corridor():
    """A ceiling (15,000 points) takes half of its slab (15,500) off the floor's score: (15,500 - 7,750) / 60,000 =
    0.129 against the long wall's (9,420 - 4,710) / 60,000 = 0.0785, still clear (1.65x). A 10 x 1 m corridor
    whose long walls (15,000 points each) outsize its floor (6,250) scores its wall 0.196 and its floor 0.159:
    unclear, so never refused, and a warning when the best axis is not --up."""
    est = estimate_floor(_box_room(6.0, 4.0, 2.4, ceiling=True))
    assert est.axis == "z" and est.clear and est.scores["z"] == pytest.approx(7750 / 60000)
    corridor = _box_room(10.0, 1.0, 2.4)
    est = estimate_floor(corridor)
    assert est.axis == "y" and not est.clear
    assert est.scores["y"] == pytest.approx(15370 / 2 / 39250) and est.scores["z"] == pytest.approx(6250 / 39250)
    warnings = []
    assert C.check_scene(corridor, "corridor.ply", "z", "m", None, warnings.append)   # a doubt, no refusal
    assert any("the up axis is unclear, --up taken as given" in w for w in warnings)


def test_the_generated_room_turned_z_up(room, tmp_path):
    """The y-up room is found y-up; the same room written z-up is refused without --up z (naming the fix), read
    with it (the same cloud as the y-up file), and with --floor-y the disagreement is only a warning."""
    pts, _ = room
    assert estimate_floor(pts).axis == "y" and C.estimate_floor(_z_up(pts)).axis == "z"
    np.save(tmp_path / "room_z.npy", _z_up(pts))
    with pytest.raises(ValueError, match=r"room_z\.npy: the floor lies across axis z .* but --up is y: "
                                         r"give --up z") as e:
        S.load_scene(tmp_path / "room_z.npy")
    assert "\n" not in str(e.value)
    sc = S.load_scene(tmp_path / "room_z.npy", up="z")
    assert np.allclose(sc.points, pts, atol=1e-5) and sc.doubts == []
    warnings = []
    S.load_scene(tmp_path / "room_z.npy", up="y", floor_y=-3.0, warn=warnings.append)
    assert any("not --up y (kept: --floor-y given)" in w for w in warnings)


# ------------------------------------------------------------------------------------------------ units
def test_a_room_in_millimetres_read_as_metres_is_refused_naming_the_units(room, tmp_path):
    """Room 0 (7.5 x 7.0 m, 2.8 m tall) saved in millimetres: read as metres it spans 7,471 m (refused: give
    --units mm), as centimetres 74.7 m (read), as millimetres the room itself; saved in metres and read as
    millimetres it spans 7.5 mm (refused: give --units m)."""
    pts, _ = room
    np.save(tmp_path / "room_mm.npy", pts * 1000.0)
    np.save(tmp_path / "room_m.npy", pts)
    with pytest.raises(ValueError, match=r"spans 7,4\d\d m after --units m, more than 2,000 m: a scene in "
                                         r"millimetres\? give --units mm") as e:
        S.load_scene(tmp_path / "room_mm.npy", units="m")
    assert "\n" not in str(e.value)
    assert np.allclose(S.load_scene(tmp_path / "room_mm.npy", units="mm").points, pts, atol=1e-4)
    with pytest.raises(ValueError, match=r"spans 0.00\d+ m after --units mm, less than 0.5 m: a scene in metres\? "
                                         r"give --units m"):
        S.load_scene(tmp_path / "room_m.npy", units="mm")
    assert C.units_fix(400.0, "m") == "cm" and C.units_fix(7.5, "m") is None and C.units_fix(3e6, "m") is None


def test_unusual_sizes_are_warned_and_named_by_the_refusals_of_start_and_goal(room, tmp_path):
    """Room 0 in centimetres read as metres (747 m across: over 200 m) and a 1 m tall scene load with warnings;
    a start off the floor of the large one names the doubt."""
    pts, _ = room
    np.save(tmp_path / "room_cm.npy", pts * 100.0)
    warnings = []
    sc = S.load_scene(tmp_path / "room_cm.npy", warn=warnings.append)
    assert any("larger than a building: if it is in centimetres, give --units cm" in w for w in warnings)
    with pytest.raises(ValueError, match=r"off the floor .*the scene looked odd: it spans 747 m after --units m "
                                         r"\(in centimetres\? --units cm\)"):
        S.check_endpoint(sc, [5000.0, 0.0], "--start")
    low = pts[pts[:, 1] < 1.0]
    np.save(tmp_path / "low.npy", low)
    warnings = []
    sc = S.load_scene(tmp_path / "low.npy", warn=warnings.append)
    assert any("lower than a person" in w for w in warnings) and sc.doubts


# ------------------------------------------------------------------------------------------------ the file
def test_unreadable_scene_files_are_one_line_naming_the_file_and_the_formats(tmp_path):
    np.save(tmp_path / "pickled.npy", np.array([{"a": 1}], dtype=object), allow_pickle=True)
    (tmp_path / "empty.ply").write_bytes(b"")
    (tmp_path / "folder.ply").mkdir()
    (tmp_path / "junk.ply").write_bytes(b"\x00\x01 not a ply")
    np.save(tmp_path / "flat.npy", np.zeros((10, 2)))
    cases = [("pickled.npy", ValueError, "pickled Python objects"), ("empty.ply", ValueError, "is empty (0 bytes)"),
             ("folder.ply", ValueError, "is a folder"), ("missing.ply", FileNotFoundError, "no such file"),
             ("junk.ply", ValueError, "cannot read it"), ("flat.npy", ValueError, "must be (N, 3)")]
    for name, exc, words in cases:
        with pytest.raises(exc) as e:
            S.load_scene(tmp_path / name)
        msg = str(e.value)
        assert words in msg and str(tmp_path / name) in msg and "\n" not in msg, msg
        if name not in ("pickled.npy", "flat.npy"):
            assert "(ply, obj" in msg   # the formats read


def test_a_scene_name_with_spaces_or_accents_is_made_file_safe(room, tmp_path):
    pts, _ = room
    for stem in ("my room", "tempelü"):
        np.save(tmp_path / f"{stem}.npy", pts)
        name = S.load_scene(tmp_path / f"{stem}.npy").name
        assert name.startswith(stem.replace(" ", "_").replace("ü", "_") + "-") and name.isascii() and " " not in name


# ------------------------------------------------------------------------------------------------ the CLI
@pytest.fixture
def no_work(monkeypatch):
    """Any expensive set-up (the body and networks, the generated rooms) fails the test."""
    import volsmpl
    from volsmpl.apps.motion import scenes

    monkeypatch.setattr(volsmpl, "create_body", lambda *a, **k: pytest.fail("the body was built before the refusal"))
    monkeypatch.setattr(scenes, "room_scenes", lambda *a, **k: pytest.fail("rooms were built before the refusal"))


def test_cli_refuses_options_a_mode_does_not_read_and_bad_numbers_before_any_work(room, tmp_path, capsys, no_work):
    from volsmpl.cli import main

    pts, _ = room
    f = tmp_path / "room.npy"
    np.save(f, pts)
    scene = ["--scene", str(f), "--start", "1.64,-1.95", "--goal=-0.01,-0.2"]
    cases = [(scene + ["--seed", "3"], "--seed does not apply to `volsmpl motion --scene`"),
             (scene + ["--scenes", "4", "--sequences", "2"], "--scenes, --sequences do not apply"),
             (scene + ["--batch", "2"], "--batch does not apply to `volsmpl motion --scene`"),
             (["--up", "z"], "--up does not apply to `volsmpl motion without --scene`"),
             (["--start", "0,0", "--goal", "1,1"], "--goal, --start do not apply to `volsmpl motion without --scene`"),
             (["tune"] + scene, "do not apply to `volsmpl motion tune`"),
             (["tune", "--scenes", "1"], "--scenes 2 or more"),
             (["--scenes", "0"], "--scenes 0: give a finite number >= 1"),
             (["--scenes", "two"], "--scenes 'two' is not a number"),
             (["--scenes", "2.5"], "--scenes 2.5: give 'all' or a whole number"),
             (["--sequences", "0"], "--sequences 0: give a finite number >= 1"),
             (["--frames", "3"], "--frames 3: give a whole number >= 4 (the jerk term"),
             (["--iters", "-1"], "--iters -1: give a finite number >= 0"),
             (["--lr", "nan"], "--lr nan: give a finite number > 0"),
             (["--lr", "0"], "--lr 0: give a finite number > 0"),
             (["--mem-budget-gb", "inf"], "--mem-budget-gb inf: give a finite number > 0"),
             (["--cost-frames", "0"], "--cost-frames 0: give a finite number >= 1"),
             (["--cost-repeats", "0"], "--cost-repeats 0: give a finite number >= 1"),
             (["--batch", "0"], "--batch 0: give a finite number >= 1"),
             (["--coll-frames", "0"], "--coll-frames must be 'auto', 'all' or a number >= 1"),
             (["--w", "mesh=1,1"], "a weight is given twice"),
             (["--w", "mesh=1", "--w", "mesh=2"], "--w mesh=... is given twice"),
             (["--w", "mesh=-1"], "finite and >= 0"),
             (scene + ["--floor-y", "nan"], "--floor-y nan: give a finite number"),
             (scene + ["--spacing", "0"], "--spacing 0: give a finite number > 0"),
             (["--spacing", "0.03"], "--spacing does not apply to `volsmpl motion without --scene`"),
             (["--scene", str(tmp_path / "none.ply"), "--start", "0,0", "--goal", "1,1"], "none.ply: no such file")]
    for extra, msg in cases:
        assert main(["motion", "--model", "mesh", "--out", str(tmp_path / "o")] + extra) == 2, extra
        err = capsys.readouterr().err.strip()
        assert err.startswith("volsmpl motion: error: ") and msg in err and "\n" not in err, (extra, err)


def test_cli_refuses_a_scene_in_the_wrong_units_or_up_axis_before_the_networks(room, tmp_path, capsys, no_work):
    from volsmpl.cli import main

    pts, (s, g) = room
    np.save(tmp_path / "mm.npy", pts * 1000.0)
    np.save(tmp_path / "z.npy", _z_up(pts))
    base = ["motion", "--model", "mesh", "--out", str(tmp_path / "o")]
    assert main(base + ["--scene", str(tmp_path / "mm.npy"), f"--start={s[0] * 1000},{s[1] * 1000}",
                        f"--goal={g[0] * 1000},{g[1] * 1000}"]) == 2
    assert "give --units mm" in capsys.readouterr().err
    assert main(base + ["--scene", str(tmp_path / "z.npy"), f"--start={s[0]},{-s[1]}", f"--goal={g[0]},{-g[1]}"]) == 2
    io = capsys.readouterr()
    assert "give --up z" in io.err and "floor: axis z, level 0.00 m, 36% of points" in io.out


def test_a_floor_level_given_at_the_walls_top_is_named_and_iters_0_warned(room, tmp_path, capsys, no_work):
    """--floor-y 2.5 on a room whose floor is at 0: the start is off that floor, and the refusal names --floor-y with
    the 2.5 m between the given level and the scene's lowest points. --iters 0 (documented: the straight walks are
    measured) is warned about before the refusal."""
    from volsmpl.cli import main

    pts, (s, g) = room
    np.save(tmp_path / "room.npy", pts)
    assert main(["motion", "--model", "mesh", "--scene", str(tmp_path / "room.npy"), f"--start={s[0]},{s[1]}",
                 f"--goal={g[0]},{g[1]}", "--floor-y", "2.5", "--iters", "0", "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert "volsmpl motion: warning: --iters 0: the walks are not optimised" in err
    assert re.search(r"off the floor .*the floor level lies 2.\d\d m above the scene's lowest points: check --floor-y",
                     err)


def test_cli_refuses_an_out_holding_another_apps_results(tmp_path, capsys, no_work):
    from volsmpl.cli import main

    (tmp_path / "results.json").write_text('{"app": "hoi"}')
    assert main(["motion", "--model", "mesh", "--out", str(tmp_path)]) == 2
    assert "holds the results of `volsmpl hoi`" in capsys.readouterr().err
