"""The judge of a finished walk (volsmpl.apps.motion.status) on hand-made records, and a user's scene named
`my room.ply` run end to end: file-safe names, a status on every record, a walk that stopped on NaN flagged and
not ending the run, results.json (strict JSON) written after every finished sequence."""
from __future__ import annotations

import json

import numpy as np
import pytest

from volsmpl.apps.motion.status import judge
from volsmpl.apps.table import flag_cases


def _rec(w=1.0, **over):
    """A record that reached its goal cleanly: 4 cm from the goal, 10% colliding frames, 0.2 cm deep; terms of
    the straight start walk (total 0.01 + 1 x 0.05 + 0.002 = 0.062) and of the optimised one."""
    m = {"goal_dist_m": 0.04, "collision_cm": 0.2, "collision_obstacles_cm": 0.2, "collision_frames_pct": 10.0,
         "max_depth_cm": 3.0, "initial_terms": {"goal": 0.01, "collision": 0.05, "jerk": 0.002},
         "final_terms": {"goal": 0.001, "collision": 0.02, "jerk": 0.002}}
    for k, v in over.items():
        if k in ("initial_terms", "final_terms"):
            m[k] = {**m[k], **v}
        else:
            m[k] = v
    return {"case": "r_0_mesh", "w": w, "metrics": m}


@pytest.mark.parametrize("over, status, words", [
    ({}, "reached", ""),
    ({"goal_dist_m": 0.49}, "reached", ""),
    ({"goal_dist_m": 0.51}, "goal_missed", "ends 0.51 m from the goal (over 0.5 m)"),
    ({"collision_frames_pct": 74.0}, "reached", ""),
    ({"collision_frames_pct": 76.0}, "colliding", "collides in 76% of frames"),
    ({"collision_cm": 3.1, "collision_obstacles_cm": 3.0}, "colliding", "3.10 cm deep"),
    ({"collision_cm": 3.1, "collision_obstacles_cm": 0.1}, "colliding", "mostly with the floor: check --floor-y"),
    # through an obstacle: deeper than 8 cm while colliding in at least 40 % of the frames
    ({"max_depth_cm": 10.3, "collision_frames_pct": 50.0}, "colliding", "passes 10.3 cm deep into the scene"),
    ({"max_depth_cm": 7.9, "collision_frames_pct": 50.0}, "reached", ""),
    ({"max_depth_cm": 10.3, "collision_frames_pct": 39.0}, "reached", ""),
    # the collision term: 1.5 x 0.05 + 0.001 = 0.076 is the most an optimised walk may end with
    ({"final_terms": {"collision": 0.0755}}, "reached", ""),
    ({"final_terms": {"collision": 0.0765}}, "worse_than_start", "rose from 0.05 (straight start walk) to 0.0765"),
    ({"goal_dist_m": float("nan")}, "diverged", "not finite: goal_dist_m"),
    ({"final_terms": {"jerk": float("inf")}}, "diverged", "final jerk term"),
    # the loss: 10 x 0.062 + 1 = 1.62 is the most; the goal term alone 1.7 is over it (the goal distance kept small)
    ({"final_terms": {"goal": 1.5}}, "reached", ""),
    ({"final_terms": {"goal": 1.7}}, "diverged", "the loss rose from 0.062"),
    ({"error": "the optimisation stopped: variable 'speed_u' became NaN or Inf"}, "diverged", "became NaN"),
    ({"stop": "diverged"}, "diverged", "a step made the walk's numbers or loss non-finite"),
])
def test_status_of_hand_made_records(over, status, words):
    got, why = judge(_rec(**over))
    assert got == status and words in why


def test_the_collision_weight_counts_in_the_loss_and_the_first_status_wins():
    """At w = 10 the start walk's loss is 0.01 + 10 x 0.05 + 0.002 = 0.512 (limit 6.12): a final goal term of 1.7
    is no divergence there. A walk that both missed the goal and collides is goal_missed (the first)."""
    assert judge(_rec(w=10.0, final_terms={"goal": 1.7}))[0] == "reached"
    assert judge(_rec(goal_dist_m=0.8, collision_frames_pct=90.0))[0] == "goal_missed"
    cases = {"mesh": [_rec(), dict(_rec(goal_dist_m=0.8), case="r_1_mesh")]}
    for recs in cases.values():
        for r in recs:
            r["status"], r["status_why"] = judge(r)
    assert flag_cases(cases, "case", {"reached"}) == [
        {"case": "r_1_mesh", "model": "mesh", "status": "goal_missed", "why": "ends 0.80 m from the goal (over 0.5 m)"}]


def _scene_file(path):
    """A 4 x 4 m floor with a 1 m cube in the middle, y up, metres, as a point cloud on a 4 cm grid (no sampling)."""
    import trimesh
    g = np.arange(-2.0, 2.0001, 0.04)
    X, Z = np.meshgrid(g, g)
    floor = np.stack([X.ravel(), np.zeros(X.size), Z.ravel()], 1)
    s = np.arange(-0.5, 0.5001, 0.04)
    A, B = np.meshgrid(s, s)
    sides = []
    for fix, val in ((0, -0.5), (0, 0.5), (2, -0.5), (2, 0.5)):
        p = np.zeros((A.size, 3))
        p[:, fix], p[:, 2 - fix], p[:, 1] = val, A.ravel(), B.ravel() + 0.5
        sides.append(p)
    top = np.stack([A.ravel(), np.ones(A.size), B.ravel()], 1)
    trimesh.PointCloud(np.concatenate([floor, top] + sides)).export(path)


def test_my_room_runs_end_to_end_and_a_diverged_walk_is_flagged(tmp_path, monkeypatch, capsys):
    """`my room.ply` (a space in the name) with two collision weights: the w = 1 walk stops on NaN (the
    optimiser's RuntimeError, forced here) and becomes a record without a walk, status diverged, flagged, the run
    going on; results.json is strict JSON after the first sequence already, and names every file file-safely."""
    from volsmpl.apps.motion import synth
    from volsmpl.cli import main

    _scene_file(tmp_path / "my room.ply")
    out = tmp_path / "out"
    real = synth.synthesize_batch
    seen = []

    def walk(model, volume, scene, pairs, w=1.0, cfg=None, progress=False):
        seen.append(w)
        if w == 1.0:
            part = json.loads((out / "results.json").read_text())   # written after the first sequence
            assert part["progress"] == {"sequences": 1, "planned": 2} and len(part["cases"]["mesh"]) == 1
            raise RuntimeError("variable 'speed_u' became NaN or Inf at iteration 1; lower the learning rate")
        return real(model, volume, scene, pairs, w, cfg, progress)

    monkeypatch.setattr(synth, "synthesize_batch", walk)
    rc = main(["motion", "--model", "mesh", "--w", "mesh=0.5,1", "--scene", str(tmp_path / "my room.ply"),
               "--start=-1.5,-0.3", "--goal=-1.5,0.3", "--frames", "10", "--iters", "2", "--cost-frames", "1",
               "--cost-repeats", "1", "--render", "1", "--threads", "1", "--out", str(out)])
    io = capsys.readouterr()
    assert rc == 0, io.err
    assert seen == [0.5, 1.0] and "floor: axis y, level 0.00 m" in io.out
    text = (out / "results.json").read_text()
    d = json.loads(text, parse_constant=lambda c: pytest.fail(f"results.json holds {c}"))
    name = d["config"]["scenes"][0]
    assert name.startswith("my_room-") and " " not in name
    ok, bad = d["cases"]["mesh"]
    assert ok["case"] == f"{name}_0_mesh_w0.5" and ok["status"] == "reached" and ok["status_why"] == ""
    assert bad["status"] == "diverged" and "became NaN or Inf" in bad["status_why"]
    assert bad["metrics"]["goal_dist_m"] is None and ok["metrics"]["goal_dist_m"] < 0.5
    assert d["flagged"] == [{"case": f"{name}_0_mesh_w1.0", "model": "mesh", "status": "diverged",
                             "why": bad["status_why"]}]
    assert any("lower than a person" in w for w in d["warnings"])   # the 1 m cube is the scene's height
    assert d["progress"] == {"sequences": 2, "planned": 2}
    assert f"flagged: {name}_0_mesh_w1.0 mesh: diverged" in io.out
    assert (out / f"topdown_{name}.png").exists() and (out / f"strip_{name}_0_mesh_w0.5.png").exists()
    assert sorted(p.name for p in (out / "cases").glob("*.json")) == [f"{name}_0_mesh_w0.5.json",
                                                                     f"{name}_0_mesh_w1.0.json"]
