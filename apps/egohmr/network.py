"""The networks of the egocentric app: conditioning encoders, the deterministic regressor and the diffusion denoiser.

EgoHMR's split: translation and shape are regressed deterministically from the image evidence; the pose is
modelled by a conditional diffusion model. Here the image evidence is the 2D keypoints (24 joints, normalised by
the intrinsics, with confidences) and the scene evidence a PointNet feature of scene points around the regressed
pelvis, expressed relative to it.

    net = EgoNet(EgoConfig())
    c_kp = net.keypoints(kp)                    # kp (B, 24, 3) -> (B, W)
    pelvis, betas, pose_reg = net.regress(c_kp) # (B, 3), (B, 10), (B, 144): the no-diffusion baseline's pose
    c = net.condition(c_kp, scene, pelvis)      # scene (B, P, 3) relative to `pelvis`
    x0_hat = net.denoise(x_t, t, c)             # (B, 144)
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import torch
from torch import nn

from .pose import NUM_JOINTS, POSE_DIM


@dataclass
class EgoConfig:
    """Network sizes and the data the network was trained for."""

    width: int = 256          # denoiser and regressor hidden width
    blocks: int = 4           # residual blocks of the denoiser
    cond_width: int = 128     # keypoint and scene feature widths
    scene_points: int = 256   # scene points fed to the scene encoder
    scene_size: float = 2.0   # side of the cube around the pelvis they come from (m)
    steps: int = 50           # diffusion steps
    num_betas: int = 10

    @classmethod
    def from_dict(cls, d: dict) -> "EgoConfig":
        known = {k: v for k, v in d.items() if k in cls.__dataclass_fields__}
        return cls(**known)

    def to_dict(self) -> dict:
        return asdict(self)


def timestep_embedding(t: torch.Tensor, dim: int) -> torch.Tensor:
    """Sinusoidal embedding of integer steps. Shape: (B,) -> (B, dim)."""
    half = dim // 2
    freqs = torch.exp(-math.log(10000.0) * torch.arange(half, dtype=torch.float32, device=t.device) / half)
    a = t.float()[:, None] * freqs[None]
    return torch.cat([a.sin(), a.cos()], dim=-1)


class ResBlock(nn.Module):
    """x + MLP(LayerNorm(x) modulated by the conditioning c)."""

    def __init__(self, width: int, cond: int):
        super().__init__()
        self.norm = nn.LayerNorm(width)
        self.film = nn.Linear(cond, 2 * width)
        self.fc1, self.fc2 = nn.Linear(width, width), nn.Linear(width, width)

    def forward(self, x: torch.Tensor, c: torch.Tensor) -> torch.Tensor:
        scale, shift = self.film(c).chunk(2, dim=-1)
        h = self.norm(x) * (1 + scale) + shift
        return x + self.fc2(torch.relu(self.fc1(torch.relu(h))))


class PointEncoder(nn.Module):
    """PointNet over scene points relative to the pelvis: shared per-point MLP, max pool. (B, P, 3) -> (B, W)."""

    def __init__(self, width: int):
        super().__init__()
        self.mlp = nn.Sequential(nn.Linear(3, 64), nn.ReLU(), nn.Linear(64, 128), nn.ReLU(), nn.Linear(128, width))
        self.out = nn.Sequential(nn.ReLU(), nn.Linear(width, width))

    def forward(self, pts: torch.Tensor) -> torch.Tensor:
        return self.out(self.mlp(pts).amax(dim=1))


class EgoNet(nn.Module):
    """Keypoint and scene encoders, the regressor (pelvis, betas, pose) and the x0-predicting denoiser."""

    def __init__(self, config: EgoConfig | None = None):
        super().__init__()
        self.config = cfg = config or EgoConfig()
        W, C = cfg.width, cfg.cond_width
        self.kp_enc = nn.Sequential(nn.Linear(NUM_JOINTS * 3, W), nn.ReLU(), nn.Linear(W, W), nn.ReLU(),
                                    nn.Linear(W, C))
        self.reg = nn.Sequential(nn.Linear(C, W), nn.ReLU(), nn.Linear(W, W), nn.ReLU(),
                                 nn.Linear(W, 3 + cfg.num_betas + POSE_DIM))
        self.scene_enc = PointEncoder(C)
        cond = 3 * C
        self.t_emb = nn.Sequential(nn.Linear(128, C), nn.SiLU(), nn.Linear(C, C))
        self.pelvis_enc = nn.Linear(3, C)
        self.inp = nn.Linear(POSE_DIM, W)
        self.blocks = nn.ModuleList(ResBlock(W, cond + C) for _ in range(cfg.blocks))
        self.head = nn.Sequential(nn.LayerNorm(W), nn.Linear(W, POSE_DIM))

    def keypoints(self, kp: torch.Tensor) -> torch.Tensor:
        """Keypoint feature. Shape: (B, 24, 3) normalised (x, y, conf) -> (B, cond_width)."""
        if kp.shape[1:] != (NUM_JOINTS, 3):
            raise ValueError(f"keypoints must be (B, {NUM_JOINTS}, 3) (x, y, confidence), got {tuple(kp.shape)}")
        return self.kp_enc(kp.reshape(len(kp), -1))

    def regress(self, c_kp: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """Pelvis position (camera frame, metres), betas and the regressed pose. Shape: (B, C) -> (B, 3), (B, 10),
        (B, 144). The pelvis is parametrised as (x/z, y/z, log z) so depth stays positive."""
        o = self.reg(c_kp)
        z = torch.exp(o[:, 2:3].clamp(-3.0, 3.0) + math.log(1.5))
        pelvis = torch.cat([o[:, :2] * z, z], dim=-1)
        nb = self.config.num_betas
        return pelvis, o[:, 3:3 + nb], o[:, 3 + nb:] + _IDENTITY6.to(o)

    def condition(self, c_kp: torch.Tensor, scene: torch.Tensor, pelvis: torch.Tensor) -> torch.Tensor:
        """The denoiser's conditioning: keypoint feature, scene feature, pelvis. Shape: -> (B, 3 * cond_width)."""
        return torch.cat([c_kp, self.scene_enc(scene), self.pelvis_enc(pelvis)], dim=-1)

    def denoise(self, x_t: torch.Tensor, t: torch.Tensor, cond: torch.Tensor) -> torch.Tensor:
        """x0_hat from the noisy pose x_t at step t. Shape: (B, 144), (B,), (B, 3C) -> (B, 144)."""
        c = torch.cat([cond, self.t_emb(timestep_embedding(t, 128))], dim=-1)
        h = self.inp(x_t)
        for blk in self.blocks:
            h = blk(h, c)
        return self.head(h) + _IDENTITY6.to(h)


_IDENTITY6 = torch.tensor([1.0, 0.0, 0.0, 0.0, 1.0, 0.0]).repeat(NUM_JOINTS)

__all__ = ["EgoConfig", "EgoNet", "timestep_embedding"]
