"""The report names the cases an app flagged (results.json `flagged`), counted by back-end and status."""
from __future__ import annotations

from volsmpl.report.sections import flagged_note, summary_section


def test_flagged_cases_are_counted_by_backend_and_status():
    d = {"flagged": [{"case": "a", "model": "volsmpl", "status": "object_lost"},
                     {"case": "b", "model": "volsmpl", "status": "object_lost"},
                     {"case": "a", "model": "mesh", "status": "diverged"}]}
    assert flagged_note(d) == ["", "Flagged by the app's own judge (no ground truth): 3 case record(s): mesh diverged "
                                   "1, volsmpl object_lost 2 (`flagged` in the result)."]
    assert flagged_note({"flagged": []})[-1].endswith("none.")
    assert flagged_note({}) == []  # a result made before the apps judged their cases: nothing claimed


def test_an_app_section_carries_the_note():
    d = {"summary": {"volsmpl": {"collision_pct": 1.0}}, "cases": {"volsmpl": [{}]},
         "flagged": [{"case": "a", "model": "volsmpl", "status": "worse_than_start"}]}
    lines = summary_section({"name": "hoi", "paper": {"3": {}}, "results": {"hoi": d}})
    assert any("volsmpl worse_than_start 1" in line for line in lines)
