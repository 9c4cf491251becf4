"""The report's table of the apps' cost per setting (tools/app_cost.py's docs/app_cost.json)."""
from __future__ import annotations

from volsmpl.report.sections import app_cost_section


def test_the_ratios_are_to_the_shipped_model_and_each_setting_names_its_flags():
    d = {"settings": {"shipped": [], "r3": ["--checkpoint-volsmpl", "X"]},
         "workloads": {"selfpen": {"command": ["selfpen"], "reads": ["step_ms", "other_ms"], "unit": "ms per step"}},
         "median": {"selfpen": {"shipped": 60.0, "r3": 90.0}},
         "ratio_to_shipped": {"selfpen": {"shipped": 1.0, "r3": 1.5}},
         "rounds": [{}, {}, {}], "meta": {"threads": 1, "cpu": "CPU-X"}}
    lines = app_cost_section({"name": "app_cost", "paper": ("3",), "results": {"app_cost": d}})
    text = "\n".join(lines)
    assert "| selfpen [ms per step] |" in text
    assert "| `r3` | 90.00 (1.50x) |" in text and "| `shipped` | 60.00 (1.00x) |" in text
    assert "median of 3 rounds" in text and "CPU-X" in text and "its ratio to `shipped`'s" in text
    assert "- `r3`: --checkpoint-volsmpl X" in text and "- `shipped`: the shipped model, no flags" in text
    assert "`volsmpl selfpen`, reading `step_ms` (kept beside it: other_ms)" in text


def test_the_ratios_are_to_the_base_setting_the_result_names():
    d = {"settings": {"s33000": ["--checkpoint-volsmpl", "Y"], "shipped": []},
         "workloads": {"hoi": {"command": ["hoi"], "reads": ["ms_per_iter"], "unit": "ms per step"}},
         "median": {"hoi": {"s33000": 40.0, "shipped": 44.0}}, "base": "s33000",
         "ratio_to_base": {"hoi": {"s33000": 1.0, "shipped": 1.1}}, "rounds": [{}], "meta": {"threads": 1}}
    text = "\n".join(app_cost_section({"name": "app_cost", "paper": ("3",), "results": {"app_cost": d}}))
    assert "its ratio to `s33000`'s" in text
    assert "| `shipped` | 44.00 (1.10x) |" in text and "| `s33000` | 40.00 (1.00x) |" in text
