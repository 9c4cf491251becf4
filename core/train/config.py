"""Training configuration of `volsmpl train`: TrainConfig (hyperparameters, their validation,
JSON round trip via to_dict/from_dict) and the learning-rate schedule lr_at.

The loss terms these fields control are described in `volsmpl.train.loop`'s module docstring.
"""
from __future__ import annotations

import dataclasses
import json
import math
import numbers
from dataclasses import dataclass, field
from pathlib import Path

from volsmpl.body.poses import check_pose_mode
from volsmpl.geometry.groundtruth import GT_BACKENDS, SIGN_MODES
from volsmpl.volume.models import learned_models, model_kind
from volsmpl.nn.config import VolumeConfig


@dataclass
class TrainConfig:
    """Training hyperparameters (paper values as defaults where the paper gives them)."""

    steps: int = 450_000            # paper: 15 epochs = 450k iterations
    batch_size: int = 8             # paper: 8
    lr: float = 1e-4                # paper: 1e-4 annealed to 1e-5
    lr_final: float = 1e-5
    anneal_start: int = 0           # step at which the annealing from lr starts (a fine-tuning phase after --init)
    ema_decay: float = 0.0          # > 0: keep an exponential moving average of the weights; checkpoints' model is the EMA
    n_uniform: int = 256            # per part, uniform in its padded box (paper)
    n_surface: int = 256            # per part, near the surface (paper)
    surface_sigma: tuple = (0.01, 0.05)  # metres; see volsmpl.geometry.groundtruth
    n_body_surface: int = 0         # per body, near the whole surface, area-weighted (the eval's near-surface law)
    body_surface_sigma: tuple = (0.005, 0.01)  # metres, offsets of those
    sign_tau: float = 0.01          # metres: scale of the sign term (STE gradient 1/tau; logistic logit -d/tau)
    sign_loss: str = "ste"          # 'ste' (eq. 3's l2 of signs, straight-through) or 'logistic' (module docstring)
    sign_weight: float = 1.0        # weight of the sign term
    abs_weight: float = 1e4         # |SDF| term in cm^2
    residual: str = "signed"        # distance term: 'signed' (d~ - d)^2 or 'abs' (|d~| - |d|)^2 (eq. 3 literally)
    pose_mode: str = "realistic"    # training poses: 'realistic', 'extreme' or 'mixed' (volsmpl.body.poses.sample_euler)
    extreme_fraction: float = 0.5   # pose_mode 'mixed': share of bodies with extreme poses
    contact_fraction: float = 0.0   # share of bodies in self-contact poses instead (volsmpl.body.poses)
    n_contact_surface: int = 0      # per body, near its self-contact vertices (volsmpl.body.contact_regions)
    contact_sigma: tuple = (0.005, 0.01)  # metres, offsets of those
    global_orient_scale: float = 0.0  # rad sd of random global orientation (parts are in local frames anyway)
    gt_sign: str = "ray_winding"    # ground-truth sign: winding number (self-overlaps inside) counted along rays
                                    # ('ray_winding', exact, fastest), or libigl's 'fast_winding' / 'winding'; or 'raycast' parity
    gt_rays: int = 3                # rays of the vote for gt_sign='ray_winding' / 'raycast' (odd)
    gt_backend: str = "auto"        # ground truth on 'open3d' (CPU) or 'torch' (the training device, no open3d/libigl);
                                    # 'auto': torch on a GPU, open3d on the CPU when it imports (groundtruth.batch_sdf)
    micro_batch: int = 2            # bodies per forward/backward; gradients accumulate to the same full-batch step
    encoder_bf16: bool = False      # bfloat16 autocast of the PointNet encoder (CPU speed; see VolumetricSMPLNet)
    seed: int = 0
    ckpt_every: int = 200
    log_every: int = 10
    keep_ckpts: int = 2
    keep_every: int = 0             # > 0: never prune checkpoints whose step is a multiple of this (for later evaluation)
    num_threads: int = 0            # torch CPU threads (0: leave torch's default)
    num_workers: int = 0            # processes that make batches ahead of the step (0: in the training process)
    train_weights: str = "all"      # 'all', or 'refiner': only the learned code refinement's weights (model.refiner_iters
                                    # > 0) train, the encoder and decoders stay as --init gave them
    model_kind: str = "volsmpl"     # 'volsmpl' (SDF, eq. 3) or 'coap' (occupancy baseline, binary cross-entropy)
    model: object = field(default_factory=VolumeConfig)  # VolumeConfig, or CoapConfig for model_kind 'coap'

    def __post_init__(self):
        check_numbers(self)
        if self.gt_sign not in SIGN_MODES:
            raise ValueError(f"gt_sign must be one of {SIGN_MODES}, got {self.gt_sign!r}")
        if self.gt_backend not in GT_BACKENDS:
            raise ValueError(f"gt_backend must be one of {GT_BACKENDS}, got {self.gt_backend!r}")
        if self.num_workers < 0:
            raise ValueError(f"num_workers must be >= 0 (0 makes batches in the training process), got {self.num_workers}")
        if not 0.0 <= self.ema_decay < 1.0:
            raise ValueError(f"ema_decay must be in [0, 1) (0 turns the average off), got {self.ema_decay}")
        if not 0 <= self.anneal_start < self.steps:
            raise ValueError(f"anneal_start must be in [0, steps={self.steps}), got {self.anneal_start}")
        if self.sign_loss not in ("ste", "logistic"):
            raise ValueError(f"sign_loss must be 'ste' or 'logistic', got {self.sign_loss!r}")
        if not (self.sign_tau > 0 and self.sign_weight >= 0):
            raise ValueError(f"sign_tau={self.sign_tau} must be > 0 (metres) and sign_weight={self.sign_weight} >= 0.")
        check_pose_mode(self.pose_mode, self.extreme_fraction, self.contact_fraction)
        if self.residual not in ("signed", "abs"):
            raise ValueError(f"residual must be 'signed' or 'abs', got {self.residual!r}")
        if self.model_kind not in learned_models():
            raise ValueError(f"model_kind must be one of {', '.join(learned_models())} (a network), got {self.model_kind!r}")
        cls = model_kind(self.model_kind).config_class()
        if not isinstance(self.model, cls):
            if self.model != VolumeConfig():
                raise ValueError(f"model_kind={self.model_kind!r} needs a {cls.__name__} as model, got a {type(self.model).__name__}.")
            self.model = cls()
        if self.train_weights not in ("all", "refiner"):
            raise ValueError(f"train_weights must be 'all' or 'refiner', got {self.train_weights!r}")
        if self.train_weights == "refiner" and not getattr(self.model, "refiner_iters", 0):
            raise ValueError("train_weights='refiner' trains the learned code refinement, but the model has none: "
                             "set model.refiner_iters >= 1 (a VolumetricSMPL model), or train_weights='all'.")

    def to_dict(self) -> dict:
        d = {f.name: getattr(self, f.name) for f in dataclasses.fields(self) if f.name != "model"}
        d["surface_sigma"] = list(self.surface_sigma)
        d["body_surface_sigma"] = list(self.body_surface_sigma)
        d["contact_sigma"] = list(self.contact_sigma)
        d["model"] = self.model.to_dict()
        return d

    @classmethod
    def from_dict(cls, d: dict) -> "TrainConfig":
        d = dict(d)
        known = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(d) - known)
        if unknown:
            raise ValueError(f"unknown training config key(s) {unknown}; valid keys: {sorted(known)}")
        kind = d.get("model_kind", "volsmpl")
        if kind not in learned_models():
            raise ValueError(f"model_kind must be one of {', '.join(learned_models())} (a network), got {kind!r}")
        if kind != "volsmpl" or "model" in d:
            d["model"] = model_kind(kind).config_from_dict(d.get("model", {}))
        for key in ("surface_sigma", "body_surface_sigma", "contact_sigma"):
            if key in d:
                d[key] = tuple(d[key])
        return cls(**d)


#: integer fields and their smallest value
_INTS = {"steps": 1, "batch_size": 1, "micro_batch": 1, "n_uniform": 0, "n_surface": 0, "n_body_surface": 0,
         "n_contact_surface": 0,
         "gt_rays": 1, "seed": 0, "ckpt_every": 1, "log_every": 1, "keep_ckpts": 1, "keep_every": 0,
         "num_threads": 0,
         "num_workers": 0, "anneal_start": 0}
#: real fields: (smallest value, whether it must be above it rather than at least it)
_REALS = {"lr": (0.0, True), "lr_final": (0.0, True), "sign_tau": (0.0, True), "sign_weight": (0.0, False),
          "abs_weight": (0.0, False), "global_orient_scale": (0.0, False), "extreme_fraction": (0.0, False),
          "contact_fraction": (0.0, False),
          "ema_decay": (0.0, False)}


def same_weights_config(held: dict, model) -> bool:
    """Whether a checkpoint's model config `held` (as stored: keys it lacks take their defaults) describes the
    weights of `model` (a VolumeConfig or CoapConfig): every field equal but `encoder_draws`, which says how the
    encoder is run, not what it holds (a phase may train on with more surface sample sets than the one before)."""
    try:
        held_cfg = type(model).from_dict(held)
    except (TypeError, ValueError):   # another kind's config, or keys this release does not know
        return False
    return dataclasses.replace(held_cfg, encoder_draws=model.encoder_draws) == model


REFINER_FIELDS = ("refiner_iters", "refiner_hidden", "refiner_blocks")


def adds_refiner(held: dict, model) -> bool:
    """Whether `model` is a checkpoint's model config `held` with learned code refinement passes added: the
    checkpoint has fewer passes (refiner_iters, possibly 0), the passes it has are of `model`'s width and depth, and
    every other field of `same_weights_config` is equal. Its weights then load from the checkpoint and the added
    passes start fresh (an untrained pass leaves the codes as they are)."""
    if not getattr(model, "refiner_iters", 0):
        return False
    try:
        held_cfg = type(model).from_dict(held)
    except (TypeError, ValueError):
        return False
    if held_cfg.refiner_iters >= model.refiner_iters:
        return False
    keep = {f: getattr(model, f) for f in REFINER_FIELDS} if held_cfg.refiner_iters == 0 else {
        "refiner_iters": model.refiner_iters}
    return dataclasses.replace(held_cfg, encoder_draws=model.encoder_draws, **keep) == model


def check_numbers(cfg: "TrainConfig") -> None:
    """ValueError / TypeError in one line for a numeric field of the wrong type, NaN, inf or out of range."""
    for name, least in _INTS.items():
        v = getattr(cfg, name)
        if isinstance(v, bool) or not isinstance(v, numbers.Integral):
            raise TypeError(f"training config: {name} must be an integer, got {type(v).__name__} {v!r}.")
        if v < least:
            raise ValueError(f"training config: {name}={v} must be >= {least}.")
    for name, (least, strict) in _REALS.items():
        v = getattr(cfg, name)
        if isinstance(v, bool) or not isinstance(v, numbers.Real):
            raise TypeError(f"training config: {name} must be a number, got {type(v).__name__} {v!r}.")
        if not math.isfinite(v) or v < least or (strict and v == least):
            raise ValueError(f"training config: {name}={v} must be a finite number {'>' if strict else '>='} {least}.")
    if cfg.n_uniform + cfg.n_surface + cfg.n_body_surface + cfg.n_contact_surface == 0:
        raise ValueError("training config: n_uniform, n_surface, n_body_surface and n_contact_surface are all 0: "
                         "no query points to train on.")
    if cfg.gt_rays % 2 == 0:
        raise ValueError(f"training config: gt_rays={cfg.gt_rays} must be odd (a majority vote of rays).")
    for name in ("surface_sigma", "body_surface_sigma", "contact_sigma"):  # the standard deviations of a mixture (training_queries)
        v = getattr(cfg, name)
        if not (isinstance(v, (tuple, list)) and len(v) > 0 and all(
                isinstance(x, numbers.Real) and not isinstance(x, bool) and math.isfinite(x) and x >= 0 for x in v)):
            raise ValueError(f"training config: {name}={v!r} must be one or more finite standard deviations >= 0 "
                             f"(metres), e.g. (0.01, 0.05).")


def lr_at(cfg: TrainConfig, step: int) -> float:
    """Exponential annealing from lr (at step cfg.anneal_start and before) to lr_final (at cfg.steps)."""
    t = (step - cfg.anneal_start) / (cfg.steps - cfg.anneal_start)
    return cfg.lr * (cfg.lr_final / cfg.lr) ** min(1.0, max(0.0, t))


def read_config_file(path, what: str = "--config") -> dict:
    """The JSON object of a training-config file; ValueError in one line naming the file for a missing, unreadable
    or non-JSON file, or one that does not hold an object of TrainConfig fields."""
    try:
        text = Path(path).read_text()
    except OSError as e:
        raise ValueError(f"{what} {path}: cannot read it ({e.strerror or type(e).__name__}); give a JSON file of "
                         f"training config fields (a run's config.json, or a checkpoint JSON's "
                         f"meta.training.train_config).") from None
    try:
        d = json.loads(text)
    except (json.JSONDecodeError, UnicodeDecodeError) as e:
        raise ValueError(f"{what} {path} is not valid JSON ({e}); give a JSON object of training config fields.") from None
    if not isinstance(d, dict):
        raise ValueError(f"{what} {path} holds a JSON {type(d).__name__}, not an object of training config fields "
                         f"(e.g. {{\"batch_size\": 4}}).")
    return d


def parse_set(items) -> dict:
    """`--set KEY=VALUE ...` -> {key: value}: a VALUE that reads as JSON (numbers, true/false, lists, objects) is
    that value, anything else (gt_backend=torch, gt_sign=fast_winding) the string itself. ValueError in one line for
    an item without '=' or an unreadable list or object."""
    d = {}
    for kv in items:
        k, eq, v = kv.partition("=")
        if not eq or not k.strip():
            raise ValueError(f"--set {kv!r}: give KEY=VALUE, e.g. --set batch_size=4 gt_backend=torch.")
        try:
            d[k.strip()] = json.loads(v)
        except json.JSONDecodeError as e:
            if v.strip()[:1] in "[{":
                raise ValueError(f"--set {k.strip()}: {v!r} is not valid JSON ({e}); quote the whole item, e.g. "
                                 f"'surface_sigma=[0.01,0.05]' or 'model={{\"latent_dim\": 64}}'.") from None
            d[k.strip()] = v
    return d
