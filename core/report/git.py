"""The few git queries `volsmpl report` needs (volsmpl.report.build): the last commit touching some paths, the
files changed since a commit, a commit's time, uncommitted changes and HEAD; without git, `available` is False and
`reason` says why.

    git = Git(root)
    git.last_change(["apps/hoi"])      # ('1a2b3c4', 1764000000, 'subject') or None
"""
from __future__ import annotations

import subprocess
from pathlib import Path

__all__ = ["Git"]


class Git:
    """The few git queries the report needs, in `root`. available is False (reason says why) without git."""

    def __init__(self, root: Path):
        self.root = Path(root)
        try:
            p = subprocess.run(["git", "-C", str(self.root), "rev-parse", "--show-toplevel"], capture_output=True,
                               text=True, timeout=30)
            self.available = p.returncode == 0
            self.reason = "" if self.available else (p.stderr.strip().splitlines() or ["not a git repository"])[-1]
        except (OSError, subprocess.SubprocessError) as e:
            self.available, self.reason = False, f"git cannot run ({e.__class__.__name__}: {e})"

    def _out(self, *args) -> str | None:
        if not self.available:
            return None
        try:
            p = subprocess.run(["git", "-C", str(self.root), *args], capture_output=True, text=True, timeout=60)
        except (OSError, subprocess.SubprocessError):
            return None
        return p.stdout.strip() if p.returncode == 0 else None

    def last_change(self, paths, since: str | None = None) -> tuple[str, int, str] | None:
        """(short sha, commit time, subject) of the last commit touching paths (after `since` if given)."""
        rng = [f"{since}..HEAD"] if since else []
        out = self._out("log", "-1", "--format=%h %ct %s", *rng, "--", *paths)
        if not out:
            return None
        sha, ct, subject = (out.split(" ", 2) + [""])[:3]
        return sha, int(ct), (subject if len(subject) <= 90 else subject[:87] + "...")

    def changed_files(self, since: str, paths) -> list[str]:
        """Files among paths that differ between commit `since` and HEAD."""
        return (self._out("diff", "--name-only", f"{since}..HEAD", "--", *paths) or "").split()

    def commit_time(self, rev: str) -> int | None:
        out = self._out("show", "-s", "--format=%ct", f"{rev}^{{commit}}")
        return int(out) if out and out.isdigit() else None

    def dirty(self, paths) -> bool:
        return bool(self._out("status", "--porcelain", "--", *paths))

    def head(self) -> str | None:
        return self._out("rev-parse", "--short", "HEAD")
