"""Missing heavy packages (volsmpl.runtime.deps): one error naming the feature and the fix, reported by the CLI as a user
error (one line, exit 2), on a real path that needs open3d (groundtruth.mesh_sdf's distances to a room mesh; a
room's line-of-sight test has a torch path now, tests/apps/egohmr/test_no_open3d.py)."""
from __future__ import annotations

import sys

import numpy as np
import pytest

from volsmpl.runtime.deps import MissingDependency, open3d


def test_open3d_missing_names_the_feature_and_the_fix(monkeypatch):
    monkeypatch.setitem(sys.modules, "open3d", None)  # `import open3d` raises ImportError
    with pytest.raises(MissingDependency, match=r"the test feature needs open3d.*pip install 'open3d>=0\.18'"):
        open3d("the test feature")
    assert issubclass(MissingDependency, ImportError)  # callers catching ImportError still do


def test_a_room_without_open3d_fails_in_one_line_at_the_cli(monkeypatch, capsys):
    from volsmpl.apps.motion import cli as motion_cli
    from volsmpl.cli import main
    from volsmpl.geometry.groundtruth import mesh_sdf
    from volsmpl.scene import make_room

    room = make_room(0)
    monkeypatch.setitem(sys.modules, "open3d", None)

    def run(args):  # a subcommand that measures signed distances to a room mesh (open3d's BVH and ray casts)
        m = room.mesh()
        mesh_sdf(m.vertices, m.faces, np.asarray(room.bounds).mean(axis=0, keepdims=True))
        return 0

    monkeypatch.setattr(motion_cli, "run", run)
    assert main(["motion"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("volsmpl motion: error: ") and "mesh distances" in err and "pip install" in err
    assert "\n" not in err and "internal error" not in err
