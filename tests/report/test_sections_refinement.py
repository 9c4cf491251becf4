"""The report says how an app result's part codes were made (results.json `config.code_refinement`)."""
from __future__ import annotations

from volsmpl.report.sections import refinement_note, summary_section


def test_the_code_refinement_of_a_result_is_named():
    assert refinement_note({}) == []                                     # not recorded: nothing claimed
    assert "no code refinement" in refinement_note({"config": {"code_refinement": {"steps": 0, "warm": False}}})[-1]
    warm = refinement_note({"config": {"code_refinement": {"steps": 1, "warm": True}}})[-1]
    assert "1 refinement step per encoding" in warm and "--refine-warm" in warm
    cold = refinement_note({"config": {"code_refinement": {"steps": 40, "warm": False}}})[-1]
    assert "40 refinement steps per encoding" in cold and "from the encoder's codes" in cold
    assert "--pass-every" not in cold
    every = refinement_note({"config": {"code_refinement": {"steps": 0, "warm": False, "pass_every": 4}}})[-1]
    assert "every 4th iteration" in every and "--pass-every 4" in every


def test_an_app_section_carries_it():
    d = {"summary": {"volsmpl": {"collision_pct": 1.0}}, "cases": {"volsmpl": [{}]},
         "config": {"code_refinement": {"steps": 2, "warm": True}}}
    lines = summary_section({"name": "hoi", "paper": {"3": {}}, "results": {"hoi": d}})
    assert any("2 refinement steps per encoding" in line for line in lines)
