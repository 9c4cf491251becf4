"""The motion app (volsmpl.apps.motion: objective, scenes, synthesis, CLI) against exact references: finite
differences of the goal term, the exact mesh penetration of points in a wall, collision_loss on the full cloud."""
from __future__ import annotations

import json

import numpy as np
import pytest
import torch

import volsmpl
from volsmpl.apps.motion import objective as O
from volsmpl.apps.table import case_records
from volsmpl.apps.motion import scenes as S
from volsmpl.apps.motion import walk as W
from volsmpl.geometry.point_mesh_distance import mesh_signed_distance


@pytest.fixture(scope="module")
def walk_model(body):
    return W.WalkModel(body)


@pytest.fixture(scope="module")
def short_walk(walk_model):
    """A straight walk of 10 frames from the origin facing +Z."""
    return walk_model(*W.straight_controls(1, 1, speed=1.3), frames=10)


def _wall(x: float, step: float = 0.02):
    """A vertical plane of points x = const, y in [0.2, 1.6], z in [-0.6, 1.0] (a wall)."""
    y, z = np.meshgrid(np.arange(0.2, 1.6, step), np.arange(-0.6, 1.0, step))
    return np.stack([np.full(y.size, x), y.ravel(), z.ravel()], 1).astype(np.float32)


# ------------------------------------------------------------------------------------------------ goal term
def test_goal_loss_values_and_gradient():
    p = torch.tensor([[0.5, 0.9, -2.0]], dtype=torch.float64)
    g = torch.tensor([[0.0, 0.0]], dtype=torch.float64)
    # Huber delta 1: x 0.5 -> 0.5 * 0.25; z 2.0 -> 2.0 - 0.5; the height does not count
    assert torch.allclose(O.goal_loss(p, g), torch.tensor([0.125 + 1.5], dtype=torch.float64))
    assert torch.allclose(O.goal_distance(p, g), torch.tensor([np.hypot(0.5, 2.0)], dtype=torch.float64))
    x = (p + torch.tensor([[0.1, 0.0, 0.3]], dtype=torch.float64)).requires_grad_(True)
    O.goal_loss(x, g).sum().backward()
    eps = 1e-6
    for k in range(3):
        d = torch.zeros_like(p)
        d[0, k] = eps
        fd = (O.goal_loss(x.detach() + d, g) - O.goal_loss(x.detach() - d, g)) / (2 * eps)
        assert abs(x.grad[0, k].item() - fd.item()) < 1e-8


def test_goal_gradient_through_the_walk():
    """d goal / d speed through the walking model: autograd vs central differences (float64)."""
    m = W.WalkModel(volsmpl.create_body().double())
    h, s = W.straight_controls(1, 2, speed=1.2, dtype=torch.float64)
    goal = torch.tensor([[0.3, 2.5]], dtype=torch.float64)
    s_ = s.clone().requires_grad_(True)
    O.goal_loss(m(h, s_).joints[:, -1, 0], goal).sum().backward()
    d = torch.tensor([[1.0, -0.5]], dtype=torch.float64)
    eps = 1e-6
    f = lambda v: O.goal_loss(m(h, v).joints[:, -1, 0], goal).item()  # noqa: E731
    fd = (f(s + eps * d) - f(s - eps * d)) / (2 * eps)
    assert abs((s_.grad * d).sum().item() - fd) < 1e-6 + 1e-5 * abs(fd)
    assert s_.grad.abs().sum() > 0


# ------------------------------------------------------------------------------------------------ collision term
def test_collision_zero_in_free_space(body, short_walk):
    vol = volsmpl.attach_volume(body, model="mesh")
    term = O.SceneCollision(vol, _wall(1.5))
    v = short_walk.vertices.detach().clone().requires_grad_(True)
    walk = W.Walk(**{**short_walk.__dict__, "vertices": v})
    loss = term(walk)
    assert loss.item() == 0.0 and term.last_stats["active_rows"] == 0
    loss.sum().backward() if loss.requires_grad else None
    assert v.grad is None or v.grad.abs().max() == 0


@pytest.mark.parametrize("kind", ["mesh", "volsmpl", "coap"])
def test_collision_in_a_wall_matches_the_full_cloud(body, short_walk, kind):
    """A wall through the body's left side: SceneCollision (culled, grouped) equals collision_loss on the full
    cloud, value and gradient; it is positive, and for the exact mesh it equals the penetration of the points
    inside the mesh, and moving the body out of the wall lowers it."""
    vol = volsmpl.attach_volume(body, model=kind)
    x_wall = float(short_walk.joints[0, :, 0, 0].mean()) + 0.12      # 12 cm to the side of the pelvis
    pts = np.concatenate([_wall(x_wall), _wall(2.0)])
    rows = torch.tensor([0, 4, 9])
    base = O.walk_output(short_walk, rows)
    outs = []
    for culled in (True, False):
        v = base.vertices.detach().clone().requires_grad_(True)
        out = type(base)(vertices=v, joints=base.joints.detach(), full_pose=base.full_pose.detach())
        val = (O.SceneCollision(vol, pts).per_frame(out) if culled else
               vol.collision_loss(out, torch.as_tensor(pts), reduction="sum"))
        val.sum().backward()
        outs.append((val.detach(), v.grad.clone()))
    (a, ga), (b, gb) = outs
    assert (a > 0).all()
    assert torch.allclose(a, b, rtol=1e-4, atol=1e-6)
    assert torch.allclose(ga, gb, rtol=1e-3, atol=1e-5)
    if kind == "mesh":
        P = torch.as_tensor(pts, dtype=torch.float64)
        for i in range(len(rows)):
            sd = mesh_signed_distance(base.vertices[i].detach().double(), torch.as_tensor(body.faces).long(), P)
            assert abs(torch.relu(-sd).sum().item() - a[i].item()) < 1e-4
    # gradient: the wall is at +x of the body, so the loss pushes the vertices towards -x
    assert ga[..., 0].sum() > 0
    moved = type(base)(vertices=base.vertices - torch.tensor([0.1, 0.0, 0.0]), joints=base.joints - torch.tensor([0.1, 0.0, 0.0]),
                       full_pose=base.full_pose)
    assert O.SceneCollision(vol, pts).per_frame(moved).sum() < a.sum()


def test_frame_subset_and_unit_grad():
    assert O.frame_subset(80, 16).tolist()[:3] == [0, 5, 11] and len(O.frame_subset(80, 16)) == 16
    assert O.frame_subset(80, "all").tolist() == list(range(80)) and len(O.frame_subset(10, 16)) == 10
    a = torch.zeros(2, 3, requires_grad=True)
    b = torch.zeros(2, 4, requires_grad=True)
    opt = O.UnitGradAdam([{"params": [a]}, {"params": [b]}], lr=0.1)
    a.grad, b.grad = torch.tensor([[3.0, 0, 0], [0, 0, 1e-3]]), torch.tensor([[4.0, 0, 0, 0], [0, 0, 0, 0]])
    opt.step()
    assert torch.allclose(torch.cat([a.grad, b.grad], 1).norm(dim=1), torch.ones(2))
    assert O.linear_decay(100)(0) == 1.0 and abs(O.linear_decay(100)(99) - 0.01) < 1e-12


# ------------------------------------------------------------------------------------------------ scenes, errors
def _user_scene(tmp_path):
    """A 4 x 4 m floor (one quad, as a scan) with a 1 m box in the middle, z-up, centimetres."""
    import trimesh
    floor = trimesh.Trimesh([[-200, -200, 0], [200, -200, 0], [200, 200, 0], [-200, 200, 0]], [[0, 1, 2], [0, 2, 3]])
    box = trimesh.creation.box(bounds=[[-50, -50, 0], [50, 50, 100]])
    path = tmp_path / "room.ply"
    trimesh.util.concatenate([floor, box]).export(path)
    return path


def test_user_scene_and_bad_inputs(tmp_path):
    path = _user_scene(tmp_path)
    sc = S.load_scene(path, up="z", units="cm")
    assert sc.points.shape == (S.N_POINTS, 3) and abs(sc.points[:, 1].min()) < 1e-4
    assert sc.points[:, 1].max() == pytest.approx(1.0, abs=0.01) and sc.floor.any()
    ok = S.check_endpoint(sc, S.floor_xz((-150, 0), "z", "cm"), "--start")
    assert np.allclose(ok, [-1.5, 0.0])
    with pytest.raises(ValueError, match="inside an obstacle"):
        S.check_endpoint(sc, S.floor_xz((0, 0), "z", "cm"), "--goal")
    with pytest.raises(ValueError, match="off the floor"):
        S.check_endpoint(sc, [9.0, 9.0], "--goal")
    empty = tmp_path / "empty.npy"
    np.save(empty, np.zeros((0, 3)))
    with pytest.raises(ValueError, match="empty"):
        S.load_scene(empty)
    bad = tmp_path / "nan.npy"
    np.save(bad, np.array([[0.0, 0, 0], [np.nan, 1, 1]]))
    with pytest.raises(ValueError, match="NaN or Inf"):
        S.load_scene(bad)
    with pytest.raises(ValueError, match="empty"):
        O.SceneCollision(volsmpl.attach_volume(volsmpl.create_body(), model="mesh"), np.zeros((0, 3)))


def test_a_scene_in_the_wrong_units_is_refused_by_its_walk(tmp_path):
    """A 4 x 4 m room scanned in millimetres and read as centimetres is a 40 m room with a 10 m box; --start/--goal
    are read in the same units, so every check passed and the walk ran (goal 24.4 m off, no collision: the box
    was out of reach). The pair is now refused: 30 m apart, 80 frames cover at most 2.2 m/s * 79 / 30 s."""
    import trimesh
    floor = trimesh.Trimesh([[-2000, -2000, 0], [2000, -2000, 0], [2000, 2000, 0], [-2000, 2000, 0]], [[0, 1, 2], [0, 2, 3]])
    box = trimesh.creation.box(bounds=[[-500, -500, 0], [500, 500, 1000]])
    trimesh.util.concatenate([floor, box]).export(tmp_path / "room_mm.ply")
    for units, (s, g) in (("mm", ([-1.5, 0.0], [1.5, 0.0])), ("cm", ([-15.0, 0.0], [15.0, 0.0]))):
        sc = S.load_scene(tmp_path / "room_mm.ply", up="z", units=units)
        ss, gg = S.floor_xz((-1500, 0), "z", units), S.floor_xz((1500, 0), "z", units)
        assert np.allclose(S.check_endpoint(sc, ss, "--start"), s) and np.allclose(S.check_endpoint(sc, gg, "--goal"), g)
        if units == "mm":
            S.check_pair(sc, ss, gg, 80, units)
            continue
        with pytest.raises(ValueError, match=r"30\.00 m apart .*--units cm.* 40\.0 x 40\.0 m and 10\.0 m tall\); 80 "
                                             r"frames walk at most 5\.79 m: check --units, or give --frames 411 or more"):
            S.check_pair(sc, ss, gg, 80, units)
    sc = S.load_scene(tmp_path / "room_mm.ply", up="z", units="mm")
    with pytest.raises(ValueError, match=r"0\.015 m apart .*nothing to walk; check --units"):
        S.check_pair(sc, S.floor_xz((-1.5, 0), "z", "cm"), S.floor_xz((0, 0), "z", "cm"), 80, "mm")

def test_scene_files_with_several_arrays_or_geometries_are_read_exactly_or_refused(tmp_path):
    """The scene reader (volsmpl.scene.scan.read_scan, behind --scene) never guesses: an .npz without a 'points'
    array took its first array (here the colours, 0..255 'metres'); a glb holding a mesh and a point cloud lost the
    cloud; a glb of point clouds only was called empty. Node transforms apply."""
    import trimesh
    from volsmpl.scene.scan import read_scan
    rng = np.random.default_rng(0)
    xyz, rgb = rng.random((50, 3)), rng.integers(0, 255, (50, 3)).astype(float)
    np.savez(tmp_path / "two.npz", colors=rgb, xyz=xyz)
    with pytest.raises(ValueError, match="none is named 'points'"):
        read_scan(tmp_path / "two.npz")
    np.savez(tmp_path / "named.npz", colors=rgb, points=xyz)
    assert np.array_equal(read_scan(tmp_path / "named.npz", units="cm"), xyz * 0.01)
    np.savez(tmp_path / "one.npz", xyz)
    assert np.array_equal(read_scan(tmp_path / "one.npz"), xyz)
    a, b = rng.random((30, 3)), rng.random((20, 3))
    T = np.eye(4)
    T[:3, 3] = [5.0, 0.0, -2.0]
    clouds = trimesh.Scene()
    clouds.add_geometry(trimesh.PointCloud(a), node_name="a")
    clouds.add_geometry(trimesh.PointCloud(b), node_name="b", transform=T)
    clouds.export(tmp_path / "clouds.glb")
    got = read_scan(tmp_path / "clouds.glb")
    want = np.concatenate([a, b + T[:3, 3]])
    assert got.shape == want.shape
    assert np.allclose(got[np.lexsort(got.T)], want[np.lexsort(want.T)], atol=1e-6)  # glb stores float32
    mixed = trimesh.Scene([trimesh.creation.box(), trimesh.PointCloud(a + 5.0)])
    mixed.export(tmp_path / "mixed.glb")
    with pytest.raises(ValueError, match=r"1 mesh\(es\) and 1 point cloud"):
        S.load_scene(tmp_path / "mixed.glb")

@pytest.mark.parametrize("kind", ["coap", "volsmpl"])
def test_published_collision_term_equals_the_culled_one(body, short_walk, kind):
    """COAP as published (every part at every point, synth.published_penetration, for the --published-cost
    column) computes the same term as the culled collision_loss: values and vertex gradients."""
    from volsmpl.apps.motion.synth import published_penetration
    x_wall = float(short_walk.joints[0, :, 0, 0].mean()) + 0.12
    pts = torch.as_tensor(np.concatenate([_wall(x_wall, 0.04), _wall(2.0, 0.08)]))
    base = O.walk_output(short_walk, torch.tensor([0, 9]))
    res = []
    for vol, fn in ((volsmpl.attach_volume(body, model=kind, dense=True), published_penetration),
                    (volsmpl.attach_volume(body, model=kind), lambda v, o, p: v.collision_loss(o, p, reduction="sum"))):
        v = base.vertices.detach().clone().requires_grad_(True)
        out = type(base)(vertices=v, joints=base.joints.detach(), full_pose=base.full_pose.detach())
        val = fn(vol, out, pts)
        val.sum().backward()
        res.append((val.detach(), v.grad))
    (a, ga), (b, gb) = res
    assert (a > 0).all() and torch.allclose(a, b, rtol=1e-4, atol=1e-6)
    assert torch.allclose(ga, gb, rtol=1e-3, atol=1e-5)


def test_cli_errors_are_one_line(tmp_path, capsys):
    from volsmpl.cli import main
    import trimesh
    path = _user_scene(tmp_path)
    out = str(tmp_path / "o")
    (tmp_path / "header.csv").write_text("x,y,z\n0,0,0\n1,0,1\n")
    trimesh.Trimesh([[0, 0, 0], [1, 0, 0], [2, 0, 0]], [[0, 1, 2]], process=False).export(tmp_path / "flat.ply")
    pair = ["--start", "0,0", "--goal", "1,1"]   # checked first: --scene needs them
    cases = [(["--frames", "1"], "--frames 1: give a whole number >= 4"),
             (["--scene", str(tmp_path / "header.csv")], "--scene needs --start and --goal"),
             (["--scene", str(tmp_path / "header.csv")] + pair, "header.csv: cannot read it as rows of numbers x y z"),
             (["--scene", str(tmp_path / "flat.ply")] + pair, "flat.ply: every triangle of the mesh has zero area"),
             (["--scene", str(path), "--up", "z", "--units", "cm", "--start", "0,0", "--goal", "150,0"], "inside an obstacle"),
             (["--scene", str(path), "--up", "z", "--units", "cm", "--start=-150,0", "--goal=300,0"], "off the floor"),
             (["--scene", str(path), "--up", "z", "--units", "m", "--start=-150,0", "--goal=150,0"],
              "--start and --goal are 300.00 m apart (in metres after --units m"),
             (["--w", "mesh=x"], "weights must be numbers"),
             (["--published-cost"], "add coap to --model"),
             (["--batch", "0"], "--batch 0: give a finite number >= 1"),
             (["--checkpoint-coap", "x"], "--model mesh does not run coap"),
             (["--encoder-bf16"], "runs none: add volsmpl or coap")]
    for extra, msg in cases:
        assert main(["motion", "--model", "mesh", "--out", out] + extra) == 2
        *warned, err = capsys.readouterr().err.strip().splitlines()   # warnings (the 1 m tall scene), then the error
        assert msg in err and err.startswith("volsmpl motion: error: ")
        assert all(w.startswith("volsmpl motion: warning: ") for w in warned)


@pytest.mark.parametrize("kind", ["volsmpl", "mesh"])
def test_pairs_optimised_together_end_where_each_ends_alone(body, walk_model, kind):
    """synthesize_batch (the CLI's --batch) on two pairs of a room: each walk equals its own synthesize run."""
    from volsmpl.apps.motion.synth import SynthConfig, synthesize, synthesize_batch
    sc = S.room_scenes(1, 2, 10)[0]
    vol = volsmpl.attach_volume(body, model=kind)
    cfg = SynthConfig(frames=10, iters=4)
    both = synthesize_batch(walk_model, vol, sc, sc.pairs[:2], 1.0, cfg)
    for (s, g), r in zip(sc.pairs[:2], both):
        alone = synthesize(walk_model, vol, sc, s, g, 1.0, cfg)
        assert torch.allclose(r["walk"].joints, alone["walk"].joints, atol=1e-4)
        assert r["metrics"]["goal_dist_m"] == pytest.approx(alone["metrics"]["goal_dist_m"], abs=1e-4)
        assert r["metrics"]["collision_cm"] == pytest.approx(alone["metrics"]["collision_cm"], abs=1e-3)
        assert r["metrics"]["batch"] == 2 and alone["metrics"]["batch"] == 1
        assert r["records"][0] != r["records"][-1]  # the walk was optimised
    assert not torch.allclose(both[0]["walk"].joints, both[1]["walk"].joints)  # two different walks


# ------------------------------------------------------------------------------------------------ end to end
@pytest.mark.slow
def test_end_to_end_every_model(tmp_path):
    from volsmpl.cli import main
    out = tmp_path / "motion"
    rc = main(["motion", "--model", "volsmpl,coap,mesh", "--w", "coap=0.1", "--scenes", "1", "--sequences", "1",
               "--frames", "10", "--iters", "2", "--cost-frames", "1", "--cost-repeats", "1", "--render", "1",
               "--published-cost", "--out", str(out)])
    assert rc == 0
    d = json.loads((out / "results.json").read_text())
    pub = d["summary"]["coap_published"]   # cost only; COAP as published does more work than our culled COAP
    assert pub["n_sequences"] == 0 and pub["ms_per_frame_fwd"] > 0 and pub["mem_per_frame_mb"] > 0
    assert pub["mem_per_frame_fwdbwd_mb"] > d["summary"]["coap"]["mem_per_frame_fwdbwd_mb"]
    for key in ("volsmpl", "coap", "mesh", "coap_w0.1", "volsmpl_w1.0"):
        s = d["summary"][key]
        for k in ("mem_per_frame_mb", "ms_per_frame_fwd", "ms_per_frame_fwdbwd", "total_mem_mb", "max_frames_in_budget",
                  "collision_cm", "collision_frames_pct", "goal_dist_m", "foot_skate_cm", "n_sequences",
                  "frame_mem_gb", "frame_ms", "total_mem_gb"):
            assert s[k] is not None, (key, k)
        assert s["n_sequences"] == 1 and np.isfinite(s["goal_dist_m"])
    assert d["paper"]["volsmpl"]["frame_ms"] == 3.78 and "coap_w0.01" in d["paper"]
    assert len(case_records(d["cases"])) == 3 and "meta" in d
    assert (out / f"topdown_{d['config']['scenes'][0]}.png").exists()
    assert len(list(out.glob("strip_*.png"))) == 3
    # a second run with --resume reuses the three sequences (same code, weights, settings, inputs) ...
    cases = {p.name: p.read_text() for p in (out / "cases").glob("*.json")}
    assert len(cases) == 3
    rc = main(["motion", "--model", "volsmpl,coap,mesh", "--w", "coap=0.1", "--scenes", "1", "--sequences", "1",
               "--frames", "10", "--iters", "2", "--cost-frames", "1", "--cost-repeats", "1", "--render", "1",
               "--out", str(out), "--resume"])
    assert rc == 0 and {p.name: p.read_text() for p in (out / "cases").glob("*.json")} == cases
    again = json.loads((out / "results.json").read_text())
    assert [c["metrics"]["goal_dist_m"] for c in case_records(again["cases"])] == [c["metrics"]["goal_dist_m"] for c in case_records(d["cases"])]
    # ... and recomputes one whose settings differ (3 iterations: a new key, the record is replaced)
    rc = main(["motion", "--model", "volsmpl", "--scenes", "1", "--sequences", "1", "--frames", "10", "--iters", "3",
               "--cost-frames", "1", "--cost-repeats", "1", "--render", "0", "--out", str(out), "--resume"])
    name = f"{d['config']['scenes'][0]}_0_volsmpl.json"
    assert rc == 0 and (out / "cases" / name).read_text() != cases[name]


@pytest.mark.slow
def test_tuned_protocol_runs_the_sweep_on_tuning_rooms_only(tmp_path, capsys):
    from volsmpl.cli import main
    out = tmp_path / "motion"
    rc = main(["motion", "tune", "--model", "volsmpl,coap", "--w", "coap=0.1,1", "--scenes", "3", "--sequences", "1",
               "--frames", "10", "--iters", "2", "--cost-frames", "1", "--cost-repeats", "1", "--render", "0",
               "--out", str(out)])
    assert rc == 0
    d = json.loads((out / "results.json").read_text())
    tune, test = d["tuning"]["tune_scenes"], d["tuning"]["test_scenes"]
    assert len(tune) == 1 and len(test) == 2 and d["config"]["protocol"] == "tuned"
    by_room = {r: sorted((c["model"], c["w"]) for c in case_records(d["cases"]) if c["scene"] == r) for r in tune + test}
    chosen = d["tuning"]["choice"]["coap"]
    assert by_room[tune[0]] == [("coap", 0.1), ("coap", 1.0), ("volsmpl", 1.0)]
    assert by_room[test[0]] == by_room[test[1]] == sorted([("coap", chosen), ("volsmpl", 1.0)])
    assert d["summary"]["coap"]["w"] == chosen and d["summary"]["coap"]["n_sequences"] == 2
    assert d["summary"]["coap_w0.1"]["split"] == "tune"
    # the compared rows' paired differences: the test rooms' two sequences, COAP at its chosen weight
    (pair,) = d["paired"]["pairs"]
    coll = {(c["model"], c["scene"]): c["metrics"]["collision_cm"] for c in case_records(d["cases"]) if c["scene"] in test
            and c["w"] in (1.0 if c["model"] == "volsmpl" else chosen,)}
    assert pair["n"] == 2 and pair["b"] == f"coap (w {chosen:g})"
    assert pair["metrics"]["collision_cm"]["mean_diff"] == pytest.approx(
        np.mean([coll[("volsmpl", r)] - coll[("coap", r)] for r in test]))
    assert main(["motion", "tune", "--model", "volsmpl", "--scenes", "1", "--out", str(out)]) == 2
    assert "--scenes 2 or more" in capsys.readouterr().err


@pytest.mark.slow
def test_resume_recomputes_a_sequence_made_with_another_body(tmp_path, monkeypatch):
    """The body (the walking model's and the exact 'mesh' kind's) was not in a sequence's key: a mesh-kind record
    walked with another body was served by --resume. Now the body's fingerprint is part of the key."""
    import volsmpl
    from volsmpl.cli import main
    out = tmp_path / "motion"
    argv = ["motion", "--model", "mesh", "--scenes", "1", "--sequences", "1", "--frames", "10", "--iters", "1",
            "--cost-frames", "1", "--cost-repeats", "1", "--render", "0", "--out", str(out), "--resume"]
    assert main(argv) == 0
    (case,) = (out / "cases").glob("*.json")
    first = case.read_text()
    create = volsmpl.create_body

    def taller_body(*a, **kw):  # another body: 5 % taller, its own fingerprint
        body = create(*a, **kw)
        with torch.no_grad():
            body.v_template.mul_(1.05)
        body.fingerprint = "another-body"
        return body

    monkeypatch.setattr(volsmpl, "create_body", taller_body)
    assert main(argv) == 0
    assert case.read_text() != first  # recomputed, not reused


def test_encoder_bf16_reaches_both_learned_encoders_and_the_record_keys(tmp_path, encoder_bf16_calls):
    """--encoder-bf16: the PointNet of every learned kind runs under bfloat16 autocast (seen at its calls), the run
    says so in its config, and a sequence stored from a float32 run is recomputed under it, not reused."""
    from volsmpl.cli import main
    seen = encoder_bf16_calls
    out = tmp_path / "motion"
    argv = ["motion", "--model", "volsmpl,coap", "--w", "coap=0.1", "--scenes", "1", "--sequences", "1", "--frames",
            "6", "--iters", "1", "--cost-frames", "1", "--cost-repeats", "1", "--render", "0", "--threads", "1",
            "--out", str(out), "--resume"]
    assert main(argv) == 0 and seen and not any(seen)
    first = {p.name: p.read_text() for p in (out / "cases").glob("*.json")}
    seen.clear()
    assert main(argv + ["--encoder-bf16"]) == 0 and seen and all(seen)
    assert json.loads((out / "results.json").read_text())["config"]["encoder_bf16"] is True
    again = {p.name: p.read_text() for p in (out / "cases").glob("*.json")}
    assert len(again) == len(first) == 2 and all(again[n] != first[n] for n in first)


@pytest.mark.slow
def test_resume_recomputes_a_sequence_made_with_another_thread_count(tmp_path):
    """The torch thread count is part of a sequence's key: a record timed (and summed) with other threads is not
    served as this run's."""
    from volsmpl.cli import main
    out = tmp_path / "motion"
    argv = ["motion", "--model", "mesh", "--scenes", "1", "--sequences", "1", "--frames", "10", "--iters", "1",
            "--cost-frames", "1", "--cost-repeats", "1", "--render", "0", "--out", str(out), "--resume"]
    threads = torch.get_num_threads()
    try:
        assert main(argv + ["--threads", str(threads)]) == 0
        (case,) = (out / "cases").glob("*.json")
        first = case.read_text()
        assert main(argv + ["--threads", str(threads)]) == 0
        assert case.read_text() == first  # same settings: reused
        assert main(argv + ["--threads", str(threads + 1)]) == 0
        assert case.read_text() != first  # recomputed, not reused
    finally:
        torch.set_num_threads(threads)


def test_warm_code_refinement_keys_the_frames_by_their_rows(body, short_walk):
    """With warm code refinement, the collision term's encodings carry each frame's refinement by the frame's row
    in the walk (frames 0, 4 and 9 of a 3-frame term), not by its position in a group of frames with the same
    parts, so a frame keeps its own correction whatever group it falls into."""
    vol = volsmpl.attach_volume(body).set_code_refinement(1, warm=True)
    x_wall = float(short_walk.joints[0, :, 0, 0].mean()) + 0.12
    term = O.SceneCollision(vol, np.concatenate([_wall(x_wall), _wall(-x_wall)]), frames=3)
    with torch.no_grad(), vol.warm_start() as warm:
        for _ in range(2):
            term(short_walk)
    rows = O.frame_subset(short_walk.body_pose.shape[1], 3).tolist()
    assert rows == [0, 4, 9] or rows == [0, 5, 9]
    assert sorted(warm.known) == rows and warm.restarted == 0
