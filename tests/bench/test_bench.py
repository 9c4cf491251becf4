"""Tests of `volsmpl bench`: an end-to-end run on a tiny setting, ratios, config errors. Timings are never asserted."""
from __future__ import annotations

import json
from pathlib import Path

import pytest

from volsmpl.bench.run import BenchConfig, estimate_call_s
from volsmpl.bench.jobs import fit_budget
from volsmpl.bench.summary import PAPER, compute_ratios
import volsmpl
import volsmpl.volume.learned
import volsmpl.volume.models
from volsmpl.cli import main


@pytest.fixture(scope="module")
def tiny_run(tmp_path_factory):
    """One CLI run: 2k points, batch 1, 1 repeat, volsmpl + volsmpl-dense, 200 body-body vertices."""
    tmp = tmp_path_factory.mktemp("bench")
    out, md = tmp / "bench.json", tmp / "bench.md"
    rc = main(["bench", "--points", "2000", "--batch", "1", "--repeats", "1", "--warmup", "1", "--threads", "1",
               "--models", "volsmpl,volsmpl-dense", "--bodybody-vertices", "200", "--winding-repeats", "1",
               "--matmul-size", "256", "--quick", "--out", str(out), "--markdown", str(md)])
    assert rc == 0
    return json.loads(out.read_text()), md.read_text()


def test_json_has_expected_keys(tiny_run):
    res, _ = tiny_run
    for key in ("meta", "config", "matmul", "models", "bodybody", "ratios", "accuracy", "paper", "notes",
                "evaluate_protocol"):
        assert key in res, key
    assert res["meta"]["threads"] == 1 and res["meta"]["torch"]
    for key in ("cpu", "cpu_count", "load_avg_1_5_15", "platform", "python", "device", "date", "git_commit"):
        assert key in res["meta"], key
    assert res["matmul"]["size"] == 256 and res["matmul"]["gflops"] > 0
    assert set(res["models"]) == {"volsmpl", "volsmpl-dense"}
    for name, dense in (("volsmpl", False), ("volsmpl-dense", True)):
        e = res["models"][name]
        assert e["status"] == "ok" and e["dense"] is dense and set(e["batches"]) == {"1"}
        r = e["batches"]["1"]
        for key in ("t_ms", "t_query_ms", "mem_bytes", "mem_query_bytes", "mem_first_call_bytes", "params",
                    "decoder_pairs", "flops_per_pair", "evals_per_point", "decoder_gflop", "gflops"):
            assert r[key] is not None, (name, key)
        assert r["batch"] == 1 and r["points"] == 2000 and len(r["t_ms_all"]) == 1
        shipped = volsmpl.volume.models.model_kind("volsmpl").default_checkpoint.with_suffix(".safetensors").exists()
        assert r["weights"] == ("trained" if shipped else "random init")
    assert res["accuracy"]["volsmpl"]["status"].startswith("skipped")


def test_decoder_work_is_consistent(tiny_run):
    res, _ = tiny_run
    sparse, dense = (res["models"][m]["batches"]["1"] for m in ("volsmpl", "volsmpl-dense"))
    K = sparse["num_parts"]
    assert dense["evals_per_point"] == pytest.approx(K)  # dense: every part on every point
    assert 0 < sparse["evals_per_point"] < K  # sparse: only the boxes containing the point
    assert sparse["params"] == dense["params"] and sparse["flops_per_pair"] == dense["flops_per_pair"]
    assert sparse["decoder_gflop"] == pytest.approx(sparse["decoder_pairs"] * sparse["flops_per_pair"] / 1e9)


def test_operator_counts_and_decoder_rate(tiny_run):
    res, md = tiny_run
    for name in ("volsmpl", "volsmpl-dense"):
        r = res["models"][name]["batches"]["1"]
        assert r["ops_per_query"] > 0 and sum(r["op_names"].values()) == r["ops_per_query"]
        assert r["t_decoder_ms"] > 0 and r["t_decoder_ms"] <= r["t_query_ms"] * 10  # profiled: loose, never timed
        assert r["decoder_gflops"] == pytest.approx(r["decoder_gflop"] / (r["t_decoder_ms"] / 1e3))
        local = r["matmul_gflops_local"]   # the --matmul-size product, before and after the profiled queries
        assert len(local) == 2 and min(local) > 0
        assert r["decoder_share"] == pytest.approx(r["decoder_gflops"] / ((local[0] + local[1]) / 2))
        assert r["t_body_ms"] == pytest.approx(r["t_ms"]) and r["t_query_body_ms"] == pytest.approx(r["t_query_ms"])
    assert "ops/query" in md and "decoder / matmul" in md


def test_profile_query_counts_top_level_operators():
    import torch
    from volsmpl.bench.jobs import profile_query
    a = torch.randn(8, 8)
    r = profile_query(lambda: (a @ a).relu(), runs=1)  # matmul's inner mm is not counted again
    assert r["op_names"] == {"aten::matmul": 1, "aten::relu": 1} and r["t_decoder_ms"] is None


def test_ratios_and_bodybody(tiny_run):
    res, _ = tiny_run
    r = res["ratios"]["volsmpl-dense/volsmpl"]["1"]
    a, b = res["models"]["volsmpl-dense"]["batches"]["1"], res["models"]["volsmpl"]["batches"]["1"]
    assert r["time"] == pytest.approx(a["t_ms"] / b["t_ms"])
    assert r["time_query"] == pytest.approx(a["t_query_ms"] / b["t_query_ms"])
    assert "coap/volsmpl" not in res["ratios"]  # coap was not requested
    bb = res["bodybody"]
    assert bb["vertices_tested"] == 200
    assert bb["agreement"] * 200 == pytest.approx(round(bb["agreement"] * 200), abs=1e-6)  # a share of the 200 vertices
    w = res["ratios"]["winding/volsmpl"]["bodybody"]
    assert w["time"] == pytest.approx(bb["winding"]["t_ms"] / bb["volsmpl"]["t_ms"])
    assert bb["winding"]["points"] == 200 and bb["winding"]["faces"] == bb["faces"]


def test_markdown_written(tiny_run):
    _, md = tiny_run
    assert md.startswith("# Benchmark")
    for text in ("| volsmpl | 1 |", "| volsmpl-dense | 1 |", "volsmpl-dense/volsmpl", "winding numbers", "torch",
                 "Table C.4"):
        assert text in md, text


def test_compute_ratios_pairs_and_paper():
    row = lambda t, q, m: {"t_ms": t, "t_query_ms": q, "mem_bytes": m, "mem_query_bytes": m / 2}
    models = {"volsmpl": {"batches": {"1": row(10, 2, 100), "8": row(40, 8, 400)}},
              "coap": {"batches": {"1": row(90, 40, 600)}}}
    bb = {"winding": {"t_ms": 400, "mem_bytes": 1000}, "volsmpl": {"t_ms": 10, "t_query_ms": 1, "mem_bytes": 20,
                                                                    "mem_query_bytes": 10}}
    r = compute_ratios(models, bb)
    assert set(r["coap/volsmpl"]) == {"1"}  # only batch sizes both have
    assert r["coap/volsmpl"]["1"] == {"time": 9.0, "time_query": 20.0, "mem": 6.0, "mem_query": 6.0}
    assert r["winding/volsmpl"]["bodybody"] == {"time": 40.0, "time_query": 400.0, "mem": 50.0, "mem_query": 100.0}
    assert PAPER["ratios"]["coap/volsmpl"]["time"] == pytest.approx(9.33, abs=0.01)
    assert PAPER["ratios"]["winding/volsmpl"]["mem"] == pytest.approx(57.7, abs=0.1)


@pytest.mark.parametrize("kwargs, match", [
    (dict(models=("volsmpl", "leap")), "unknown model"),
    (dict(batches=(0,)), "batch size"),
    (dict(repeats=0), "repeats"),
    (dict(device="tpu"), "device"),
    (dict(checkpoints={"leap": "x"}), "checkpoints"),
])
def test_config_errors(kwargs, match):
    with pytest.raises(ValueError, match=match):
        BenchConfig(**kwargs)


def test_missing_checkpoint_is_a_clear_cli_error(tmp_path, capsys):
    rc = main(["bench", "--models", "volsmpl", "--checkpoint-volsmpl", str(tmp_path / "nope"), "--quick",
               "--points", "1000", "--batch", "1", "--repeats", "1", "--matmul-size", "64", "--no-bodybody"])
    assert rc == 2
    assert "not found" in capsys.readouterr().err


@pytest.mark.parametrize("option, model, asset", [("--checkpoint-coap", "coap-sparse", "volsmpl"),
                                                  ("--checkpoint-volsmpl", "volsmpl", "coap")])
def test_checkpoint_of_the_other_model_is_refused_before_any_work(monkeypatch, capsys, option, model, asset):
    """--checkpoint-coap core/assets/volsmpl_anny ran the matmul timing and every model before it, then died in the
    coap worker with its traceback in the message and the advice 'call attach_volume(..., model=...)'. It is now
    refused before any work, naming the option to use."""
    from volsmpl.bench import run as bench
    from volsmpl.volume.models import model_kind

    def no_work(*a, **k):
        raise AssertionError("the benchmark began before the checkpoints were checked")

    monkeypatch.setattr(bench, "matmul_rate", no_work)
    monkeypatch.setattr(bench, "bench_model", no_work)
    path = str(model_kind(asset).default_checkpoint)
    rc = main(["bench", "--models", model, option, path, "--quick", "--points", "100", "--batch", "1",
               "--repeats", "1", "--matmul-size", "64", "--no-bodybody"])
    err = capsys.readouterr().err.strip()
    assert rc == 2 and len(err.splitlines()) == 1, err
    assert f"{option} {path} holds a {asset} model" in err and f"--checkpoint-{asset}" in err


def test_budget_rules():
    assert fit_budget(2, 5, 0.1, 120.0) == (2, 5)  # fits: unchanged
    assert fit_budget(2, 5, 10.0, 120.0) == (0, 5)  # slow: no warm-up, 2 x 5 x 10 s <= 120 s
    assert fit_budget(2, 5, 30.0, 120.0) == (0, 2)
    assert fit_budget(2, 5, 500.0, 120.0) == (0, 1)  # always at least one timed run
    assert estimate_call_s({}, 8) is None
    assert estimate_call_s({"1": {"t_ms": 2000.0}}, 8) == pytest.approx(16.0)


def test_reduced_precision_models(tmp_path):
    """volsmpl-bf16 runs with its volume in bfloat16; volsmpl-tf32 is skipped off CUDA with the reason; the
    accuracy of a reduced-precision model is measured in that precision."""
    import torch

    from volsmpl.bench.run import accuracy, checkpoint_for
    out = tmp_path / "bench.json"
    rc = main(["bench", "--points", "2000", "--batch", "1", "--repeats", "1", "--warmup", "0", "--threads", "1",
               "--models", "volsmpl-bf16,volsmpl-tf32", "--no-bodybody", "--matmul-size", "128", "--quick",
               "--out", str(out)])
    assert rc == 0
    res = json.loads(out.read_text())
    assert res["models"]["volsmpl-bf16"]["status"] == "ok"
    assert res["accuracy"]["volsmpl-bf16"]["status"].startswith("skipped")
    if not torch.cuda.is_available():
        assert res["models"]["volsmpl-tf32"]["status"] == "skipped"
        assert "CUDA" in res["models"]["volsmpl-tf32"]["note"]
    cfg = BenchConfig(n_bodies=1, n_points=3000)
    ckpt = checkpoint_for("volsmpl", cfg)
    if ckpt is not None:
        acc = accuracy("volsmpl", ckpt, cfg, "bf16")
        assert acc["precision"] == "bf16" and 0.5 < acc["metrics"]["iou_mean"] <= 1.0


def test_the_accuracy_of_a_variant_with_its_own_passes():
    """A variant with its own number of learned passes has its own accuracy: volsmpl_r3 with none is step 50,000
    (the same encoder and decoders), with all of them its own."""
    from volsmpl.bench.run import accuracy

    ckpts = Path(__file__).resolve().parents[2] / "checkpoints"
    r3, base = (str(ckpts / d / "model") for d in ("volsmpl_r3/ckpt-00057000", "volsmpl_b8q/ckpt-00050000"))
    cfg = BenchConfig(n_bodies=1, n_points=3000)
    none, plain = accuracy("volsmpl", r3, cfg, passes=0), accuracy("volsmpl", base, cfg)
    both = accuracy("volsmpl", r3, cfg)
    assert none["passes"] == 0 and both["passes"] is None
    assert none["metrics"] == plain["metrics"] and none["metrics"]["iou_mean"] != both["metrics"]["iou_mean"]


def test_one_chunk_model_has_operator_calls_independent_of_batch():
    """'volsmpl-onechunk' runs a query as one chunk: the same operator calls at B = 1 and B = 3 (the profiler's
    count), where the default sparse model, whose CPU chunks hold at most cpu_chunk_elems entries, makes one chunk
    per (body, point range) and so more calls with more bodies; both give the same values."""
    import torch

    from volsmpl.bench.jobs import build_volume, profile_query
    from volsmpl.bench.variants import VARIANTS

    body = volsmpl.create_body()
    n = volsmpl.volume.learned.Volume.CPU_CHUNK_ELEMS // 16 + 5000  # just over one body's cache chunk: 2 point ranges
    counts, values = {}, {}
    for name in ("volsmpl", "volsmpl-onechunk"):
        vol = build_volume(body, VARIANTS[name].spec(checkpoint=None, init_seed=0))
        assert vol.num_parts == 16
        for B in (1, 3):
            g = torch.Generator().manual_seed(B)
            with torch.no_grad():
                out = body(body_pose=0.1 * torch.randn(B, 69, generator=g))
                lo, hi = out.vertices.amin(1, keepdim=True), out.vertices.amax(1, keepdim=True)
                pts = lo + (hi - lo) * torch.rand(B, n, 3, generator=g)
                enc = vol.encode(out, fresh=True)
                counts[name, B] = profile_query(lambda: vol.query_encoded(enc, pts), 1)["ops_per_query"]
                values[name, B] = vol.query_encoded(enc, pts)
    assert counts["volsmpl-onechunk", 1] == counts["volsmpl-onechunk", 3]
    assert counts["volsmpl", 3] > counts["volsmpl", 1] > counts["volsmpl-onechunk", 1]
    for B in (1, 3):
        torch.testing.assert_close(values["volsmpl-onechunk", B], values["volsmpl", B], atol=1e-5, rtol=1e-5)


def test_batch_scaling_job_times_the_same_bodies_both_ways(tmp_path):
    """The interleaved per-body timing (volsmpl.bench.scaling): per-round lists for both ways, medians and ratios
    derived from them, its table and summary line; a batch of one body is refused."""
    import numpy as np
    import torch

    from volsmpl.bench.jobs import make_frames, run_job
    from volsmpl.bench.summary import to_markdown
    from volsmpl.bench.scaling import batch_scaling_job, scaling_line, scaling_rows

    body = volsmpl.create_body()
    job = {"spec": {"model": "volsmpl", "dense": False, "checkpoint": None, "init_seed": 0}, "device": "cpu",
           "threads": 1, "warmup": 1, "repeats": 3}
    s = run_job("volsmpl.bench.scaling:batch_scaling_job", job, make_frames(body, 2, 1500, 1, 0))
    assert s["batch"] == 2 and s["points"] == 1500 and s["rounds"] == 3
    for key in ("t_body_ms", "t_query_body_ms"):
        assert set(s[key]) == {"1", "2"} and all(len(v) == 3 for v in s[key + "_all"].values())
        for b in ("1", "2"):
            assert s[key][b] == pytest.approx(np.median(s[key + "_all"][b])) and s[key][b] > 0
    assert s["ratio_query"] == pytest.approx(s["t_query_body_ms"]["2"] / s["t_query_body_ms"]["1"])
    assert s["ratio_t"] == pytest.approx(s["t_body_ms"]["2"] / s["t_body_ms"]["1"])
    head, rows = scaling_rows(s)
    assert head[2] == "B = 2 (one batch)" and len(rows) == 2 and "B = 2 against B = 1" in scaling_line(s)
    one = tmp_path / "one.pt"
    torch.save(make_frames(body, 1, 100, 1, 0), one)
    with pytest.raises(ValueError, match="at least 2 bodies"):
        batch_scaling_job(dict(job, inputs=str(one)))
    res = {"meta": {"cpu": "x", "cpu_count": 2, "load_avg_1_5_15": [0, 0, 0], "device": "cpu", "threads": 1,
                    "torch": "t", "python": "p", "date": "d", "git_commit": "c"},
           "matmul": {"size": 8, "t_ms": 1.0, "gflops": 1.0, "t_ms_all": [1.0]},
           "config": {"batches": [1, 2], "n_points": 1500, "repeats": 3, "warmup": 1, "device": "cpu"},
           "models": {}, "ratios": {}, "notes": [], "batch_scaling": s}
    assert "## Per-body time by batch size, interleaved in one process" in to_markdown(res)


def test_a_stored_result_still_renders():
    """A result written by an earlier run (docs/bench_cpu.json, which `volsmpl report` reads too) still gives the
    plain-text and Markdown reports, with a row for each of its models."""
    from pathlib import Path

    from volsmpl.bench.summary import format_report, to_markdown

    path = Path(__file__).resolve().parents[2] / "docs" / "bench_cpu.json"
    if not path.is_file():
        pytest.skip(f"{path} is not in this checkout")
    res = json.loads(path.read_text())
    md, text = to_markdown(res), format_report(res)
    assert res["models"] and md.startswith("# Benchmark")
    for name in res["models"]:
        assert f"| {name} | " in md and f"\n{name} " in text, name


def test_decoder_share_column_uses_the_matmul_measured_beside_the_decoder():
    """'decoder / matmul' divides by the rate measured in the job's process when the row has it, else by the run's."""
    from volsmpl.bench.summary import model_rows
    row = {"t_ms": 10.0, "t_query_ms": 5.0, "t_ms_all": [10.0], "mem_bytes": 1, "params": 1, "evals_per_point": 1.0,
           "decoder_gflop": 1.0, "gflops": 200.0, "decoder_gflops": 50.0, "ops_per_query": 3}
    result = {"matmul": {"gflops": 100.0}, "accuracy": {},
              "models": {"volsmpl": {"status": "ok", "model": "volsmpl", "batches": {"1": dict(row, decoder_share=0.25)}},
                         "volsmpl-dense": {"status": "ok", "model": "volsmpl", "batches": {"1": row}}}}
    head, rows = model_rows(result)
    col = head.index("decoder / matmul")
    assert [r[col] for r in rows] == ["25%", "50%"]
