"""Shape sampler for the default body: realistic human shapes drawn from Anny's calibrated population.

The exporter sampled N bodies with Anny's WHO-calibrated shape distribution (morphological age
13-80 years, gender uniform in [0, 1] with 0 = male, 1 = female; height 1.38-2.03 m) and projected
each onto the default body's shape space. `sample_betas` draws from that population, optionally
restricted to a phenotype range, so the betas it returns are those of real Anny bodies, not of an
unbounded Gaussian.
"""
from __future__ import annotations

from functools import lru_cache

import numpy as np
import torch

from .model import ASSETS

SHAPE_BANK_FILE = ASSETS / "anny_shapes.npz"
PHENOTYPES = ("gender", "age", "muscle", "weight", "height", "proportions")


@lru_cache(maxsize=1)
def shape_bank() -> dict:
    """phenotypes (N, 6) in Anny's [0, 1] units, betas (N, NB), heights_m (N,) of the sampled population."""
    if not SHAPE_BANK_FILE.exists():
        raise FileNotFoundError(f"{SHAPE_BANK_FILE} is missing; regenerate the default body with `volsmpl body export`.")
    with np.load(SHAPE_BANK_FILE) as d:
        return {k: d[k].copy() for k in d.files}


def sample_betas(n: int, num_betas: int = 10, seed: int | None = None, height_range: tuple | None = None,
                 gender_range: tuple | None = None, jitter: float = 0.0) -> torch.Tensor:
    """Betas of n bodies drawn (with replacement) from the calibrated population.

    Args:
        n: number of bodies; num_betas: leading shape coefficients returned (<= bank's NB).
        height_range: (min_m, max_m) keep only bodies of this height; gender_range: (lo, hi) in [0, 1]
            (0 = male, 1 = female); jitter: std of Gaussian noise added to the betas (0 = exact Anny bodies).
    Returns:
        (n, num_betas) float32.
    """
    bank = shape_bank()
    betas, ph, h = bank["betas"], bank["phenotypes"], bank["heights_m"]
    if num_betas > betas.shape[1]:
        raise ValueError(f"num_betas={num_betas} but the shape bank holds {betas.shape[1]} coefficients.")
    keep = np.ones(len(betas), bool)
    if height_range is not None:
        keep &= (h >= height_range[0]) & (h <= height_range[1])
    if gender_range is not None:
        g = ph[:, PHENOTYPES.index("gender")]
        keep &= (g >= gender_range[0]) & (g <= gender_range[1])
    if not keep.any():
        raise ValueError(f"no body of the population matches height_range={height_range}, gender_range={gender_range}; "
                         f"heights span {h.min():.2f}-{h.max():.2f} m.")
    rng = np.random.default_rng(seed)
    rows = rng.choice(np.nonzero(keep)[0], size=n, replace=True)
    out = betas[rows, :num_betas].astype(np.float64)
    if jitter > 0:
        out = out + rng.standard_normal(out.shape) * jitter
    return torch.as_tensor(out, dtype=torch.float32)
