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


def test_the_learned_passes_of_a_result_are_named():
    def note(r):
        return refinement_note({"config": {"code_refinement": {"steps": 0, "warm": False, **r}}})[-1]

    two = note({"passes": 2, "pass_every": 4})
    assert "2 learned passes at every 4th iteration" in two and "--pass-every 4" in two
    assert "1 learned pass at every encoding" in note({"passes": 1, "pass_every": 1})
    none = note({"passes": 0, "pass_every": 1})
    assert "no code refinement" in none and "learned pass" not in none   # --passes 0: the encoder's codes
    cold = refinement_note({"config": {"code_refinement": {"steps": 80, "warm": False, "passes": 2}}})[-1]
    assert "80 refinement steps per encoding" in cold and "2 learned passes at every encoding" in cold


def test_an_app_section_carries_it():
    d = {"summary": {"volsmpl": {"collision_pct": 1.0}}, "cases": {"volsmpl": [{}]},
         "config": {"code_refinement": {"steps": 2, "warm": True}}}
    lines = summary_section({"name": "hoi", "paper": {"3": {}}, "results": {"hoi": d}})
    assert any("2 refinement steps per encoding" in line for line in lines)
