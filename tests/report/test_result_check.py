"""Re-run checks of long results (volsmpl.report.result_check) and how `volsmpl report` uses them."""
from __future__ import annotations

import copy
import json
from pathlib import Path

import pytest

from conftest import producer_repo, write_result
from volsmpl.report import build as report
from volsmpl.cli import main
from volsmpl.report.result_check import case_leaves, check_path, compare_results, write_check


def rec(name, model, collision, ms):
    return {"name": name, "model": model, "after": {"collision_pct": collision, "contact_cm": 3.0},
            "ms_per_iter": ms, "peak_mem_mb": 40.0, "status": "max_iters", "loss": [1.0, 0.5]}


STORED = {"summary": {"volsmpl": {"collision_pct": 2.0}},
          "cases": {"volsmpl": [rec("a", "volsmpl", 1.0, 30.0), rec("b", "volsmpl", 3.0, 31.0)],
                    "mesh": [rec("a", "mesh", 2.0, 60.0), rec("b", "mesh", 2.5, 61.0)]},
          "meta": {"git_commit": "abc1234"}}


def fresh_of(*names, **change):
    """A fresh run of some cases of STORED, with other timings; change={'volsmpl/a': value} alters a collision."""
    f = {"cases": {m: [dict(copy.deepcopy(r), ms_per_iter=r["ms_per_iter"] * 1.7, peak_mem_mb=99.0)
                       for r in rs if r["name"] in names] for m, rs in STORED["cases"].items()}}
    for key, v in change.items():
        m, n = key.split("/")
        next(r for r in f["cases"][m] if r["name"] == n)["after"]["collision_pct"] = v
    return f


def test_leaves_are_keyed_by_the_records_identity_and_skip_run_measures():
    leaves = case_leaves(STORED["cases"])
    assert leaves[("model=volsmpl|name=b", "after/collision_pct")] == 3.0
    assert leaves[("model=mesh|name=a", "loss/1")] == 0.5
    assert not any("ms_per_iter" in p or "peak_mem" in p for _, p in leaves)
    motion = [{"scene": "room0", "sequence": 1, "model": "coap", "w": 0.1, "metrics": {"goal_dist_m": 0.01,
                                                                                       "optim_s": 100.0}}]
    assert case_leaves(motion) == {("model=coap|w=0.1|scene=room0|sequence=1", "metrics/goal_dist_m"): 0.01}


def test_compare_agrees_on_same_values_other_timings_and_names_a_difference():
    c = compare_results(STORED, fresh_of("b"))
    assert c["agree"] and c["cases_compared"] == 2 and c["cases_total"] == 4 and c["values_compared"] == 10
    c = compare_results(STORED, fresh_of("a", "b", **{"volsmpl/a": 1.0 + 1e-4}))
    assert not c["agree"] and c["n_mismatches"] == 1 and c["mismatches"][0]["value"] == "after/collision_pct"
    assert c["mismatches"][0]["case"] == "model=volsmpl|name=a"
    assert abs(c["max_abs_diff"] - 1e-4) < 1e-9
    assert compare_results(STORED, fresh_of("a", **{"volsmpl/a": 1.0 + 1e-4}), rel_tol=1e-3)["agree"]
    with pytest.raises(ValueError, match="shares no case"):
        compare_results(STORED, {"cases": {"volsmpl": [rec("zzz", "volsmpl", 1.0, 1.0)]}})
    timing_only = {"cases": {"volsmpl": [{"name": "a", "model": "volsmpl", "ms_per_iter": 1.0}]}}
    with pytest.raises(ValueError, match="shares no case"):        # nothing compared vouches for nothing
        compare_results(STORED, timing_only)
    with pytest.raises(ValueError, match="no per-case records"):
        compare_results({"summary": {}}, fresh_of("a"))


def test_a_value_only_the_fresh_run_records_is_listed_and_one_it_lacks_is_a_mismatch():
    """Later code may record more per case (a status, a stop rule): those values have nothing in the table to
    disagree with and are listed, not compared; a value of the table that the fresh run no longer makes is a
    mismatch."""
    f = fresh_of("a")
    for r in f["cases"]["volsmpl"] + f["cases"]["mesh"]:
        r["after"]["stop"] = "max_iters"
    c = compare_results(STORED, f)
    assert c["agree"] and c["values_compared"] == 10 and c["n_added"] == 2 and c["added"] == ["after/stop"]
    del f["cases"]["mesh"][0]["after"]["contact_cm"]
    c = compare_results(STORED, f)
    assert not c["agree"] and c["n_mismatches"] == 1 and c["values_compared"] == 10
    assert c["mismatches"][0] == {"case": "model=mesh|name=a", "value": "after/contact_cm", "stored": 3.0,
                                  "fresh": "<absent>"}




@pytest.fixture
def repo(tmp_path):
    """A hoi result made at `made`; the producer changes at `later` (a change that cannot touch its numbers)."""
    made, later = producer_repo(tmp_path)
    stored = write_result(tmp_path / "docs" / "hoi" / "results.json", dict(STORED, meta={"git_commit": made}))
    return tmp_path, stored, made, later


def _verdict(root: Path, stored: Path) -> tuple[str, str]:
    text, status = report.build_report(root / "r.md", root=root, overrides={"hoi": stored})
    line = next(ln for ln in text.splitlines() if ln.startswith("| `hoi` |"))
    return ("stale" if "hoi" in status["stale"] else "current"), line


def test_report_takes_an_agreeing_check_at_or_after_the_change_and_nothing_else(repo):
    root, stored, made, later = repo
    assert _verdict(root, stored)[0] == "stale"
    fresh = write_result(root / "out" / "fresh.json", dict(fresh_of("a"), meta={"git_commit": later}))
    write_check(stored, fresh)
    verdict, line = _verdict(root, stored)
    assert verdict == "current" and "re-run check at" in line and "2 of 4 cases" in line
    # a check made before the change does not count
    write_check(stored, write_result(root / "out" / "old.json", dict(fresh_of("a"), meta={"git_commit": made})))
    verdict, line = _verdict(root, stored)
    assert verdict == "stale" and "predates" in line
    # a disagreeing check keeps it stale and says where
    write_check(stored, write_result(root / "out" / "bad.json", dict(fresh_of("a", **{"mesh/a": 9.0}),
                                                              meta={"git_commit": later})))
    verdict, line = _verdict(root, stored)
    assert verdict == "stale" and "disagrees on 1 values" in line and "model=mesh|name=a" in line
    # a check of another version of the result file is ignored
    write_check(stored, fresh)
    stored.write_text(json.dumps(dict(STORED, meta={"git_commit": made}, note="edited")))
    assert _verdict(root, stored)[0] == "stale"


def test_cli_verify_writes_the_check_and_refuses_bad_input(repo, monkeypatch, capsys):
    root, stored, made, later = repo
    monkeypatch.setattr(report, "ROOT", root)
    fresh = write_result(root / "out" / "fresh.json", dict(fresh_of("b"), meta={"git_commit": later}))
    out = root / "docs" / "report.md"
    assert main(["report", "--out", str(out), "--verify", f"hoi={fresh}"]) == 0
    assert "2 of 4 cases compared, 10 values, all agree" in capsys.readouterr().out
    assert json.loads(check_path(stored).read_text())["agree"] is True
    assert main(["report", "--out", str(out), "--verify", f"nosuch={fresh}"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "--verify nosuch: unknown result name" in err
    other = write_result(root / "out" / "other.json", {"cases": {"volsmpl": [rec("zzz", "volsmpl", 1.0, 1.0)]}})
    assert main(["report", "--out", str(out), "--verify", f"hoi={other}"]) == 2
    assert "shares no case" in capsys.readouterr().err
    assert main(["report", "--out", str(out), "--verify", f"selfpen={fresh}"]) == 2
    assert "no stored result to compare with" in capsys.readouterr().err


def test_chained_check_ties_new_code_to_the_table_through_code_checked_on_its_machine(repo, monkeypatch, capsys):
    """On another machine the table's own code gives other values (here mesh/a 9.0 for 2.0): a fresh run there
    disagrees with the table whatever the code. --baseline compares the fresh run with a run, on the same machine, of
    code tied to the table (its own commit, or that of its last agreeing check): equal values make the result
    current, named as such; a baseline of other code or from another machine is refused in one line, a fresh run
    that differs from it keeps the result stale."""
    root, stored, made, later = repo
    monkeypatch.setattr(report, "ROOT", root)
    out = root / "docs" / "report.md"
    m1 = {"cpu": "AMD EPYC", "platform": "Linux-a"}
    m2 = {"cpu": "Intel Xeon", "platform": "Linux-b"}
    run = lambda name, commit, machine, **change: write_result(  # noqa: E731
        root / "out" / f"{name}.json", dict(fresh_of("a", **change), meta={"git_commit": commit, **machine}))
    cli = lambda *a: (main(["report", "--out", str(out), *a]), capsys.readouterr())  # noqa: E731
    base = run("base", made, m2, **{"mesh/a": 9.0})
    fresh = run("fresh", later, m2, **{"mesh/a": 9.0})
    rc, io = cli("--verify", f"hoi={fresh}")                                   # a plain check on the new machine
    assert rc == 0 and "1 differ" in io.out and _verdict(root, stored)[0] == "stale"
    rc, io = cli("--verify", f"hoi={fresh}", "--baseline", f"hoi={run('other', later, m2, **{'mesh/a': 9.0})}")
    assert rc == 2 and f"the code tied to results.json is {made} (the table itself)" in io.err
    assert io.err.count("\n") == 1
    rc, io = cli("--verify", f"hoi={fresh}", "--baseline", f"hoi={base}")     # the table's own code, run here
    assert rc == 0 and "all agree" in io.out
    verdict, line = _verdict(root, stored)
    assert verdict == "current" and f"with the code of {made}" in line and "Intel Xeon" in line
    check = json.loads(check_path(stored).read_text())
    assert check["machine"]["baseline_vs_table_mismatches"] == 1 and check["chained_from"]["fresh_commit"] == made
    # an agreeing check (this chained one, at `later`) ties its own code too
    rc, io = cli("--verify", f"hoi={fresh}", "--baseline", f"hoi={run('base2', later, m2, **{'mesh/a': 9.0})}")
    assert rc == 0 and "all agree" in io.out
    assert json.loads(check_path(stored).read_text())["chained_from"]["fresh_commit"] == later
    rc, io = cli("--verify", f"hoi={run('fresh1', later, m1, **{'mesh/a': 9.0})}", "--baseline", f"hoi={base}")
    assert rc == 2 and "same machine" in io.err and io.err.count("\n") == 1
    rc, io = cli("--baseline", f"hoi={base}")
    assert rc == 2 and "needs --verify hoi=" in io.err
    rc, io = cli("--verify", f"hoi={run('fresh2', later, m2, **{'mesh/a': 8.0})}", "--baseline", f"hoi={base}")
    assert rc == 0 and "1 differ" in io.out and _verdict(root, stored)[0] == "stale"


def test_records_grouped_by_the_kind_they_name_compare_with_the_same_records_listed_flat():
    """The apps' envelope groups records per kind ({"coap": [...]}); a motion table made before it lists them flat.
    Records that name their kind in 'model' are labelled by their own fields either way, so a check compares them."""
    from volsmpl.report.result_check import case_leaves, compare_results

    a = {"model": "coap", "w": 0.1, "scene": "room0", "sequence": 1, "metrics": {"goal_dist_m": 0.25}}
    b = {"model": "mesh", "w": 1.0, "scene": "room0", "sequence": 1, "metrics": {"goal_dist_m": 0.5}}
    assert case_leaves({"coap": [a], "mesh": [b]}) == {
        ("model=coap|w=0.1|scene=room0|sequence=1", "metrics/goal_dist_m"): 0.25,
        ("model=mesh|w=1.0|scene=room0|sequence=1", "metrics/goal_dist_m"): 0.5}
    assert case_leaves([a, b]) == case_leaves({"coap": [a], "mesh": [b]})
    check = compare_results({"cases": [a, b]}, {"cases": {"coap": [dict(a, metrics={"goal_dist_m": 0.3})]}})
    assert check["cases_compared"] == 1 and check["n_mismatches"] == 1
    # records that do not name the key they are grouped under keep it in their label
    assert case_leaves({"volsmpl": [{"name": "sit", "v": 1}]}) == {("volsmpl/name=sit", "v"): 1}
