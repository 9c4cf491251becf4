"""DDPM with a cosine schedule (Nichol & Dhariwal 2021) and an x0-predicting denoiser, as EgoHMR samples it,
with the collision guidance of supp. eq. D.2:

    theta_{t-1} ~ N(mu_t(theta_t, theta0_hat) - a Sigma_t grad J, Sigma_t)

(the paper writes `+ a Sigma_t grad J` with J a score to raise; J here is the collision penalty to lower, so the
step goes down its gradient). In the last `plain_steps` steps the gradient is scaled by `a` alone (`Sigma_t`
left out, so the guidance does not vanish as Sigma_t -> 0).

    sched = Schedule(50)
    xt = sched.q_sample(x0, t, noise)                             # training input
    x = sample(denoise, (B, D), sched, generator=g, guide=guide)  # denoise(x_t, t) -> x0_hat; guide -> gradient
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import torch


class Schedule:
    """The cosine noise schedule with T steps: betas, cumulative alphas and the DDPM posterior coefficients.

    Shape: every table is (T,), indexed by the step t in [0, T) (t = T-1 is the noisiest)."""

    def __init__(self, T: int = 50, s: float = 0.008, max_beta: float = 0.999):
        if int(T) != T or T < 1:
            raise ValueError(f"the number of diffusion steps must be a positive integer, got {T}")
        self.T = int(T)
        f = lambda u: math.cos((u / T + s) / (1 + s) * math.pi / 2) ** 2  # noqa: E731
        betas = torch.tensor([min(1 - f(i + 1) / f(i), max_beta) for i in range(T)], dtype=torch.float64)
        alphas = 1 - betas
        ab = torch.cumprod(alphas, 0)
        ab_prev = torch.cat([torch.ones(1, dtype=torch.float64), ab[:-1]])
        self.betas, self.alphas_cumprod, self.alphas_cumprod_prev = betas, ab, ab_prev
        # posterior q(x_{t-1} | x_t, x0) = N(c0 x0 + ct x_t, var)
        self.posterior_var = betas * (1 - ab_prev) / (1 - ab)
        self.coef_x0 = betas * ab_prev.sqrt() / (1 - ab)
        self.coef_xt = (1 - ab_prev) * alphas.sqrt() / (1 - ab)

    def _at(self, table: torch.Tensor, t: torch.Tensor, like: torch.Tensor) -> torch.Tensor:
        v = table.to(like.device)[t].to(like.dtype)
        return v.reshape(-1, *([1] * (like.ndim - 1)))

    def q_sample(self, x0: torch.Tensor, t: torch.Tensor, noise: torch.Tensor) -> torch.Tensor:
        """x_t = sqrt(ab_t) x0 + sqrt(1 - ab_t) noise. Shape: x0, noise (B, D); t (B,) long -> (B, D)."""
        ab = self._at(self.alphas_cumprod, t, x0)
        return ab.sqrt() * x0 + (1 - ab).sqrt() * noise

    def posterior(self, x0_hat: torch.Tensor, xt: torch.Tensor, t: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Mean and variance of q(x_{t-1} | x_t, x0 = x0_hat). Shape: (B, D), (B, D), (B,) -> (B, D), (B, 1)."""
        mean = self._at(self.coef_x0, t, xt) * x0_hat + self._at(self.coef_xt, t, xt) * xt
        return mean, self._at(self.posterior_var, t, xt)


@dataclass
class Guidance:
    """Collision guidance of the sampler.

    Attributes:
        gradient: fn(x_t, x0_hat, t) -> dJ/dx (B, D), the collision penalty's gradient (volsmpl.apps.egohmr.guidance).
        scale: a (paper: 30 for VolumetricSMPL, 0.4 for COAP).
        steps: guided steps, the last ones (paper 10; the authors' code guides t <= 10, i.e. 11).
        plain_steps: of those, the last ones whose step is `plain_factor * a * grad` without Sigma_t (paper 5).
        plain_factor: 1 (paper) or 0.01 (the authors' code).
        pelvis: the gradient call also moves the pelvis (guidance.CollisionScore.moves_pelvis), so it is made in
            every guided step even where scale is 0 (the pose then unguided).
    """

    gradient: Callable
    scale: float
    steps: int = 10
    plain_steps: int = 5
    plain_factor: float = 1.0
    pelvis: bool = False

    def step(self, x_t: torch.Tensor, x0_hat: torch.Tensor, t: int, var: torch.Tensor) -> torch.Tensor | None:
        """The shift to add to the posterior mean at step t (None when step t is not guided)."""
        if t >= self.steps or (self.scale == 0 and not self.pelvis):
            return None
        g = self.gradient(x_t, x0_hat, t)
        if self.scale == 0:
            return None
        if t < self.plain_steps:
            return -self.plain_factor * self.scale * g
        return -self.scale * var * g


def sample(denoise: Callable, shape: tuple, schedule: Schedule, generator: torch.Generator | None = None,
           guide: Guidance | None = None, device=None, dtype=torch.float32, x_T: torch.Tensor | None = None,
           noises: torch.Tensor | None = None, bar: Callable | None = None) -> torch.Tensor:
    """Ancestral DDPM sampling from x_T ~ N(0, I) down to x_0.

    Args:
        denoise: fn(x_t (B, D), t (B,) long) -> x0_hat (B, D).
        shape: (B, D).
        generator: the noise's generator (the same generator state gives the same samples for every guide).
        guide: collision guidance, or None.
        x_T, noises: optional fixed start (B, D) and per-step noises (T, B, D) (tests).
        bar: wraps the steps' iterable (e.g. a progress bar: volsmpl.apps.progress.progress); None: plain.
    Returns:
        x_0 (B, D).
    """
    T = schedule.T
    # noise drawn by the (CPU) generator, then moved: the same samples on every device
    x = torch.randn(shape, generator=generator, dtype=dtype).to(device) if x_T is None else x_T
    if noises is None:
        noises = torch.randn((T, *shape), generator=generator, dtype=dtype).to(x.device)
    steps = range(T - 1, -1, -1)
    for t in (steps if bar is None else bar(steps)):
        tt = torch.full((shape[0],), t, dtype=torch.long, device=x.device)
        with torch.no_grad():
            x0_hat = denoise(x, tt)
            mean, var = schedule.posterior(x0_hat, x, tt)
        if guide is not None:
            shift = guide.step(x, x0_hat, t, var)
            if shift is not None:
                mean = mean + shift.detach()
        x = mean + var.sqrt() * noises[t] if t > 0 else mean
    return x


__all__ = ["Schedule", "Guidance", "sample"]
