"""Provenance of results: the commit a result records (volsmpl.io.provenance.git_commit)."""
from __future__ import annotations

import subprocess
from pathlib import Path

import volsmpl
from volsmpl.io.provenance import SOURCE_COMMIT, git_commit


def test_git_commit_of_an_export_is_the_one_it_names(tmp_path):
    """An exported package (no .git) records the commit its SOURCE_COMMIT names; without the file, none; the
    checkout's own package records the checkout's HEAD."""
    (tmp_path / SOURCE_COMMIT).write_text("106a83a\n")
    assert git_commit(tmp_path) == "106a83a"
    (tmp_path / SOURCE_COMMIT).unlink()
    assert git_commit(tmp_path) is None
    head = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=Path(volsmpl.__file__).parent,
                          capture_output=True, text=True)
    if head.returncode == 0:
        assert git_commit() == head.stdout.strip()
