"""The table scripts (tools/app_tables.sh, tools/motion_assemble.sh) refuse a wrong argument with one line and exit 2
before any work: no export, no output folder."""
from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

pytestmark = pytest.mark.skipif(shutil.which("bash") is None or not (ROOT / ".git").exists(),
                                reason="needs bash and a git checkout")


@pytest.mark.parametrize("script, args, words", [
    ("tools/app_tables.sh", ["selfpen", "hoii"], "unknown stage 'hoii'"),
    ("tools/motion_assemble.sh", ["--bogus"], "unknown argument '--bogus'"),
    ("tools/motion_assemble.sh", ["--worker"], "--worker needs the kinds"),
    ("tools/motion_assemble.sh", ["--worker", "mesh,coap"], "got 'coap'"),
])
def test_wrong_argument_is_one_line_exit_2_before_any_work(script, args, words):
    before = sorted(p.name for p in (ROOT / "out").glob("*")) if (ROOT / "out").exists() else []
    r = subprocess.run(["bash", script, *args], cwd=ROOT, capture_output=True, text=True, timeout=60)
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert r.returncode == 2, r.stderr
    assert len(lines) == 1 and words in lines[0], r.stderr
    assert r.stdout == ""
    after = sorted(p.name for p in (ROOT / "out").glob("*")) if (ROOT / "out").exists() else []
    assert after == before
