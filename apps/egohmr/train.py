"""`volsmpl egohmr train`: the regressor and the diffusion denoiser on the generated training frames (resumable).

    train(out="runs/egohmr", settings=TrainSettings(steps=4000))     # or: volsmpl egohmr train --out runs/egohmr

One loss per step over a batch of training frames:
- regressor: pelvis L1 + 0.1 betas L2 + 6D pose L2 + mean joint distance of its pose (forward kinematics with the
  true shape and pelvis): the deterministic translation and shape, and the no-diffusion pose baseline;
- denoiser (x0 prediction, cosine schedule, t uniform): 6D pose L2 + mean joint distance, conditioned on the
  keypoints, the pelvis and the scene crop around it; during training the pelvis (and so the crop's centre) is
  the true one plus N(0, pelvis_noise) per axis, standing in for the regressor's error at test time.

Checkpoints: OUT/model.{safetensors,json} (network, config, body fingerprint, step, settings, validation
MPJPE) and OUT/state.pt (optimiser, step, generator; tensors only, loaded with weights_only) written atomically
every `save_every` steps; `--resume` continues from them.
"""
from __future__ import annotations

import json
import math
import os
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import torch

from .diffusion import Schedule
from .network import EgoConfig, EgoNet
from .pose import pose_joints, rest_joints

DEFAULT_CHECKPOINT = Path(__file__).resolve().parent / "egohmr_anny"


@dataclass
class TrainSettings:
    steps: int = 4000
    batch: int = 64
    lr: float = 1e-3
    lr_min: float = 1e-5
    pelvis_noise: float = 0.1
    joint_weight: float = 1.0
    save_every: int = 500
    seed: int = 0
    threads: int | None = None
    device: str = "cpu"

    def check(self) -> None:
        for name in ("steps", "batch", "save_every"):
            v = getattr(self, name)
            if not isinstance(v, int) or v < 1:
                raise ValueError(f"egohmr train: {name} must be a positive integer, got {v!r}")
        for name in ("lr", "lr_min", "pelvis_noise", "joint_weight"):
            v = getattr(self, name)
            if not math.isfinite(v) or v < 0 or (name == "lr" and v == 0):
                raise ValueError(f"egohmr train: {name} must be a finite {'positive' if name == 'lr' else 'non-negative'} number, got {v!r}")


def losses(net: EgoNet, body, d: dict, sched: Schedule, gen: torch.Generator, s: TrainSettings) -> dict:
    """The step's loss terms on a batch dict (dataset.frame_tensors rows plus 'rest' joints)."""
    B = len(d["kp"])
    c_kp = net.keypoints(d["kp"])
    pelvis_hat, betas_hat, pose_reg = net.regress(c_kp)
    rel_gt = d["joints"] - d["joints"][:, :1]

    def joint_err(x):
        J = pose_joints(body, d["betas"], x, torch.zeros_like(d["pelvis"]), rest=d["rest"])
        return (J - rel_gt).norm(dim=-1).mean()

    out = {"pelvis": (pelvis_hat - d["pelvis"]).abs().sum(-1).mean(),
           "betas": 0.1 * ((betas_hat - d["betas"]) ** 2).mean(),
           "reg_pose": ((pose_reg - d["pose"]) ** 2).mean(),
           "reg_joints": s.joint_weight * joint_err(pose_reg)}
    dev = d["kp"].device  # random draws by the CPU generator, then moved: the same run on every device
    shift = (torch.randn(B, 3, generator=gen) * s.pelvis_noise).to(dev)
    cond = net.condition(c_kp.detach(), d["scene"] - shift[:, None], d["pelvis"] + shift)
    t = torch.randint(0, sched.T, (B,), generator=gen).to(dev)
    noise = torch.randn(d["pose"].shape, generator=gen).to(dev)
    x0_hat = net.denoise(sched.q_sample(d["pose"], t, noise), t, cond)
    out["diff_pose"] = ((x0_hat - d["pose"]) ** 2).mean()
    out["diff_joints"] = s.joint_weight * joint_err(x0_hat)
    return out


def save_model(out: Path, net: EgoNet, opt, step: int, gen: torch.Generator, s: TrainSettings, body, extra: dict) -> None:
    from volsmpl.io.checkpoint import save_checkpoint

    meta = {"body_fingerprint": body.fingerprint, "step": step, "settings": asdict(s), **extra}
    save_checkpoint(out / "model", net.state_dict(), net.config.to_dict(), meta)
    tmp = out / f"state.pt.tmp{os.getpid()}"
    torch.save({"step": torch.tensor(step), "gen": gen.get_state(), "opt": opt.state_dict()}, tmp)
    os.replace(tmp, out / "state.pt")


def load_model(path=None, body=None) -> tuple[EgoNet, dict]:
    """The network of a checkpoint (default: the shipped one) and its meta; refuses another body's checkpoint."""
    from volsmpl.io.checkpoint import load_checkpoint

    path = Path(path) if path is not None else DEFAULT_CHECKPOINT
    if not Path(str(path) + ".safetensors").is_file() and (path / "model.safetensors").is_file():
        path = path / "model"
    if not Path(str(path) + ".safetensors").is_file():
        raise FileNotFoundError(f"no egohmr checkpoint at {path}(.safetensors); train one with `volsmpl egohmr "
                                f"train --out runs/egohmr` and pass --checkpoint runs/egohmr")
    fp = body.fingerprint if body is not None else None
    state, cfg, meta = load_checkpoint(path, expected_fingerprint=fp)
    if "kp_enc.0.weight" not in state:
        raise ValueError(f"{path} is not an egohmr checkpoint (it holds a {cfg.get('model', 'volsmpl') if isinstance(cfg, dict) else 'different'} network); "
                         f"pass an egohmr checkpoint (volsmpl egohmr train)")
    net = EgoNet(EgoConfig.from_dict(cfg))
    net.load_state_dict(state)
    net.eval().requires_grad_(False)
    return net, meta


def train(out, settings: TrainSettings | None = None, config: EgoConfig | None = None, resume: bool = False,
          n_train: int | None = None, n_val: int = 64, log=print, body=None) -> Path:
    """Train into folder `out` (module docstring); returns the model path (without extension)."""
    import volsmpl
    from volsmpl.io.outputs import check_writable

    from .data import make_frames
    from .dataset import frame_tensors
    from .evaluate import regressor_and_sample_errors

    s = settings or TrainSettings()
    s.check()
    out = check_writable(out, "dir", "--out")
    if s.threads:
        torch.set_num_threads(s.threads)
    from volsmpl.runtime.devices import check_device

    dev = check_device(s.device)
    body = (body or volsmpl.create_body()).to(dev)
    torch.manual_seed(s.seed)
    net = EgoNet(config or EgoConfig()).to(dev)
    sched = Schedule(net.config.steps)
    opt = torch.optim.Adam(net.parameters(), lr=s.lr)
    gen = torch.Generator().manual_seed(s.seed)
    step, prior_seconds = 0, 0.0
    if resume and (out / "state.pt").is_file():
        net, meta = load_model(out / "model", body)
        net.to(dev).train().requires_grad_(True)
        opt = torch.optim.Adam(net.parameters(), lr=s.lr)
        st = torch.load(out / "state.pt", weights_only=True, map_location=dev)
        opt.load_state_dict(st["opt"])
        gen.set_state(st["gen"].cpu())
        step = int(st["step"])
        prior_seconds = float(meta.get("seconds", 0.0))
        log(f"resumed {out} at step {step}")
    elif resume:
        raise FileNotFoundError(f"--resume: no {out / 'state.pt'}; start without --resume")
    t0 = time.time()
    train_frames = make_frames("train", n_train, seed=s.seed)
    val_frames = make_frames("val", n_val, seed=s.seed)
    data = {k: v.to(dev) for k, v in frame_tensors(train_frames, net.config.scene_points, net.config.scene_size).items()}
    with torch.no_grad():
        data["rest"] = rest_joints(body, data["betas"])
    log(f"{len(train_frames)} training frames, {len(val_frames)} validation frames ({time.time() - t0:.0f} s)")
    n = len(train_frames)
    hist_path = out / "history.json"
    history = json.loads(hist_path.read_text()) if step and hist_path.is_file() else []
    t_train = time.time()
    while step < s.steps:
        lr = s.lr_min + 0.5 * (s.lr - s.lr_min) * (1 + math.cos(math.pi * step / s.steps))
        for g in opt.param_groups:
            g["lr"] = lr
        idx = torch.randint(0, n, (min(s.batch, n),), generator=gen).to(dev)
        terms = losses(net, body, {k: v[idx] for k, v in data.items()}, sched, gen, s)
        loss = sum(terms.values())
        if not torch.isfinite(loss):
            raise RuntimeError(f"egohmr train: the loss became {loss.item()} at step {step}; lower --lr")
        opt.zero_grad(set_to_none=True)
        loss.backward()
        torch.nn.utils.clip_grad_norm_(net.parameters(), 1.0)
        opt.step()
        step += 1
        if step % 100 == 0 or step == s.steps:
            log(f"step {step:6d}  loss {loss.item():.4f}  " + "  ".join(f"{k} {v.item():.4f}" for k, v in terms.items())
                + f"  lr {lr:.2e}")
        if step % s.save_every == 0 or step == s.steps:
            net.eval()
            val = regressor_and_sample_errors(net, body, val_frames, seed=s.seed)
            net.train()
            history.append({"step": step, **val})
            log(f"step {step:6d}  validation MPJPE regressor {val['regressor_mpjpe_mm']:.1f} mm "
                f"(invisible {val['regressor_invisible_mm']:.1f})  diffusion {val['diffusion_mpjpe_mm']:.1f} mm "
                f"(invisible {val['diffusion_invisible_mm']:.1f})")
            save_model(out, net, opt, step, gen, s, body, {"validation": history[-1], "train_frames": n,
                                                      "seconds": prior_seconds + time.time() - t_train})
            hist_path.write_text(json.dumps(history, indent=1))
    return out / "model"


__all__ = ["TrainSettings", "losses", "train", "save_model", "load_model", "DEFAULT_CHECKPOINT"]
