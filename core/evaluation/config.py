"""Settings and result of one evaluation (`EvalConfig`, `EvalResult`) and the paper's Table 1 as the evaluation
prints it (`PAPER_TABLE1`); `volsmpl.evaluation.run` evaluates, `volsmpl.evaluation.cli` is `volsmpl eval`."""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Dict, Optional


from volsmpl.report import paper
from volsmpl.volume.precision import PRECISIONS
from volsmpl.evaluation.validation_set import VAL_SEED

__all__ = ["PAPER_TABLE1", "SAMPLINGS", "EvalConfig", "EvalResult"]


def _paper_table1() -> dict:
    """The paper's Table 1 (volsmpl.report.paper) as this module prints it: IoU as fractions, MSE in m^2, time in ms."""
    names = {"volsmpl": "VolumetricSMPL (paper)", "coap": "COAP (paper)", "leap": "LEAP (paper)"}
    out = {}
    for key, row in paper.rows("1").items():
        out[names[key]] = dict(t_ms=row["t_ms"], mem=f"{row['gpu_gb']} G GPU",
                               **{k: round(row[k] / 100, 6) for k in ("iou_mean", "iou_surf", "iou_unif")},
                               mse_sdf=row["mse_sdf"], mse_abs_sdf=row["mse_abs_sdf"])
    return out


#: where `evaluate` puts the query points (EvalConfig.sampling)
SAMPLINGS = ("body", "parts")

#: the paper's Table 1 (fractions for IoU, m^2 for MSE, GPU memory in GB, time in ms), for reference
PAPER_TABLE1 = _paper_table1()


@dataclass
class EvalConfig:
    """Settings of one evaluation (defaults: 60k points per body, half uniform in the body's padded box, half
    within 1 cm of the surface, on our validation set; the paper does not publish the sampling behind its Table 1).

    Attributes:
        n_bodies: validation bodies (64). seed: validation seed (VAL_SEED) for bodies and points.
        n_points: query points per body (60k). surface_fraction: share of near-surface points (0.5).
        bbox_padding: padding of the uniform sampling box around the posed body, metres (0.05).
        surface_sigma: std of the Gaussian offsets of near-surface points, metres (0.01).
        gt_sign / gt_nsamples: sign mode and rays of `batch_mesh_sdf` ('ray_winding' with 3 rays).
        batch_size: bodies per predictor call. device: 'cpu' or 'cuda' for the predictor.
        cache_dir: ground-truth cache folder (None: `default_cache_dir()`); use_cache: read/write it.
        timing: measure time and memory (checkpoint/volume evaluations only); timing_repeats / timing_warmup:
            timed runs (median reported) and untimed warm-up runs; timing_threads: torch CPU threads of the
            timing subprocess (None: this process's torch.get_num_threads()). On a shared machine use 1:
            with other processes busy, OpenMP threads waiting for each other can slow a CPU query 100x.
        precision: the volume's decoder arithmetic during the evaluation ('full', 'bf16', 'tf32';
            `Volume.set_precision`), for the accuracy cost of a reduced-precision mode.
        sampling: where the points lie: 'body' (uniform in the body's padded bounding box, near-surface samples
            on the whole mesh: `validation.query_points`) or 'parts' (COAP's per-part sampling: the same number
            of points per body part, uniform in its padded box and near its own faces: `part_points`;
            bbox_padding does not apply, the boxes are the models' 12.5 %).
        encoder_draws: surface sample sets whose codes the encoder averages (`Volume.set_encoder_draws`) during
            the evaluation; None (default): the checkpoint's own (1 unless it was trained with more).
        refine_steps: test-time refinement of the part codes on the posed mesh's own surface
            (`Volume.set_code_refinement`, volsmpl.volume.code_refinement) during the evaluation; 0 (default): none.
        passes: how many of the model's learned code-refinement passes run (`Volume.set_passes`); None (default):
            all it has.
    """

    n_bodies: int = 64
    seed: int = VAL_SEED
    n_points: int = 60000
    surface_fraction: float = 0.5
    bbox_padding: float = 0.05
    surface_sigma: float = 0.01
    gt_sign: str = "ray_winding"
    gt_nsamples: int = 3
    batch_size: int = 8
    device: str = "cpu"
    cache_dir: Optional[str] = None
    use_cache: bool = True
    timing: bool = False
    timing_repeats: int = 10
    timing_warmup: int = 3
    timing_threads: Optional[int] = None
    precision: str = "full"
    sampling: str = "body"
    encoder_draws: Optional[int] = None
    refine_steps: int = 0
    passes: Optional[int] = None

    def __post_init__(self):
        for name in ("n_bodies", "n_points", "batch_size", "timing_repeats"):
            v = getattr(self, name)
            if not isinstance(v, int) or isinstance(v, bool) or v < 1:
                raise ValueError(f"EvalConfig.{name} must be a positive integer, got {v!r}.")
        if not isinstance(self.timing_warmup, int) or self.timing_warmup < 0:
            raise ValueError(f"EvalConfig.timing_warmup must be an integer >= 0, got {self.timing_warmup!r}.")
        if self.timing_threads is not None and (not isinstance(self.timing_threads, int) or self.timing_threads < 1):
            raise ValueError(f"EvalConfig.timing_threads={self.timing_threads!r}: give a positive integer or None.")
        if not 0.0 < self.surface_fraction < 1.0:
            raise ValueError(f"EvalConfig.surface_fraction={self.surface_fraction} must lie strictly between 0 and 1 "
                             f"(0.5: half near the surface): each IoU column needs points of its own.")
        if not math.isfinite(self.surface_sigma) or self.surface_sigma < 0:
            raise ValueError(f"--surface-sigma {self.surface_sigma}: give a finite scale >= 0 in metres (default 0.01).")
        if not math.isfinite(self.bbox_padding) or self.bbox_padding < 0:
            raise ValueError(f"EvalConfig.bbox_padding={self.bbox_padding}: give a finite padding >= 0 in metres (0.05).")
        if self.encoder_draws is not None and (not isinstance(self.encoder_draws, int) or self.encoder_draws < 1):
            raise ValueError(f"--encoder-draws {self.encoder_draws}: give a positive number of surface sample sets.")
        if not isinstance(self.refine_steps, int) or isinstance(self.refine_steps, bool) or self.refine_steps < 0:
            raise ValueError(f"--refine-steps {self.refine_steps}: give an integer >= 0 (0: no code refinement).")
        if self.passes is not None and (not isinstance(self.passes, int) or isinstance(self.passes, bool)
                                        or self.passes < 0):
            raise ValueError(f"--passes {self.passes}: give an integer >= 0 (0: the encoder's codes as they are).")
        if self.sampling not in SAMPLINGS:
            raise ValueError(f"EvalConfig.sampling={self.sampling!r}: use one of {', '.join(SAMPLINGS)}.")
        n_surf = int(round(self.n_points * self.surface_fraction))
        if self.sampling == "body" and not 0 < n_surf < self.n_points:
            raise ValueError(f"--points {self.n_points} leaves the {'near-surface' if n_surf == 0 else 'uniform'} set "
                             f"empty at surface_fraction {self.surface_fraction}; give more points per body.")
        if self.device not in ("cpu", "cuda") and not str(self.device).startswith("cuda:"):
            raise ValueError(f"EvalConfig.device={self.device!r}: use 'cpu' or 'cuda'.")
        if self.precision not in PRECISIONS:
            raise ValueError(f"EvalConfig.precision={self.precision!r}: use one of {', '.join(PRECISIONS)}.")
        if self.precision == "tf32" and not str(self.device).startswith("cuda"):
            raise ValueError("precision tf32 runs on CUDA tensor cores: add --device cuda, or use --precision bf16 "
                             "or full on the CPU.")


@dataclass
class EvalResult:
    """Outcome of `evaluate`: metrics (means over bodies), per-body values, timings, resources and provenance
    (meta: `volsmpl.io.provenance.machine_info`)."""

    name: str
    metrics: Dict[str, float]
    per_body: Dict[str, list]
    config: dict
    validation_digest: str
    points_digest: str
    seconds: Dict[str, float]
    resources: Optional[dict] = None
    extra: dict = field(default_factory=dict)
    meta: dict = field(default_factory=dict)

    def to_dict(self) -> dict:
        d = dataclasses.asdict(self)
        d["paper_table1"] = PAPER_TABLE1
        return d


