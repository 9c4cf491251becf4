"""The bench variants' table (volsmpl.bench.variants) is the one source of what each `volsmpl bench --models` name
runs: the names and their order, each name's model kind and Volume settings, and the volume a job builds from it.
The expectations below are written out by hand, not read from the code."""
from __future__ import annotations

import argparse
import ast
from pathlib import Path

import pytest

import volsmpl
from volsmpl.bench import run as bench
from volsmpl.bench.variants import RATIO_PAIRS, VARIANTS

BENCH_DIR = Path(bench.__file__).resolve().parent
BIG = 1 << 62   # the chunk budget of a one-pass query

#: name -> (kind, dense, engine, precision, pair_decoder (None: the Volume's default), one pass, cuda_graphs,
#: cuda_graph_queries, CUDA only, learned passes (None: all the checkpoint's)), in the order `--models` lists them
EXPECTED = {
    "volsmpl": ("volsmpl", False, "lean", "full", None, False, True, False, False, None),
    "volsmpl-encoder": ("volsmpl", False, "lean", "full", None, False, True, False, False, 0),
    "volsmpl-dense": ("volsmpl", True, "lean", "full", None, True, True, False, False, None),
    "coap": ("coap", True, "lean", "full", None, True, True, False, False, None),
    "coap-sparse": ("coap", False, "lean", "full", None, False, True, False, False, None),
    "volsmpl-chunked": ("volsmpl", False, "chunked", "full", None, False, True, False, False, None),
    "volsmpl-bf16": ("volsmpl", False, "lean", "bf16", None, False, True, False, False, None),
    "volsmpl-tf32": ("volsmpl", False, "lean", "tf32", None, False, True, False, True, None),
    "volsmpl-onechunk": ("volsmpl", False, "lean", "full", None, True, True, False, False, None),
    "volsmpl-tiles": ("volsmpl", False, "lean", "full", "tiles", False, True, False, False, None),
    "volsmpl-grouped": ("volsmpl", False, "lean", "full", "grouped", False, True, False, False, None),
    "volsmpl-eager": ("volsmpl", False, "lean", "full", None, False, False, False, False, None),
    "volsmpl-qgraph": ("volsmpl", False, "lean", "full", None, False, True, True, False, None),
}
DEFAULT_MODELS = ("volsmpl", "volsmpl-encoder", "volsmpl-dense", "coap", "coap-sparse")


def _parser():
    parser = argparse.ArgumentParser()
    sub = bench.add_parser(parser.add_subparsers())
    return parser, next(a for a in sub._actions if "--models" in a.option_strings)


def test_table_holds_the_variants_in_order_with_their_settings():
    assert list(VARIANTS) == list(EXPECTED)
    for name, expected in EXPECTED.items():
        v = VARIANTS[name]
        assert (v.kind, v.dense, v.engine, v.precision, v.pair_decoder, v.dense or v.one_chunk, v.cuda_graphs,
                v.cuda_graph_queries, bool(v.cuda_only), v.passes) == expected, name
        assert v.label and v.note, name
    with pytest.raises(AttributeError):   # frozen: one table, not a per-run copy to edit
        VARIANTS["volsmpl"].engine = "chunked"


def test_models_option_accepts_exactly_the_table():
    """Every name of the table passes `--models` (alone, and all together in the help's order); other names,
    among them the GPU results' old 'volsmpl-graphs', are refused with the list of names."""
    parser, models = _parser()
    assert models.help == "comma-separated, from " + ",".join(EXPECTED)
    for name in EXPECTED:
        assert bench.config_from_args(parser.parse_args(["bench", "--models", name])).models == (name,)
    assert bench.config_from_args(parser.parse_args(["bench", "--models", ",".join(EXPECTED)])).models == tuple(EXPECTED)
    assert bench.config_from_args(parser.parse_args(["bench"])).models == DEFAULT_MODELS
    assert bench.BenchConfig().models == DEFAULT_MODELS
    for other in ("volsmpl-graphs", "mesh", "leap", "VOLSMPL"):
        with pytest.raises(ValueError, match=r"unknown model\(s\) \['" + other + r"'\]; choose from \['volsmpl', "
                                             r"'volsmpl-encoder', 'volsmpl-dense', 'coap', 'coap-sparse'"):
            bench.config_from_args(parser.parse_args(["bench", "--models", other]))


def test_checkpoints_are_taken_for_the_model_kinds():
    assert bench.BenchConfig(checkpoints={"volsmpl": "a", "coap": "b"}).checkpoints == {"volsmpl": "a", "coap": "b"}
    for other in ("volsmpl-dense", "coap-sparse", "mesh"):
        with pytest.raises(ValueError, match=rf"checkpoints for \['{other}'\]: give them for 'volsmpl' or 'coap'\."):
            bench.BenchConfig(checkpoints={other: "x"})


def test_ratio_pairs_name_variants_of_the_table():
    assert RATIO_PAIRS == [("coap", "volsmpl"), ("coap-sparse", "volsmpl"), ("volsmpl-dense", "volsmpl"),
                           ("coap", "coap-sparse"), ("volsmpl-chunked", "volsmpl"), ("volsmpl", "volsmpl-bf16"),
                           ("volsmpl", "volsmpl-tf32"), ("coap", "volsmpl-bf16"), ("coap", "volsmpl-tf32"),
                           ("volsmpl-onechunk", "volsmpl"), ("volsmpl-eager", "volsmpl"), ("volsmpl", "volsmpl-qgraph"),
                           ("coap", "volsmpl-qgraph"), ("coap", "volsmpl-encoder"), ("volsmpl", "volsmpl-encoder")]
    from volsmpl.bench import summary
    assert summary.RATIO_PAIRS is RATIO_PAIRS


def _tile_rows(vol):
    """Rows per CPU cache tile of the volume's no-grad pair decoder (None: untiled)."""
    return (vol.net.decoder if hasattr(vol.net, "decoder") else vol.net).TILE_ROWS


def _check_volume(vol, name, built: bool = True):
    kind, dense, engine, precision, pair_decoder, one_pass, graphs, qgraphs, _, passes = EXPECTED[name]
    assert not built or vol.passes == passes      # set by build_volume (Volume's constructor does not take it)
    assert vol.kind == kind and vol.dense is dense and vol.engine == engine and vol.precision == precision
    assert vol.pair_decoder == (pair_decoder or "tiles")      # the Volume's default pair decoder is 'tiles'
    assert vol.cuda_graphs is graphs and vol.cuda_graph_queries is qgraphs


@pytest.mark.parametrize("name", list(EXPECTED))
def test_volume_kwargs_give_that_volume(name):
    """A Volume on the default body with random weights, the variant's keyword arguments applied by the setters (or
    given to the constructor), has the settings the variant stands for."""
    from volsmpl.volume.learned import Volume

    v = VARIANTS[name]
    vol = volsmpl.attach_volume(volsmpl.create_body(), model=EXPECTED[name][0], pretrained=False)
    for key, value in v.volume_kwargs.items():
        if key == "precision":
            vol.set_precision(value)
        else:
            assert hasattr(vol, key), key
            setattr(vol, key, value)
    _check_volume(vol, name, built=False)
    _check_volume(Volume(vol.net, vol.partition, vol.fingerprint, **v.volume_kwargs), name, built=False)


@pytest.mark.parametrize("name", list(EXPECTED))
def test_bench_job_builds_the_variants_volume(name, monkeypatch):
    """What a bench job measures: bench_model sends the variant's spec, and build_volume makes of it the Volume
    the table says, in one pass (unbounded chunks, untiled decoders) for dense and one-chunk variants."""
    from volsmpl.bench.jobs import build_volume
    from volsmpl.volume.learned import Volume

    sent = []
    body = volsmpl.create_body()
    monkeypatch.setattr(bench, "make_frames", lambda *a, **k: {})
    monkeypatch.setattr(bench, "run_job", lambda target, job, inputs, timeout: sent.append((target, job)) or {})
    bench.bench_model(name, 1, bench.BenchConfig(models=(name,), init_seed=3), body, None)
    (target, job), = sent
    assert target == "volsmpl.bench.jobs:volume_job" and job["spec"]["checkpoint"] is None
    assert job["spec"]["init_seed"] == 3 and job["spec"]["model"] == EXPECTED[name][0]
    vol = build_volume(body, job["spec"])
    _check_volume(vol, name)
    one_pass = EXPECTED[name][5]
    chunks = (vol.chunk_elems, vol.cpu_chunk_elems, vol.gpu_chunk_elems)
    assert chunks == ((BIG, BIG, BIG) if one_pass else (1 << 21, Volume.CPU_CHUNK_ELEMS, Volume.GPU_CHUNK_ELEMS))
    assert (_tile_rows(vol) is None) is one_pass


def test_batch_scaling_and_bodybody_measure_the_volsmpl_variant(monkeypatch):
    import torch

    from volsmpl.bench.jobs import build_volume

    sent = []
    monkeypatch.setattr(bench, "make_frames", lambda *a, **k: {})
    monkeypatch.setattr(bench, "bodybody_inputs", lambda *a, **k: {
        "pose_b": torch.zeros(1, 69), "transl_b": torch.zeros(1, 3), "points": torch.zeros(1, 4, 3),
        "vertices_b": torch.zeros(3, 3)})
    monkeypatch.setattr(bench, "run_job", lambda target, job, inputs, timeout: sent.append(job.get("spec")) or {
        "pred": torch.zeros(1, 4), "t_ms": 1.0, "mem_bytes": 1})
    body = volsmpl.create_body()
    cfg = bench.BenchConfig(batches=(1, 2))
    bench.bench_batch_scaling(cfg, body, None)
    bench.bench_bodybody(cfg, body, None)
    scaling, bodybody, winding = sent
    assert winding is None
    for spec in (scaling, bodybody):
        assert spec["model"] == "volsmpl"
        _check_volume(build_volume(body, spec), "volsmpl")


def _code_strings(path: Path) -> list:
    """The string constants of a module's code (docstrings left out)."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    docs = {id(n.body[0].value) for n in ast.walk(tree)
            if isinstance(n, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)) and n.body
            and isinstance(n.body[0], ast.Expr) and isinstance(n.body[0].value, ast.Constant)}
    return [n.value for n in ast.walk(tree) if isinstance(n, ast.Constant) and isinstance(n.value, str)
            and id(n) not in docs]


def test_no_other_module_of_the_bench_names_a_variant():
    """Only variants.py spells out the variants: no other bench module's code names one (but 'volsmpl', the
    variant of the batch-scaling and body-body measurements, which is also a model kind), nor keeps the
    per-variant tables the table replaced."""
    kinds = {"volsmpl", "coap"}
    modules = sorted(BENCH_DIR.glob("*.py"))
    assert BENCH_DIR / "variants.py" in modules and len(modules) >= 5
    for path in modules:
        if path.name == "variants.py":
            continue
        named = sorted({s for s in _code_strings(path) for name in set(EXPECTED) - kinds if name in s})
        assert not named, f"{path.name} names variants: {named}"
    for old in ("MODELS", "ENGINES", "PRECISIONS", "PAIR_DECODERS", "ONE_CHUNK", "EAGER_ENCODE", "GRAPH_QUERIES"):
        assert not hasattr(bench, old), old
