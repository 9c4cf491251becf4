"""Every error a user can cause ends in one clear line naming the problem and the fix: at the CLI without a
traceback (exit 2; 1 for internal errors, 130 for Ctrl-C), the traceback only with --debug / VOLSMPL_DEBUG=1."""
from __future__ import annotations

import os
import sys
import types

import pytest
import torch

import volsmpl
from volsmpl import cli
from volsmpl.cli import main
from volsmpl.io.outputs import check_writable, write_atomic


def one_line(capsys) -> str:
    err = capsys.readouterr().err
    assert "Traceback" not in err, err
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1, err
    return lines[0]


# ------------------------------------------------------------------------------------ 1. CLI: one line, exit codes

@pytest.fixture
def fake_command(monkeypatch):
    """Register `volsmpl boom --kind K`: raises the exception K (a lazily imported subcommand like the real ones)."""
    mod = types.ModuleType("volsmpl_test_boom")
    errors = {"value": ValueError("bad thing; give a good thing"), "type": TypeError("expected an int, got str"),
              "oserror": PermissionError(13, "Permission denied"), "attr": AttributeError("'NoneType' has no 'x'"),
              "key": KeyError("k"), "interrupt": KeyboardInterrupt(), "multi": ValueError("first line\nsecond line")}

    def add_parser(sub):
        p = sub.add_parser("boom")
        p.add_argument("--kind", default="value")
        return p

    def run(args):
        raise errors[args.kind]

    mod.add_parser, mod.run = add_parser, run
    monkeypatch.setitem(sys.modules, "volsmpl_test_boom", mod)
    monkeypatch.setitem(cli.SUBCOMMANDS, "boom", ("volsmpl_test_boom", "raise an error"))
    monkeypatch.delenv("VOLSMPL_DEBUG", raising=False)
    return mod


@pytest.mark.parametrize("kind", ["value", "type", "oserror", "multi"])
def test_cli_user_error_is_one_line_exit_2(fake_command, capsys, kind):
    assert main(["boom", "--kind", kind]) == 2
    line = one_line(capsys)
    assert line.startswith("volsmpl boom: error: ") and "--debug" not in line


@pytest.mark.parametrize("kind", ["attr", "key"])
def test_cli_internal_error_is_one_line_exit_1_and_names_debug(fake_command, capsys, kind):
    assert main(["boom", "--kind", kind]) == 1
    line = one_line(capsys)
    assert line.startswith("volsmpl boom: error: internal error:") and "--debug" in line
    assert ("AttributeError" if kind == "attr" else "KeyError") in line


def test_cli_keyboard_interrupt_exit_130(fake_command, capsys):
    assert main(["boom", "--kind", "interrupt"]) == 130
    assert "interrupted" in one_line(capsys)


@pytest.mark.parametrize("how", ["flag_first", "flag_last", "env"])
def test_cli_debug_shows_the_traceback(fake_command, capsys, monkeypatch, how):
    argv = {"flag_first": ["--debug", "boom", "--kind", "attr"], "flag_last": ["boom", "--kind", "attr", "--debug"],
            "env": ["boom", "--kind", "attr"]}[how]
    if how == "env":
        monkeypatch.setenv("VOLSMPL_DEBUG", "1")
    assert main(argv) == 1
    err = capsys.readouterr().err
    assert "Traceback" in err and "AttributeError" in err
    assert err.strip().splitlines()[-1].startswith("volsmpl boom: error: internal error:")


def test_cli_real_subcommand_internal_error_has_no_traceback(monkeypatch, capsys):
    """A bug inside a real subcommand (an AttributeError escaping `body info`) no longer escapes main."""
    import volsmpl.body.partition as partition

    def broken(*a, **k):
        raise AttributeError("'Body' object has no attribute 'oops'")
    monkeypatch.delenv("VOLSMPL_DEBUG", raising=False)
    monkeypatch.setattr(partition, "Partition", broken)
    assert main(["body", "info"]) == 1
    assert "AttributeError" in one_line(capsys)


# ------------------------------------------------------------------------------- 2. output paths checked up front

def test_check_writable_and_write_atomic(tmp_path):
    f = tmp_path / "a" / "b" / "r.json"
    assert check_writable(f, "file") == f and f.parent.is_dir() and not f.exists()
    write_atomic(f, "x")
    write_atomic(f, b"yz")
    assert f.read_text() == "yz" and sorted(p.name for p in f.parent.iterdir()) == ["r.json"]
    d = tmp_path / "new" / "folder"
    assert check_writable(d, "dir") == d and d.is_dir() and list(d.iterdir()) == []
    with pytest.raises(ValueError, match="existing folder"):
        check_writable(tmp_path, "file")
    with pytest.raises(ValueError, match="existing file"):
        check_writable(f, "dir")
    with pytest.raises(ValueError, match="is a file"):
        check_writable(f / "sub" / "x.json", "file")
    if os.geteuid() != 0:  # root writes anywhere
        ro = tmp_path / "ro"
        ro.mkdir()
        ro.chmod(0o500)
        try:
            with pytest.raises(ValueError, match="cannot write"):
                check_writable(ro / "x.json", "file")
        finally:
            ro.chmod(0o700)


def test_bench_out_checked_before_the_benchmark(tmp_path, monkeypatch, capsys):
    import volsmpl.bench.run as bench
    monkeypatch.setattr(bench, "run_bench", lambda *a, **k: pytest.fail("the benchmark ran before the --out check"))
    afile = tmp_path / "file.txt"
    afile.write_text("x")
    assert main(["bench", "--out", str(tmp_path)]) == 2  # an existing folder where a file is expected
    line = one_line(capsys)
    assert line.startswith("volsmpl bench: error: --out") and "existing folder" in line
    assert main(["bench", "--out", str(tmp_path / "ok.json"), "--markdown", str(afile / "r.md")]) == 2
    line = one_line(capsys)
    assert "--markdown" in line and "is a file" in line


@pytest.mark.parametrize("argv, option", [
    (["eval", "--out", "{dir}"], "--out"),
    (["report", "--out", "{dir}"], "--out"),
    (["selfpen", "--out", "{file}"], "--out"),
    (["demo", "--out", "{file}"], "--out"),
    (["train", "--out", "{file}/run"], "--out"),
    (["body", "export", "--out", "{file}"], "--out"),
    (["body", "pose", "--out", "{file}/x.ply"], "--out"),
])
def test_subcommand_outputs_checked_before_the_job(tmp_path, capsys, argv, option):
    afile = tmp_path / "file.txt"
    afile.write_text("x")
    argv = [a.format(dir=tmp_path, file=afile) for a in argv]
    assert main(argv) == 2
    line = one_line(capsys)
    assert line.startswith(f"volsmpl {argv[0]}: error: {option}") and ("existing" in line or "is a file" in line)
    assert afile.read_text() == "x"


def test_app_results_are_written_atomically(tmp_path, monkeypatch):
    """The apps write results.json through volsmpl.apps.table.write_results: a write that fails half-way (here the
    final rename) leaves the earlier file whole and no partial file beside it."""
    import json
    import os

    from volsmpl.apps.table import write_results

    write_results(tmp_path, {"a": 1})

    def fail(*a, **k):
        raise OSError("disk full")

    monkeypatch.setattr(os, "replace", fail)
    with pytest.raises(OSError, match="disk full"):
        write_results(tmp_path, {"a": 2, "b": list(range(1000))})
    monkeypatch.undo()
    assert json.loads((tmp_path / "results.json").read_text()) == {"a": 1}
    assert [p.name for p in tmp_path.iterdir()] == ["results.json"]


def test_report_uses_the_shared_write_atomic():
    from volsmpl.io import outputs
    from volsmpl.report import build as report
    assert report.write_atomic is outputs.write_atomic


# --------------------------------------------------------------------------------------- 3. attach_volume(non-body)

@pytest.mark.parametrize("bad", [None, torch.nn.Linear(2, 2), "smpl"])
def test_attach_volume_refuses_a_non_body(bad):
    with pytest.raises(TypeError, match="expected a volsmpl.Body or an smplx SMPL/SMPL-H/SMPL-X model, got") as e:
        volsmpl.attach_volume(bad)
    assert type(bad).__name__ in str(e.value) and "\n" not in str(e.value)


@pytest.mark.parametrize("model", ["volsmpl", "coap"])
def test_attach_volume_refuses_an_argument_it_would_ignore(tiny_config, model):
    """checkpoint=... with pretrained=False gave random weights, the checkpoint unread; config=... with the
    pretrained default was replaced by the checkpoint's own: both silently. Both are refused in one line."""
    from volsmpl.volume.models import model_kind
    kind = model_kind(model)
    b = volsmpl.create_body()
    with pytest.raises(ValueError, match="pretrained=False would give random weights") as e:
        volsmpl.attach_volume(b, model=model, checkpoint=kind.default_checkpoint, pretrained=False)
    assert "\n" not in str(e.value)
    cfg = tiny_config if model == "volsmpl" else kind.default_config()
    with pytest.raises(ValueError, match="config is the architecture of random weights") as e:
        volsmpl.attach_volume(b, model=model, config=cfg)
    assert "\n" not in str(e.value) and not hasattr(b, "volume")
    assert volsmpl.attach_volume(b, model=model, pretrained=False, config=cfg).kind == model  # the meant uses
    assert volsmpl.attach_volume(b, model=model, checkpoint=kind.default_checkpoint).kind == model


# ------------------------------------------------------------------------------------ 4. extract_mesh arguments

@pytest.fixture(scope="module")
def posed_two(tiny_config):
    b = volsmpl.create_body()
    vol = volsmpl.attach_volume(b, pretrained=False, config=tiny_config)
    mesh = volsmpl.attach_volume(volsmpl.create_body(), model="mesh")
    with torch.no_grad():
        out = b(betas=torch.zeros(2, 10))
    return vol, mesh, out


@pytest.mark.parametrize("which", ["volume", "mesh"])
@pytest.mark.parametrize("kwargs, exc, words", [
    (dict(resolution=16.0), TypeError, "must be an int"),
    (dict(resolution=1000), ValueError, "limit 512"),
    (dict(resolution=4), ValueError, "at least 8"),
    (dict(body_index=2), ValueError, "batch of 2"),
    (dict(body_index=-1), ValueError, "batch of 2"),
    (dict(padding=0.0), ValueError, "must be positive"),
    (dict(padding=-0.1), ValueError, "must be positive"),
])
def test_extract_mesh_refuses_bad_arguments(posed_two, which, kwargs, exc, words):
    vol, mesh, out = posed_two
    target = vol if which == "volume" else mesh
    with pytest.raises(exc, match=words):
        target.extract_mesh(out, **kwargs)


def test_mesh_volume_extract_mesh_still_works(posed_two):
    _, mesh, out = posed_two
    assert mesh.extract_mesh(out, body_index=1).is_watertight


# ------------------------------------------------------------------------------------------ 5. a batch of 0 bodies

def test_zero_bodies_clear_message(body):
    with pytest.raises(ValueError, match=r"batch of 0 bodies \(betas has shape \(0, 10\)\).*B >= 1"):
        body(betas=torch.zeros(0, 10))
    with pytest.raises(ValueError, match="batch of 0 bodies"):
        body(body_pose=torch.zeros(0, 69))


# -------------------------------------------------------------------------------- 6. unsupported mesh extension

def test_body_pose_unsupported_extension(tmp_path, capsys):
    f = tmp_path / "file.xyz123"
    assert main(["body", "pose", "--out", str(f)]) == 2
    line = one_line(capsys)
    assert "xyz123" in line and "not a supported mesh format" in line and ".ply" in line and ".obj" in line
    assert not f.exists()
    assert main(["body", "pose", "--out", str(tmp_path / "noext")]) == 2
    assert "no extension" in one_line(capsys)
