"""volsmpl report: tables beside the paper's, provenance, staleness from git, missing results, CLI errors."""
from __future__ import annotations

import json
from pathlib import Path

import pytest

from conftest import NoGit, git_run, producer_repo, write_result
from volsmpl.report import build as report
from volsmpl.cli import main





HOI = {"summary": {"volsmpl": {"iter_ms": 12.5, "total_min": 0.2, "collision_pct": 4.1, "contact_cm": 3.3,
                               "steps": 1000},
                   "mesh": {"iter_ms": 900.0, "total_min": 15.0, "collision_pct": 6.0, "contact_cm": 3.1}},
       "paper": {"volsmpl": {"iter_ms": 4.28}}, "cases": [{"name": "a"}, {"name": "b"}], "figures": ["fig.png"],
       "meta": {"git_commit": "abc1234", "date": "2026-11-20T10:00:00+00:00", "device": "cuda: H100"},
       "checkpoints": {"volsmpl": "shipped"}}


def test_app_table_beside_the_paper_and_missing_ones_listed(tmp_path):
    write_result(tmp_path / "out" / "hoi" / "results.json", HOI)
    (tmp_path / "out" / "hoi" / "fig.png").write_bytes(b"png")
    write_result(tmp_path / "docs" / "eval_coap_anny.json", {"metrics": {"iou_mean": 0.5, "iou_surf": 0.4, "iou_unif": 0.6},
                                                     "config": {"device": "cpu"}})
    text, status = report.build_report(tmp_path / "docs" / "report.md", root=tmp_path, git=NoGit())
    hoi = text[text.index("## Human-object"):]
    assert "| ours: volsmpl | 12.50 | 0.200 | 4.10 | 3.30 | 1,000 |" in hoi  # ours, with the extra metric
    assert "| paper: w. Ours | 4.28 | 0.57 | 5.73 | 3.96 |" in hoi               # the paper's row beside
    assert "| paper: w. SDF [Wang et al.] | 2128.2 | 35.9 | 6.33 | 3.2 |" in hoi
    assert "2 per-case records" in hoi and "![fig](../out/hoi/fig.png)" in hoi
    assert "abc1234" in hoi and "2026-11-20T10:00:00+00:00" in hoi and "cuda: H100" in hoi and "volsmpl: shipped" in hoi
    assert "git unavailable (no git in this test)" in hoi
    # eval: COAP's row from a synthetic JSON with the paper's rows; fields the JSON lacks say so
    ev = text[text.index("## Volumetric bodies: accuracy"):text.index("## Volumetric bodies: time")]
    assert "| ours: COAP | 50.00 | 40.00 | 60.00 |" in ev and "| paper: COAP | 94.31 | 93.98 | 94.63 |" in ev
    assert "| `eval_coap` |" in ev and "not recorded" in ev
    # what is missing, with the commands
    missing = text[text.index("## Results still missing"):text.index('<a id="eval">')]
    for cmd in ("volsmpl egohmr sample --split test --tuned docs/egohmr/tune.json --out out/egohmr",
                "volsmpl motion tune --model volsmpl,coap,mesh --scenes all --published-cost --out out/motion",
                "volsmpl eval --out docs/eval_volsmpl_anny.json", "volsmpl bench --threads 1 --models volsmpl,"):
        assert f"`{cmd}" in missing
    assert "`hoi`" not in missing and "hoi" not in status["missing"]
    assert {"egohmr", "motion", "eval_volsmpl", "bench", "selfpen"} <= set(status["missing"])
    assert "No results yet: run `volsmpl egohmr sample --split test --tuned docs/egohmr/tune.json --out out/egohmr`." in text
    assert sorted(status["unknown"]) == ["eval_coap", "hoi"]


def test_motion_back_ends_split_over_tables_5_and_d1(tmp_path):
    res = write_result(tmp_path / "m.json", {"summary": {"volsmpl": {"frame_ms": 9.0}, "coap_w0.01": {"frame_ms": 70.0}}})
    text, _ = report.build_report(tmp_path / "r.md", root=tmp_path, overrides={"motion": res}, git=NoGit())
    t5 = text[text.index("Paper Table 5"):text.index("Paper Table D.1")]
    d1 = text[text.index("Paper Table D.1"):]
    assert "ours: volsmpl" in t5 and "ours: coap_w0.01" not in t5 and "71*" in t5 and "16 frames only" in t5
    assert "| ours: coap_w0.01 | - | 70.00 | - | - |" in d1
    assert "| paper: w. COAP (w=0.01) | 4.44 | 26.48 | 4.92 | 0.02 |" in d1


PAIRED = {"confidence": 0.95, "method": "BCa bootstrap of the mean difference", "diff": "a - b",
          "pairs": [{"a": "volsmpl", "b": "coap (w 0.01)", "n": 80,
                     "metrics": {"collision_cm": {"mean_a": 0.18, "mean_b": 0.31, "mean_diff": -0.13,
                                                  "ci": [-0.18, -0.08], "a_lower": 0.81, "equal": 0.09,
                                                  "a_higher": 0.1}}}]}


def test_motion_paired_differences_from_their_file_or_the_result(tmp_path):
    res = write_result(tmp_path / "m.json", {"summary": {"volsmpl": {"frame_ms": 9.0}}})
    pair = write_result(tmp_path / "p.json", PAIRED)
    row = "| volsmpl - coap (w 0.01) | collision_cm | 0.180 | 0.310 | -0.13 [-0.18, -0.08] | 81% / 10% | 80 |"
    text, _ = report.build_report(tmp_path / "r.md", root=tmp_path, overrides={"motion": res, "motion_paired": pair},
                                  git=NoGit())
    assert row in text and "95% interval" in text
    res = write_result(tmp_path / "m2.json", {"summary": {"volsmpl": {"frame_ms": 9.0}}, "paired": PAIRED})
    text, status = report.build_report(tmp_path / "r.md", root=tmp_path, overrides={"motion": res}, git=NoGit())
    assert row in text and "motion_paired" in status["missing"]
    res = write_result(tmp_path / "m3.json", {"summary": {"volsmpl": {"frame_ms": 9.0}}})
    text, _ = report.build_report(tmp_path / "r.md", root=tmp_path, overrides={"motion": res}, git=NoGit())
    assert "Paired over the same cases" not in text


def test_paper_mismatch_is_noted(tmp_path):
    res = write_result(tmp_path / "s.json", {"summary": {"volsmpl": {"step_ms": 1.0}},
                                      "paper": {"volsmpl": {"step_ms": 15.0}}})
    text, _ = report.build_report(tmp_path / "r.md", root=tmp_path, overrides={"selfpen": res}, git=NoGit())
    assert "volsmpl.step_ms: 15.0 (paper: 14)" in text




@pytest.fixture
def repo(tmp_path):
    results = json.dumps({"summary": {"volsmpl": {"iter_ms": 1.0}}})  # no commit recorded
    first, second = producer_repo(tmp_path, {"docs/hoi/results.json": results})
    return tmp_path, first, second


def _verdict(root: Path, data: dict | None = None) -> tuple[str, str]:
    over = {"hoi": write_result(root / "x" / "r.json", data)} if data is not None else {}
    text, status = report.build_report(root / "r.md", root=root, overrides=over)
    line = next(ln for ln in text.splitlines() if ln.startswith("| `hoi` |"))
    return ("stale" if "hoi" in status["stale"] else "unknown" if "hoi" in status["unknown"] else "current"), line


def test_stale_when_the_producer_changed_after_the_recorded_commit(repo):
    root, first, second = repo
    verdict, line = _verdict(root, {"summary": {}, "meta": {"git_commit": first}})
    assert verdict == "stale" and "**stale**" in line and second in line and "change the producer" in line
    verdict, line = _verdict(root, {"summary": {}, "meta": {"git_commit": second}})
    assert verdict == "current" and "**current**" in line
    # a recorded date (no commit) before / after the producer's last change
    assert _verdict(root, {"summary": {}, "date": "2026-01-01T12:00:00+00:00"})[0] == "stale"
    assert _verdict(root, {"summary": {}, "date": "2026-01-03T00:00:00+00:00"})[0] == "current"
    # nothing recorded: the commit that last touched the committed JSON (the first one) predates the change
    verdict, line = _verdict(root)
    assert verdict == "stale" and f"committed in {first}" in line


def test_stale_when_core_code_the_app_imports_changed(tmp_path):
    """An app table depends on the core modules its code imports: a change there makes it stale (naming the
    file); a change to core code it does not import leaves it current."""
    files = {"apps/hoi/run.py": "from volsmpl.volume.learned import query\n", "core/__init__.py": "",
             "core/volume/learned.py": "def query():\n    return 1\n", "core/unrelated.py": "x = 1\n"}
    first, second = producer_repo(tmp_path, files)
    (tmp_path / "apps/hoi/run.py").write_text("from volsmpl.volume.learned import query\nv = 2\n")
    git_run(tmp_path, "commit", "-q", "-am", "the app itself", date="2026-01-02T00:00:00+00:00")
    made = git_run(tmp_path, "rev-parse", "--short", "HEAD")
    data = {"summary": {}, "meta": {"git_commit": made}}
    assert _verdict(tmp_path, data)[0] == "current"
    (tmp_path / "core/unrelated.py").write_text("x = 2\n")
    git_run(tmp_path, "commit", "-q", "-am", "unrelated core", date="2026-01-03T00:00:00+00:00")
    assert _verdict(tmp_path, data)[0] == "current"
    (tmp_path / "core/volume/learned.py").write_text("def query():\n    return 2\n")
    git_run(tmp_path, "commit", "-q", "-am", "the engine", date="2026-01-04T00:00:00+00:00")
    verdict, line = _verdict(tmp_path, data)
    assert verdict == "stale" and "core/volume/learned.py" in line and "the engine" in line


def test_git_unavailable_is_said_not_guessed(tmp_path):
    write_result(tmp_path / "docs" / "hoi" / "results.json", HOI)
    text, status = report.build_report(tmp_path / "r.md", root=tmp_path, git=report.Git(tmp_path / "nowhere"))
    assert status["unknown"] == ["hoi"] and status["stale"] == []
    assert "**unknown**: not checked: git unavailable (" in text


def test_cli_user_errors_one_line_exit_2(tmp_path, capsys):
    out = tmp_path / "r.md"
    assert main(["report", "--results", f"hoi={tmp_path / 'missing.json'}", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "file not found" in err and err.startswith("volsmpl report: error:")
    bad = write_result(tmp_path / "bad.json", "{not json")
    assert main(["report", "--results", f"egohmr={bad}", "--out", str(out)]) == 2
    assert "cannot read result JSON" in capsys.readouterr().err
    assert main(["report", "--results", f"nosuch={bad}", "--out", str(out)]) == 2
    assert "unknown result name" in capsys.readouterr().err
    assert not out.exists()


def test_check_exit_code_and_atomic_write(tmp_path, monkeypatch):
    monkeypatch.setattr(report, "ROOT", tmp_path)  # an empty checkout: every result missing
    out = tmp_path / "docs" / "report.md"
    assert main(["report", "--out", str(out)]) == 0 and out.read_text().startswith("# Results report")
    assert main(["report", "--out", str(out), "--check"]) == 1
    assert [p.name for p in out.parent.iterdir()] == ["report.md"]  # no temporary file left behind
    one = {"hoi": report.SECTIONS["hoi"]}
    monkeypatch.setattr(report, "SECTIONS", one)
    res = write_result(tmp_path / "h.json", HOI)
    assert main(["report", "--out", str(out), "--check", "--results", f"hoi={res}"]) == 0  # no git: not stale


def test_real_results_render_if_present():
    docs = report.ROOT / "docs"
    if not (docs / "bench_cpu.json").exists():
        pytest.skip("no result JSONs in this checkout")
    text, status = report.build_report(docs / "report.md", git=NoGit())
    for sec in report.SECTIONS.values():
        assert sec.title in text
    assert "Paper Table C.4" in text and "464.41" in text and "Paper Table 6" in text


def test_a_result_of_another_layout_does_not_stop_the_report(tmp_path):
    res = write_result(tmp_path / "e.json", {"metrics": [1, 2], "config": "x"})
    text, _ = report.build_report(tmp_path / "r.md", root=tmp_path, overrides={"eval_volsmpl": res}, git=NoGit())
    assert "Could not tabulate these results (AttributeError" in text and "| `eval_volsmpl` |" in text


def test_checkpoint_note_names_only_the_checkpoint_a_result_describes(repo):
    """An eval of the shipped VolumetricSMPL is not said to describe an earlier COAP when only COAP changed later
    (and an eval that records no checkpoint is, as before, checked against both)."""
    root, first, second = repo
    for stem in ("volsmpl_anny", "coap_anny"):
        write_result(root / "core" / "assets" / f"{stem}.safetensors", "v1")
    git_run(root, "add", ".")
    git_run(root, "commit", "-q", "-m", "ship both", date="2026-01-03T00:00:00+00:00")
    made = git_run(root, "rev-parse", "--short", "HEAD")
    write_result(root / "core" / "assets" / "coap_anny.safetensors", "v2")
    git_run(root, "commit", "-q", "-am", "ship a new coap", date="2026-01-04T00:00:00+00:00")
    metrics = {"metrics": {"iou_mean": 0.9, "iou_surf": 0.85, "iou_unif": 0.95}, "meta": {"git_commit": made}}

    def row(extra: dict) -> str:
        res = write_result(root / "x" / "eval.json", {**metrics, "extra": extra})
        text, _ = report.build_report(root / "r.md", root=root, overrides={"eval_volsmpl": res})
        return next(ln for ln in text.splitlines() if ln.startswith("| `eval_volsmpl` |"))

    assert "changed after it" not in row({"checkpoint": "shipped volsmpl_anny"})
    line = row({"checkpoint": None})
    assert "coap_anny.safetensors" in line and "describes an earlier checkpoint" in line
    line = row({"checkpoint": "runs/x/coap_anny"})
    assert "coap_anny.safetensors" in line and "volsmpl_anny.safetensors" not in line


def test_eval_section_states_the_sampling_of_each_result(tmp_path):
    """The eval section says where each result's points lie (older JSONs, without the key, used the body box)."""
    write_result(tmp_path / "docs" / "eval_volsmpl_anny.json", {"metrics": {"iou_mean": 0.9, "iou_surf": 0.85, "iou_unif": 0.95},
          "config": {"n_bodies": 64, "n_points": 60000, "sampling": "parts", "surface_sigma": 0.02}})
    write_result(tmp_path / "docs" / "eval_coap_anny.json", {"metrics": {"iou_mean": 0.8, "iou_surf": 0.7, "iou_unif": 0.9},
          "config": {"n_bodies": 64, "n_points": 60000, "surface_sigma": 0.01}})
    text, _ = report.build_report(tmp_path / "docs" / "report.md", root=tmp_path, git=NoGit())
    assert "- VolumetricSMPL: 64 validation bodies, 60,000 points each (parts sampling, near-surface offsets 0.020 m)" in text
    assert "- COAP: 64 validation bodies, 60,000 points each (body sampling, near-surface offsets 0.010 m)" in text
    assert "does not publish the sampling behind its Table 1" in text


def test_wide_summaries_keep_the_paper_columns_first_and_tables_at_most_ten_columns(tmp_path):
    """A summary with many measures: the paper's columns first, then ours up to ten columns a table; the rest in
    further tables of our rows, every measure shown once."""
    extra = {f"m{i:02d}": float(i) for i in range(15)}
    res = write_result(tmp_path / "h.json", {"summary": {"volsmpl": {"iter_ms": 12.5, **extra}}})
    text, _ = report.build_report(tmp_path / "r.md", root=tmp_path, overrides={"hoi": res}, git=NoGit())
    hoi = text[text.index("## Human-object"):text.index("Sources:", text.index("## Human-object"))]
    tables = [ln for ln in hoi.splitlines() if ln.startswith("| row")]
    # Table 3's four columns and five of ours; then nine of ours; then the last one
    assert [len(h.split("|")) - 2 for h in tables] == [10, 10, 2]
    assert tables[0].startswith("| row | per iteration [ms] | total [min] | collision [%] | contact [cm] | m00 |")
    cols = [c.strip() for h in tables for c in h.split("|")[2:-1]]
    assert sorted(c for c in cols if c.startswith("m")) == sorted(extra)          # each measure once
    assert "| ours: volsmpl | 12.50 |" in hoi


def test_a_result_of_another_app_is_refused_for_a_section(tmp_path, capsys):
    """--results hoi=<selfpen's results.json> rendered selfpen's numbers as Table 3, marked current; a results.json
    names its app, and the report refuses it for another app's section in one line (before writing anything)."""
    from volsmpl.cli import main

    other = write_result(tmp_path / "selfpen" / "results.json", {"app": "selfpen", "summary": {"volsmpl": {"step_ms": 1.0}}})
    out = tmp_path / "r.md"
    assert main(["report", "--out", str(out), "--results", f"hoi={other}"]) == 2
    err = capsys.readouterr().err.strip()
    assert "is a results.json of `volsmpl selfpen`, not of `volsmpl hoi`" in err and "\n" not in err
    assert not out.exists()
    own = write_result(tmp_path / "hoi" / "results.json", {"app": "hoi", "summary": {"volsmpl": {"iter_ms": 1.0}}})
    assert report.parse_overrides([f"hoi={own}", f"selfpen={other}"]) == {"hoi": own, "selfpen": other}


def test_selfpen_section_reads_the_preset_of_either_layout(tmp_path):
    """selfpen's results name their preset at the top (tables made before the envelope) or in config (the envelope)."""
    summary = {"volsmpl": {"step_ms": 50.0, "collisions_after": 200.0}}
    for i, data in enumerate(({"preset": "paper", "summary": summary},
                              {"app": "selfpen", "config": {"preset": "paper", "seed": 0}, "summary": summary})):
        res = write_result(tmp_path / f"s{i}.json", data)
        text, _ = report.build_report(tmp_path / "r.md", root=tmp_path, overrides={"selfpen": res}, git=NoGit())
        assert "Ours: preset paper," in text


def test_hoi_medians_per_kind_from_the_apps_own_summaries(tmp_path):
    """Three hand-made fits of two kinds through the app's summarize / by_kind: the medians by hand (rotation 10, 20,
    40 -> 20; per kind 15 and 40), the cases whose rotation grew counted, a ball's undefined rotation left out; the
    report shows them as before -> after rows."""
    from types import SimpleNamespace

    from volsmpl.apps.hoi.cli import by_kind, summarize

    def fit(name, rot, rot0, contact):
        m = {"collision_pct": 1.0, "contact_cm": contact, "obj_trans_err_cm": 5.0, "obj_rot_err_deg": rot,
             "scale_err_pct": 0.0, "human_scale_err_pct": 0.0}
        return SimpleNamespace(name=name, after=m, before={**m, "obj_rot_err_deg": rot0, "contact_cm": 50.0},
                               ms_per_iter=10.0, total_s=1.0, peak_mem_mb=1.0)

    rs = [fit("cup_a", 10.0, 12.0, 2.0), fit("cup_b", 20.0, 15.0, 4.0), fit("chair_a", 40.0, 30.0, 9.0),
          fit("ball_a", None, None, 1.0)]
    kinds = by_kind(rs, lambda n: n.split("_")[0])
    s = summarize(rs)
    assert s["obj_rot_err_deg_median"] == 20.0 and s["obj_rot_err_deg_median_before"] == 15.0
    assert s["contact_cm_median"] == 3.0 and s["obj_rot_err_deg"] == pytest.approx(70 / 3)
    assert kinds["cup"]["obj_rot_err_deg_median"] == 15.0 and kinds["cup"]["worse_rotation"] == 1
    assert kinds["chair"]["worse_rotation"] == 1 and kinds["ball"]["obj_rot_err_deg_median"] is None
    res = write_result(tmp_path / "h.json", {"summary": {"volsmpl": s}, "by_kind": {"volsmpl": kinds}, "cases": {}})
    text, _ = report.build_report(tmp_path / "r.md", root=tmp_path, overrides={"hoi": res}, git=NoGit())
    assert "| volsmpl | all | 4 | 15.00 -> 20.00 | 50.00 -> 3.00 | 5.00 -> 5.00 | 1.00 -> 1.00 | 2 |" in text
    assert "| volsmpl | cup | 2 | 13.50 -> 15.00 | 50.00 -> 3.00 |" in text


def test_egohmr_paired_difference_and_activities_from_the_apps_own_rows(tmp_path):
    """Hand-made frames through the app's summarize / by_activity / paired_interval: the report shows each guide's
    paired MPJPE difference (every frame 2 mm worse: +2.00, interval [+2.00, +2.00]) and MPJPE / contact per
    activity (sitting 50 and 70 mm -> 60)."""
    from volsmpl.apps.egohmr.evaluate import by_activity, paired_interval, summarize

    def rec(i, act, err, contact):
        return {"frame": f"f{i}", "activity": act, "mpjpe_mm": err, "mpjpe_visible_mm": err,
                "mpjpe_invisible_mm": float("nan"), "n_visible": 24, "n_invisible": 0, "pa_mpjpe_mm": err,
                "pelvis_err_mm": 100.0, "collision_ratio": 0.0, "contact": contact, "s_per_frame": 1.0}

    none = [rec(0, "sitting", 50.0, True), rec(1, "sitting", 70.0, False), rec(2, "standing", 90.0, True)]
    mesh = [{**r, "mpjpe_mm": r["mpjpe_mm"] + 2, "mpjpe_visible_mm": r["mpjpe_mm"] + 2, "contact": True} for r in none]
    s_none, s_mesh = summarize(none), summarize(mesh)
    s_mesh["mpjpe_diff_mm"], *ci = paired_interval(mesh, none)
    s_mesh["mpjpe_diff_ci95_mm"] = ci
    res = write_result(tmp_path / "e.json", {"app": "egohmr", "summary": {"none": s_none, "mesh": s_mesh},
                                      "by_activity": {"none": by_activity(none), "mesh": by_activity(mesh)},
                                      "cases": {}})
    text, _ = report.build_report(tmp_path / "r.md", root=tmp_path, overrides={"egohmr": res}, git=NoGit())
    assert "| mesh | +2.00 [+2.00, +2.00] | 0 | 100.0 |" in text
    assert "| sitting | 2 | 60.00 / 50.00 | 62.00 / 100.0 |" in text
    assert "| standing | 1 | 90.00 / 100.0 | 92.00 / 100.0 |" in text


def test_the_refinement_cost_lines(tmp_path):
    """The eval section's cost lines list each checkpoint's encode and step times per batch size, with its learned
    passes and the test-time refinement steps where a row has them."""
    write_result(tmp_path / "docs" / "eval_volsmpl_anny.json", {"metrics": {"iou_mean": 0.9, "iou_surf": 0.85, "iou_unif": 0.95}})
    write_result(tmp_path / "docs" / "refiner_cost.json", {"threads": 1, "points": 2000, "rows": [
        {"checkpoint": "base", "B": 1, "refiner_iters": 0, "encode_ms": 40.0, "step_ms": 100.0},
        {"checkpoint": "runs/r/model", "B": 1, "refiner_iters": 2, "encode_ms": 80.0, "step_ms": 125.0},
        {"checkpoint": "runs/q/model", "B": 1, "refiner_iters": 1, "encode_ms": 60.0, "step_ms": 110.0},
        {"checkpoint": "base", "B": 1, "refiner_iters": 0, "refine_steps": 1, "encode_ms": 70.0, "step_ms": 130.0}]})
    text, _ = report.build_report(tmp_path / "docs" / "report.md", root=tmp_path, git=NoGit())
    ev = text[text.index("## Volumetric bodies: accuracy"):text.index("## Volumetric bodies: time")]
    rows = [ln for ln in ev.splitlines() if ln.startswith("| ours:")]
    assert len(rows) == 1 and rows[0].startswith("| ours: VolumetricSMPL | 90.00 | 85.00 | 95.00 |")
    assert ("- Cost at B = 1 (1 thread, 2,000 points per body; `docs/scripts/refiner_cost.py`): base (0 passes): encode "
            "40.00 ms, step 100.0 ms; runs/r/model (2 passes): encode 80.00 ms, step 125.0 ms; runs/q/model (1 pass): "
            "encode 60.00 ms, step 110.0 ms; base (0 passes, 1 refinement step per encoding): encode 70.00 ms, step "
            "130.0 ms.") in ev


def test_the_bench_ratio_of_the_papers_model_form_beside_the_papers(tmp_path):
    """With learned passes shipped, COAP as published against the encoder's codes (the paper's model) is the
    paper's ratio's counterpart: both ratios shown, each beside the paper's 140 / 15 ms and 18.7 / 3.1 GB."""
    ratios = {"coap/volsmpl": {"1": {"time": 3.0, "time_query": 4.0, "mem": 20.0}},
              "coap/volsmpl-encoder": {"1": {"time": 6.0, "time_query": 4.5, "mem": 21.0}}}
    res = write_result(tmp_path / "bench.json", {"models": {}, "ratios": ratios, "meta": {"cpu": "test cpu"}})
    text, _ = report.build_report(tmp_path / "r.md", root=tmp_path, overrides={"bench": res}, git=NoGit())
    assert "| coap/volsmpl (cpu), B = 1 | 3.00 | 4.00 | 20.00 | 9.3 | 6.0 |" in text
    assert "| coap/volsmpl-encoder (cpu), B = 1 | 6.00 | 4.50 | 21.00 | 9.3 | 6.0 |" in text
