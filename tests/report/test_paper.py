"""volsmpl.report.paper: the paper's numbers, re-read from its LaTeX source where the checkout has it."""
from __future__ import annotations

import re
from pathlib import Path

import pytest

from volsmpl.report import paper
TEX = Path(__file__).resolve().parents[3] / "shared" / "paper" / "volumetric_smpl_iccv2025.tex"

_NUM = r"-?\d+(?:\.\d+)?(?:e-?\d+)?"


def _table_rows(tex: str, label: str) -> list[list]:
    """The body rows of the table with \\label{label}: per row, the numbers of each cell after the first
    (None for a '-' cell)."""
    env = next((m.group(0) for m in re.finditer(r"\\begin\{table\}.*?\\end\{table\}", tex, re.S)
                if f"\\label{{{label}}}" in m.group(0)), None)
    assert env is not None, f"no table labelled {label}"
    body = re.split(r"\\midrule", env, maxsplit=1)[1]
    body = re.split(r"\\bottomrule", body)[0]
    rows = []
    for line in body.splitlines():
        line = re.sub(r"(?<!\\)%.*", "", line)  # LaTeX comments, not \%
        if "&" not in line:
            continue
        line = re.sub(r"\\(?:cite|phantom)\{[^}]*\}", "", line)
        line = re.sub(r"(\d+(?:\.\d+)?)\s*\\times\s*10\^\{(-?\d+)\}", r"\1e\2", line)
        line = line.replace("\\%", "").replace("\\\\", "").replace("\\hdashline", "")
        cells = [c.strip() for c in line.split("&")][1:]
        row = []
        for c in cells:
            nums = re.findall(_NUM, re.sub(r"\\[a-zA-Z]+", " ", c))
            assert len(nums) <= 1, (label, c)
            row.append(float(nums[0]) if nums else None)
        rows.append(row)
    return rows


@pytest.mark.skipif(not TEX.exists(), reason=f"the paper's source is not in this checkout ({TEX})")
@pytest.mark.parametrize("number", list(paper.TABLES))
def test_every_number_equals_the_papers_source(number):
    t = paper.TABLES[number]
    printed = _table_rows(TEX.read_text(encoding="utf-8"), t["label"])
    ours = [[None if v is None else float(v) for v in (r[c] for c in t["columns"])] for r in t["rows"].values()]
    assert ours == printed


def test_parser_catches_a_wrong_number():
    tex = ("\\begin{table}\\caption{x}\\label{tab:x}\\begin{tabular}{lc}\\toprule & a & b \\\\\n\\midrule\n"
           "w. Ours & \\textbf{14 ms} & \\( 3.7 \\times 10^{-5} \\) \\\\\nCOAP~\\cite{c} & - & 6.33\\% \\\\\n"
           "\\bottomrule\\end{tabular}\\end{table}")
    assert _table_rows(tex, "tab:x") == [[14.0, 3.7e-5], [None, 6.33]]
    assert _table_rows(tex, "tab:x") != [[15.0, 3.7e-5], [None, 6.33]]


def test_a_few_numbers_by_hand():
    assert paper.value("1", "volsmpl", "iou_mean") == 94.67
    assert paper.value("1", "coap", "gpu_gb") == 18.7
    assert paper.value("3", "mesh", "iter_ms") == 2128.2
    assert paper.value("egohmr", "volsmpl", "batch") == 30
    assert paper.value("Table 5", "coap", "total_mem_gb") == 71.0
    assert "16 frames" in paper.table("5")["notes"]["coap"]["total_mem_gb"]
    assert paper.value("6", "volsmpl", "step_ms") == 14 and paper.value("6", "coap", "collisions") == 74
    assert paper.value("C.4", "winding", "t_ms") == 464.41
    assert paper.value("d.1", "coap_w1.0", "goal_dist_m") == 0.57


def test_tables_are_complete_and_named_as_the_paper():
    assert list(paper.TABLES) == ["1", "2", "3", "4", "5", "6", "C.4", "D.1"]
    hw = {k: t["hardware"] for k, t in paper.TABLES.items()}
    assert hw["3"] == "NVIDIA RTX 3090" and hw["6"] == "NVIDIA RTX 3090"
    assert "TITAN RTX" in hw["4"] and "A100" in hw["5"]
    for t in paper.TABLES.values():
        assert t["caption"] and t["title"] and set(t["row_labels"]) == set(t["rows"])
        for r in t["rows"].values():
            assert list(r) == list(t["columns"])
        assert all(set(c) == {"label", "unit"} for c in t["columns"].values())


def test_accessors():
    assert paper.rows("selfpen") == {
        "coap": {"step_ms": 30, "memory_gb": 6.2, "iterations": 9.75, "total_s": 0.29, "collisions": 74},
        "volsmpl": {"step_ms": 14, "memory_gb": 1.8, "iterations": 7.37, "total_s": 0.10, "collisions": 68}}
    paper.rows("6")["coap"]["step_ms"] = 0  # copies: the data stays as printed
    assert paper.value("6", "coap", "step_ms") == 30
    b = paper.bench_paper()
    assert b["volsmpl"] == {"t_ms": 15.0, "mem_gb": 3.1} and b["winding_bodybody"] == {"t_ms": 464.41, "mem_gb": 15.58}
    assert b["ratios"]["coap/volsmpl"]["time"] == pytest.approx(140 / 15)
    assert b["ratios"]["coap/volsmpl-encoder"] == {"time": pytest.approx(140 / 15), "mem": pytest.approx(18.7 / 3.1)}
    with pytest.raises(KeyError, match="no paper table"):
        paper.table("B.4")
    with pytest.raises(KeyError, match="no row"):
        paper.value("6", "mesh", "step_ms")
