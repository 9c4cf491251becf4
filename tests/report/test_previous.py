"""The report's figures beside a record kept from the models shipped before (volsmpl.report.previous): the
pairs by hand, and a record never stale nor missing."""
from __future__ import annotations

from conftest import NoGit, write_result
from volsmpl.report import build as report
from volsmpl.report.previous import previous_table


def selfpen(collidable: float, left: int, ms: float, commit: str) -> dict:
    return {"summary": {"volsmpl": {"collidable_after": collidable, "collidable_left_cases": left,
                                    "collisions_after": 200, "step_ms": ms},
                        "coap": {"collidable_after": 17.5, "collidable_left_cases": 7, "step_ms": 80.0}},
            "meta": {"git_commit": commit}}


def test_each_headline_as_before_and_now():
    now, before = selfpen(1.25, 1, 52.5, "new"), selfpen(10.5, 3, 45.0, "old")
    before["summary"].pop("coap")                                 # a back-end the record lacks: no row
    lines = previous_table("selfpen", {"selfpen": now}, {"selfpen_previous": before})
    assert "made at commit old" in lines[1]
    assert "| back-end | collidable pairs after | cases left | pairs after | ms per step |" in lines
    assert "| volsmpl | 10.50 -> 1.25 | 3 -> 1 | 200 -> 200 | 45.00 -> 52.50 |" in lines
    assert not any(line.startswith("| coap") for line in lines)
    assert previous_table("selfpen", {"selfpen": now}, {"selfpen_previous": None}) == []


def test_an_eval_record_by_split_in_percent():
    def ev(mean, contact):
        return {"metrics": {"iou_mean": mean, "iou_surf": 0.85, "iou_unif": 0.95},
                "splits": {"self_contact": {"metrics": {"iou_mean": contact}}}}
    lines = previous_table("eval", {"eval_volsmpl": ev(0.9261, 0.9412)}, {"eval_volsmpl_previous": ev(0.9006, 0.9178)},
                           {"eval_volsmpl": "VolumetricSMPL"})
    assert "| VolumetricSMPL, standard split | 90.06 -> 92.61 | 85.00 -> 85.00 | 95.00 -> 95.00 |" in lines
    assert "| VolumetricSMPL, self-contact split | 91.78 -> 94.12 | - -> - | - -> - |" in lines


def test_a_record_is_shown_never_stale_nor_missing(tmp_path):
    write_result(tmp_path / "docs" / "selfpen" / "results.json", selfpen(1.25, 1, 52.5, "new"))
    text, status = report.build_report(tmp_path / "r.md", root=tmp_path, git=NoGit())
    assert "Before and after" not in text                           # no record yet: nothing claimed
    assert "selfpen_previous" not in text and "selfpen_previous" not in sum(status.values(), [])
    write_result(tmp_path / "docs" / "selfpen" / "results_previous.json", selfpen(10.5, 3, 45.0, "old"))
    text, status = report.build_report(tmp_path / "r.md", root=tmp_path, git=NoGit())
    sec = text[text.index("## Self-intersection repair"):]
    assert "| volsmpl | 10.50 -> 1.25 | 3 -> 1 | 200 -> 200 | 45.00 -> 52.50 |" in sec
    assert "| coap | 17.50 -> 17.50 | 7 -> 7 | - -> - | 80.00 -> 80.00 |" in sec
    assert "**record** of the models shipped before, beside `selfpen`" in sec
    assert "selfpen_previous" not in sum(status.values(), [])
