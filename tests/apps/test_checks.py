"""The checks the apps share (volsmpl.apps.checks, volsmpl.apps.table): options of another mode, numbers, JSON
files, safe names, standard JSON out."""
from __future__ import annotations

import json
import math

import pytest

from volsmpl.apps.checks import applies, number, read_json, safe_name, strict_json
from volsmpl.apps.table import write_results
from volsmpl.cli import build_parser


def test_results_json_is_standard_json(tmp_path):
    """NaN and inf become null, at any depth; json.loads with a constant hook that refuses NaN/Infinity reads it."""
    res = {"a": float("nan"), "b": [1.0, float("inf"), {"c": -float("inf")}], "d": (2, 3), "e": "NaN"}
    path = write_results(tmp_path, res)

    def refuse(name):
        raise AssertionError(f"non-standard JSON constant {name}")

    assert json.loads(path.read_text(), parse_constant=refuse) == {"a": None, "b": [1.0, None, {"c": None}],
                                                                    "d": [2, 3], "e": "NaN"}
    assert strict_json(1.5) == 1.5 and strict_json(math.nan) is None


def test_number_accepts_the_range_and_names_the_flag():
    assert number("2", "--n", lo=1) == 2.0 and number(0, "--w", lo=0) == 0.0 and number(1, "--f", hi=1) == 1.0
    for value, kw, msg in [("nan", {}, "--x nan: give a finite number"), ("inf", {"lo": 0}, ">= 0"),
                           (0, {"lo": 0, "lo_open": True}, "> 0"), (2, {"hi": 1}, "<= 1"),
                           (1, {"hi": 1, "hi_open": True}, "< 1"), ("abc", {}, "--x 'abc' is not a number")]:
        with pytest.raises(ValueError, match=msg.replace("(", r"\(")):
            number(value, "--x", **kw)


def test_read_json_names_the_file_and_the_option(tmp_path):
    with pytest.raises(FileNotFoundError, match=r"the tuning file .*nope.json \(--tuned\) not found"):
        read_json(tmp_path / "nope.json", "the tuning file", "--tuned")
    (tmp_path / "bad.json").write_text('{"best": ')
    with pytest.raises(ValueError, match=r"bad.json \(--tuned\) is not valid JSON: Expecting value at line 1"):
        read_json(tmp_path / "bad.json", "the tuning file", "--tuned")
    (tmp_path / "ok.json").write_text('{"best": {"volsmpl": 3}}')
    assert read_json(tmp_path / "ok.json", "the tuning file") == {"best": {"volsmpl": 3}}


def test_safe_names_are_file_names_and_distinct():
    assert safe_name("room_3.ply") == "room_3.ply"  # already safe: as it is
    names = ["my room", "my_room", "tempelü", "a" * 300, "../etc/passwd", ""]
    safe = [safe_name(n) for n in names]
    assert len(set(safe)) == len(safe)  # 'my room' and 'my_room' stay apart
    for s in safe:
        assert len(s) <= 48 and all(ch.isascii() and (ch.isalnum() or ch in "._-=+") for ch in s) and "/" not in s


def test_applies_refuses_options_a_mode_does_not_read():
    args = build_parser("hoi").parse_args(["hoi", "fit", "--case", "c.json", "--split", "tune", "--n", "5"])
    with pytest.raises(ValueError, match=r"--n, --split do not apply to `volsmpl hoi fit`: drop them"):
        applies(args, "hoi fit", {"case", "model"})
    applies(args, "hoi fit", {"case", "split", "n"})  # both read: nothing refused
    # an option given at its default value is not a change: accepted
    args = build_parser("hoi").parse_args(["hoi", "fit", "--case", "c.json", "--iters", "1000"])
    applies(args, "hoi fit", {"case"})
