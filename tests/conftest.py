"""Shared fixtures: the default body, a small random-weight volume, random poses."""
from __future__ import annotations

import pytest
import torch

import volsmpl
from volsmpl.nn.config import VolumeConfig

torch.set_num_threads(2)


def pytest_collection_modifyitems(config, items):
    for item in items:
        if item.get_closest_marker("cuda") is not None and not torch.cuda.is_available():
            item.add_marker(pytest.mark.skip(reason="no CUDA GPU"))


def pytest_runtest_setup(item):
    """A test that needs the shipped checkpoint fails (not skips) when the file is missing."""
    if item.get_closest_marker("needs_checkpoint") is not None:
        from volsmpl.volume.models import model_kind
        path = model_kind("volsmpl").default_checkpoint.with_suffix(".safetensors")
        if not path.exists():
            pytest.fail(f"the shipped checkpoint {path} is missing: restore it (git checkout core/assets) before "
                        "running the tests that need it", pytrace=False)


@pytest.fixture(scope="session")
def body():
    return volsmpl.create_body()


@pytest.fixture(scope="session")
def tiny_config():
    return VolumeConfig(latent_dim=16, encoder_hidden=16, encoder_blocks=2, n_surface_samples=64,
                        decoder_hidden=16, nbw_rank=2)


@pytest.fixture
def host_reads(monkeypatch):
    """Counts, by method name, every read of tensor values to the host (tolist, item, int(), float(), bool(),
    index use): on a GPU each one waits for the device. Returns the Counter (clear it before the code under test)."""
    import collections

    reads = collections.Counter()
    for name in ("tolist", "item", "__int__", "__float__", "__bool__", "__index__"):
        original = getattr(torch.Tensor, name)

        def counted(self, *a, _name=name, _original=original, **k):
            reads[_name] += 1
            return _original(self, *a, **k)
        monkeypatch.setattr(torch.Tensor, name, counted)
    return reads


@pytest.fixture
def encoder_bf16_calls(monkeypatch):
    """The `bf16` argument of every PointNet encoding (`ResnetPointNet.encode_parts`), in call order: whether it ran
    under bfloat16 autocast. Returns the list (clear it before the code under test)."""
    from volsmpl.nn.pointnet import ResnetPointNet

    calls = []
    encode = ResnetPointNet.encode_parts

    def spied(self, surface, draws=1, bf16=False):
        calls.append(bf16)
        return encode(self, surface, draws, bf16)
    monkeypatch.setattr(ResnetPointNet, "encode_parts", spied)
    return calls


def random_pose(B: int, scale: float = 0.4, seed: int = 0, dtype=torch.float32, num_betas: int = 10):
    g = torch.Generator().manual_seed(seed)
    return dict(
        betas=torch.randn(B, num_betas, generator=g, dtype=dtype),
        global_orient=torch.randn(B, 3, generator=g, dtype=dtype) * scale,
        body_pose=torch.randn(B, 69, generator=g, dtype=dtype) * scale,
        transl=torch.randn(B, 3, generator=g, dtype=dtype) * 0.2,
    )


class NoGit:
    """`volsmpl report`'s git queries where git is unavailable (volsmpl.report.build.Git's interface)."""
    available, reason = False, "no git in this test"

    def head(self):
        return None


def write_result(path, data):
    """`data` (a dict as JSON, or text as it is) written to `path`, its folders made; returns the path."""
    import json
    from pathlib import Path

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(data) if not isinstance(data, str) else data)
    return path


def git_run(repo, *args, date: str | None = None) -> str:
    """Run git in `repo` with a fixed author (and commit date when given); its stdout, stripped."""
    import os
    import subprocess

    env = dict(os.environ, GIT_AUTHOR_NAME="t", GIT_AUTHOR_EMAIL="t@t", GIT_COMMITTER_NAME="t",
               GIT_COMMITTER_EMAIL="t@t")
    if date:
        env.update(GIT_AUTHOR_DATE=date, GIT_COMMITTER_DATE=date)
    return subprocess.run(["git", "-C", str(repo), *args], env=env, check=True, capture_output=True,
                          text=True).stdout.strip()


def producer_repo(root, first_files: dict | None = None) -> tuple[str, str]:
    """A git repository in `root` whose producer code apps/hoi/run.py changes once: commit 'first' (with
    `first_files`, {relative path: text}) on 2026-01-01, 'change the producer' on 2026-01-02. Returns both short
    hashes; skips the test where git is unavailable."""
    import subprocess
    from pathlib import Path

    try:
        git_run(root, "init", "-q")
    except (OSError, subprocess.CalledProcessError):
        pytest.skip("git is not available")
    for rel, text in {"apps/hoi/run.py": "v = 1\n", **(first_files or {})}.items():
        (Path(root) / rel).parent.mkdir(parents=True, exist_ok=True)
        (Path(root) / rel).write_text(text)
    git_run(root, "add", ".")
    git_run(root, "commit", "-q", "-m", "first", date="2026-01-01T00:00:00+00:00")
    first = git_run(root, "rev-parse", "--short", "HEAD")
    (Path(root) / "apps/hoi/run.py").write_text("v = 2\n")
    git_run(root, "commit", "-q", "-am", "change the producer", date="2026-01-02T00:00:00+00:00")
    return first, git_run(root, "rev-parse", "--short", "HEAD")
