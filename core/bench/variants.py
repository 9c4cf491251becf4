"""The variants of `volsmpl bench` in one table: each name maps to the registry model kind it attaches
(`volsmpl.volume.models`) and the `Volume` settings it runs with.

    from volsmpl.bench.variants import VARIANTS
    v = VARIANTS["volsmpl-bf16"]     # Variant(kind='volsmpl', precision='bf16', ...)
    v.volume_kwargs                  # {'dense': False, 'engine': 'lean', 'precision': 'bf16', 'cuda_graphs': True, ...}
    v.spec(checkpoint=None)          # the job spec that volsmpl.bench.jobs.build_volume turns into this Volume

The rest of the benchmark reads only this table: the names `--models` accepts and their order (also the order of
the result's 'models' and of its tables), the default `--models`, each (model, batch) job's spec, the variants
skipped off CUDA, the variants whose accuracy is measured in their own precision, and the base kinds that take
a checkpoint (`--checkpoint-volsmpl`, `--checkpoint-coap`). RATIO_PAIRS names the pairs of variants whose time
and memory ratios a run reports.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Dict, List, Optional, Tuple

__all__ = ["Variant", "VARIANTS", "DEFAULT_VARIANTS", "KINDS", "RATIO_PAIRS"]


@dataclass(frozen=True)
class Variant:
    """One benchmark variant: a registry model kind and the Volume settings it is measured with.

    Attributes:
        kind: the model kind given to `attach_volume(body, model=kind)` ('volsmpl' or 'coap'); also the key of
            its checkpoint (`--checkpoint-<kind>`, BenchConfig.checkpoints) and of its full-precision accuracy.
        label: the variant's name in words (e.g. for a report row).
        note: what the variant measures.
        dense: `Volume.dense`: every part decoder on every point (the reference path) instead of only the
            (point, part) pairs inside part boxes. A dense variant runs its query in one pass: one chunk, no
            decoder tiles, as the published implementations do.
        engine: `Volume.engine` of the sparse path, 'lean' or 'chunked'.
        precision: `Volume.set_precision`, 'full', 'bf16' or 'tf32'. A variant in a reduced precision has its
            own accuracy row, measured in that precision.
        pair_decoder: `Volume.pair_decoder`, 'tiles' or 'grouped'; None keeps the Volume's default.
        one_chunk: run the sparse query in one pass as well: the whole batch in one chunk (chunk_elems,
            cpu_chunk_elems and gpu_chunk_elems unbounded) and the decoders untiled (`net.set_tile_rows(None)`).
        cuda_graphs: `Volume.cuda_graphs` (replay the no-grad encode from a CUDA graph on a GPU).
        cuda_graph_queries: `Volume.cuda_graph_queries` (replay the no-grad lean query from a CUDA graph on a GPU).
        cuda_only: why the variant runs on CUDA only: off CUDA it is skipped with this note. '' runs anywhere.
        default: measured when `--models` is not given.
        passes: `Volume.set_passes`: None runs all the checkpoint's learned code-refinement passes, 0 the
            encoder's codes alone (the paper's model). A variant that sets it has its own accuracy row.
    """

    kind: str
    label: str
    note: str
    dense: bool = False
    engine: str = "lean"
    precision: str = "full"
    pair_decoder: Optional[str] = None
    one_chunk: bool = False
    cuda_graphs: bool = True
    cuda_graph_queries: bool = False
    cuda_only: str = ""
    default: bool = False
    passes: Optional[int] = None

    @property
    def volume_kwargs(self) -> Dict[str, object]:
        """The `Volume` keyword arguments of this variant (its constructor's names; the same attributes after
        construction, precision through `set_precision`); pair_decoder only when the variant sets it."""
        kw = {"dense": self.dense, "engine": self.engine, "precision": self.precision}
        if self.pair_decoder is not None:
            kw["pair_decoder"] = self.pair_decoder
        return dict(kw, cuda_graphs=self.cuda_graphs, cuda_graph_queries=self.cuda_graph_queries)

    def spec(self, checkpoint: Optional[str] = None, init_seed: int = 0) -> dict:
        """The job spec of this variant for `volsmpl.bench.jobs.build_volume` (JSON-able; checkpoint None:
        random weights drawn with init_seed)."""
        return {"model": self.kind, "dense": self.dense, "checkpoint": checkpoint, "init_seed": init_seed,
                "engine": self.engine, "precision": self.precision, "one_chunk": self.one_chunk,
                "pair_decoder": self.pair_decoder, "cuda_graphs": self.cuda_graphs,
                "cuda_graph_queries": self.cuda_graph_queries, "passes": self.passes}


#: benchmark variant name -> Variant, in the order `--models` lists them
VARIANTS: Dict[str, Variant] = {
    "volsmpl": Variant(
        "volsmpl", "VolumetricSMPL (sparse)",
        "the sparse engine with the Volume's defaults: the lean query (decoders only on the (point, part) pairs "
        "inside part boxes), cache-sized chunks on the CPU (one body per chunk at 60k points), the no-grad encode "
        "replayed from a CUDA graph on a GPU where no learned pass runs, all the checkpoint's learned passes",
        default=True),
    "volsmpl-encoder": Variant(
        "volsmpl", "VolumetricSMPL, the encoder's codes",
        "the sparse engine with the encoder's codes alone, no learned passes: the paper's model", passes=0,
        default=True),
    "volsmpl-dense": Variant(
        "volsmpl", "VolumetricSMPL, dense",
        "the paper's implementation: every part decoder on every point, in one pass", dense=True, default=True),
    "coap": Variant(
        "coap", "COAP as published",
        "COAP as published: every part on every point, in one pass", dense=True, default=True),
    "coap-sparse": Variant(
        "coap", "COAP on our sparse engine",
        "COAP's network on the sparse engine", default=True),
    "volsmpl-chunked": Variant(
        "volsmpl", "VolumetricSMPL, chunked engine",
        "the sparse engine 'chunked': padded chunks, every part's box distance at every point, the minimum over a "
        "dense (B, K, N) array", engine="chunked"),
    "volsmpl-bf16": Variant(
        "volsmpl", "VolumetricSMPL, bf16 decoders",
        "the sparse engine with bfloat16 decoder layers", precision="bf16"),
    "volsmpl-tf32": Variant(
        "volsmpl", "VolumetricSMPL, TF32 matmuls",
        "the sparse engine with TF32 matmuls", precision="tf32",
        cuda_only="TF32 is a CUDA tensor-core mode (run with --device cuda)"),
    "volsmpl-onechunk": Variant(
        "volsmpl", "VolumetricSMPL, one chunk",
        "the lean path with the whole batch in one chunk and the decoders' batched one-pass form: its operator "
        "calls do not depend on B", one_chunk=True),
    "volsmpl-tiles": Variant(
        "volsmpl", "VolumetricSMPL, tiled pair decoder",
        "the sparse engine with the tiled pair decoder", pair_decoder="tiles"),
    "volsmpl-grouped": Variant(
        "volsmpl", "VolumetricSMPL, grouped pair decoder",
        "the sparse engine with one grouped matmul per decoder layer", pair_decoder="grouped"),
    "volsmpl-eager": Variant(
        "volsmpl", "VolumetricSMPL, eager encode",
        "the no-grad encode run op by op on a GPU (on a CPU the same as 'volsmpl')", cuda_graphs=False),
    "volsmpl-qgraph": Variant(
        "volsmpl", "VolumetricSMPL, CUDA-graph query",
        "the no-grad lean query replayed from a CUDA graph as well on a GPU (on a CPU the same as 'volsmpl')",
        cuda_graph_queries=True),
}

#: the variants measured when `--models` is not given, in table order
DEFAULT_VARIANTS: Tuple[str, ...] = tuple(name for name, v in VARIANTS.items() if v.default)

#: the registry model kinds of the variants, in table order: the models that take a checkpoint
KINDS: Tuple[str, ...] = tuple(dict.fromkeys(v.kind for v in VARIANTS.values()))

#: (numerator, denominator) variant pairs whose time and memory ratios are reported per batch size, in this order
RATIO_PAIRS: List[Tuple[str, str]] = [
    ("coap", "volsmpl"), ("coap-sparse", "volsmpl"), ("volsmpl-dense", "volsmpl"), ("coap", "coap-sparse"),
    ("volsmpl-chunked", "volsmpl"), ("volsmpl", "volsmpl-bf16"), ("volsmpl", "volsmpl-tf32"),
    ("coap", "volsmpl-bf16"), ("coap", "volsmpl-tf32"), ("volsmpl-onechunk", "volsmpl"),
    ("volsmpl-eager", "volsmpl"), ("volsmpl", "volsmpl-qgraph"), ("coap", "volsmpl-qgraph"),
    ("coap", "volsmpl-encoder"), ("volsmpl", "volsmpl-encoder")]
