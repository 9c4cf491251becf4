"""Shape sampler: draws real population members, honours ranges, reproducible; heights match the body."""
from __future__ import annotations

import numpy as np
import pytest
import torch

from volsmpl.body.shapes import sample_betas, shape_bank


def test_draws_population_members():
    b = sample_betas(50, seed=0)
    bank = shape_bank()["betas"][:, :10]
    d = np.abs(b.numpy()[:, None] - bank[None]).max(-1).min(-1)
    assert b.shape == (50, 10) and d.max() < 1e-6
    assert torch.equal(b, sample_betas(50, seed=0)) and not torch.equal(b, sample_betas(50, seed=1))


def test_height_of_sampled_bodies(body):
    """A body drawn from a height range has that height (mesh extent in the T-pose, +-3 cm for the 10-beta truncation)."""
    betas = sample_betas(8, seed=2, height_range=(1.85, 2.1))
    v = body(betas=betas).vertices
    heights = (v[..., 1].amax(1) - v[..., 1].amin(1))
    assert (heights > 1.82).all(), heights
    small = body(betas=sample_betas(8, seed=2, height_range=(1.3, 1.5))).vertices
    assert ((small[..., 1].amax(1) - small[..., 1].amin(1)) < 1.53).all()


def test_bad_ranges():
    with pytest.raises(ValueError, match="no body"):
        sample_betas(3, height_range=(2.5, 3.0))
    with pytest.raises(ValueError, match="num_betas"):
        sample_betas(3, num_betas=99)
