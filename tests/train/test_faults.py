"""Faults: a training run killed with SIGKILL (at a random moment, or inside each step of a checkpoint write)
leaves no corrupted file and resumes from its last complete checkpoint to the same result as a run never killed;
a second process writing the same run folder is refused; a failed results write keeps the previous results."""
from __future__ import annotations

import csv
import json
import os
import signal
import subprocess
import sys
import time

import pytest
import torch

from volsmpl.io.checkpoint import load_checkpoint
from volsmpl.nn.config import VolumeConfig
from volsmpl.io.outputs import exclusive_folder, write_atomic
from volsmpl.train.loop import LOG_HEADER, latest_checkpoint, train
from volsmpl.train.state import verify_state
from volsmpl.train.config import TrainConfig

TINY = VolumeConfig(latent_dim=8, encoder_hidden=8, encoder_blocks=1, n_surface_samples=32, decoder_hidden=8, nbw_rank=2)
CFG = TrainConfig(batch_size=2, micro_batch=2, n_uniform=8, n_surface=8, steps=1000, ckpt_every=2, log_every=1,
                  keep_ckpts=2, model=TINY)
STEPS = 6

#: the child: trains CFG to STEPS in `out`, killing itself with SIGKILL at `mode` while writing checkpoint 4
CHILD = r"""
import os, signal, sys, json
import safetensors.torch as st
import volsmpl.train.loop as T
out, mode = sys.argv[1], sys.argv[2]
cfg = T.TrainConfig.from_dict(json.loads(sys.argv[3]))
die = lambda: os.kill(os.getpid(), signal.SIGKILL)
in_ckpt4 = lambda p: "ckpt-00000004" in str(p)
real_save, real_replace = st.save_file, os.replace
def save_file(tensors, path, metadata=None):
    if mode == "tensor_write" and in_ckpt4(path):  # half the bytes of the file on disk, then killed
        real_save(tensors, path + ".full", metadata=metadata)
        data = open(path + ".full", "rb").read()
        open(path, "wb").write(data[: len(data) // 2])
        die()
    return real_save(tensors, path, metadata=metadata)
import pathlib
real_write_text = pathlib.Path.write_text
def write_text(self, data, *a, **k):  # a plain write of the run's config: killed half-way
    if mode == "config_write" and self.name == "config.json":
        with open(self, "w") as fh:
            fh.write(data[: len(data) // 2])
        die()
    return real_write_text(self, data, *a, **k)
pathlib.Path.write_text = write_text
def replace(src, dst):
    if mode == "config_write" and str(dst).endswith("config.json"):
        die()
    if mode == "before_dir" and str(dst).endswith("ckpt-00000004"):
        die()
    if mode == "before_latest" and str(dst).endswith("latest") and "ckpt-00000004" in open(src).read():
        die()
    real_replace(src, dst)
    if mode == "after_latest" and str(dst).endswith("latest") and "ckpt-00000004" in open(dst).read():
        die()
st.save_file, os.replace = save_file, replace
print("ready", flush=True)
T.train(cfg, out, resume=os.path.exists(os.path.join(out, "latest")), max_steps=%d, quiet=True)
""" % STEPS


def _child(out, mode):
    return subprocess.Popen([sys.executable, "-c", CHILD, str(out), mode, json.dumps(CFG.to_dict())],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env={**os.environ, "OMP_NUM_THREADS": "1"})


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    """The losses of a run never killed."""
    return train(CFG, tmp_path_factory.mktemp("ref") / "run", max_steps=STEPS, quiet=True)["losses"]


def _check_intact(out):
    """Every published file reads: latest -> a complete checkpoint, each checkpoint verifies, the log parses."""
    ck = latest_checkpoint(out)
    assert ck is not None
    for d in sorted(out.glob("ckpt-*")):
        state, _, meta = load_checkpoint(d / "model")  # digests verified
        assert meta["training"]["step"] == int(d.name.split("-")[1])
        doc = verify_state(d)  # every file against its recorded sha256
        assert doc["step"] == meta["training"]["step"] and doc["optimizer"]["files"]
    json.loads((out / "config.json").read_text())
    rows = list(csv.reader((out / "log.csv").open()))
    assert rows[0] == LOG_HEADER and all(len(r) == len(LOG_HEADER) for r in rows)
    return int(ck.name.split("-")[1])


@pytest.mark.parametrize("mode,last", [("tensor_write", 2), ("before_dir", 2), ("before_latest", 2), ("after_latest", 4)])
def test_killed_during_checkpoint_write_resumes(tmp_path, reference, mode, last):
    out = tmp_path / "run"
    p = _child(out, mode)
    _, err = p.communicate(timeout=300)
    assert p.returncode == -signal.SIGKILL, err
    assert _check_intact(out) == last  # the last complete checkpoint
    resumed = train(CFG, out, resume=True, max_steps=STEPS - last, quiet=True)
    assert resumed["losses"] == pytest.approx(reference[last:], rel=1e-5, abs=1e-7)
    assert _check_intact(out) == STEPS and not list(out.glob(".tmp-*")) and not (out / ".latest.tmp").exists()
    steps = [int(r[0]) for r in list(csv.reader((out / "log.csv").open()))[1:]]
    assert steps == list(range(1, STEPS + 1))  # every step logged once


def test_killed_at_a_random_moment_resumes(tmp_path, reference):
    """SIGKILL from outside, a random delay after the first checkpoint is published."""
    out = tmp_path / "run"
    p = _child(out, "none")
    t0 = time.time()
    while not (out / "latest").exists() and p.poll() is None and time.time() - t0 < 120:
        time.sleep(0.01)
    time.sleep(float(torch.rand(1, generator=torch.Generator().manual_seed(int(time.time()))) * 0.5))
    p.kill()
    p.wait(timeout=60)
    last = _check_intact(out)
    resumed = train(CFG, out, resume=True, max_steps=STEPS - last, quiet=True) if last < STEPS else None
    if resumed is not None:
        assert resumed["losses"] == pytest.approx(reference[last:], rel=1e-5, abs=1e-7)
    assert _check_intact(out) == STEPS


def test_second_writer_of_a_run_folder_is_refused(tmp_path):
    out = tmp_path / "run"
    with exclusive_folder(out, "volsmpl train"):
        code = ("import sys; from volsmpl.cli import main; sys.exit(main(['train', '--out', sys.argv[1], '--set', "
                "'batch_size=2', 'steps=4', '--max-steps', '1', '--device', 'cpu']))")
        r = subprocess.run([sys.executable, "-c", code, str(out)], capture_output=True, text=True, timeout=300)
        assert r.returncode == 2 and f"pid {os.getpid()}" in r.stderr and len(r.stderr.strip().splitlines()) == 1
        assert not (out / "latest").exists() and not (out / "log.csv").exists()
    with exclusive_folder(out, "volsmpl train"):  # released at the end of the block
        pass


def test_failed_results_write_keeps_the_previous_file(tmp_path, monkeypatch):
    f = tmp_path / "results.json"
    write_atomic(f, '{"old": 1}')

    def disk_full(fd, mode):
        raise OSError(28, "No space left on device")
    monkeypatch.setattr(os, "fdopen", disk_full)
    with pytest.raises(OSError, match="No space"):
        write_atomic(f, '{"new": 2}')
    monkeypatch.undo()
    assert f.read_text() == '{"old": 1}' and [p.name for p in tmp_path.iterdir()] == ["results.json"]


def test_killed_while_writing_the_run_config_resumes(tmp_path, reference):
    """A resumed run rewrites config.json: killed half-way, the file must still be the whole previous one."""
    out = tmp_path / "run"
    train(CFG, out, max_steps=2, quiet=True)
    p = _child(out, "config_write")
    _, err = p.communicate(timeout=300)
    assert p.returncode == -signal.SIGKILL, err
    assert _check_intact(out) == 2
    resumed = train(CFG, out, resume=True, max_steps=STEPS - 2, quiet=True)
    assert resumed["losses"] == pytest.approx(reference[2:], rel=1e-5, abs=1e-7)
