"""Shared fixtures: the default body, a small random-weight volume, random poses."""
from __future__ import annotations

import pytest
import torch

import volsmpl
from volsmpl.nn.config import VolumeConfig

torch.set_num_threads(2)


def pytest_collection_modifyitems(config, items):
    for item in items:
        if item.get_closest_marker("cuda") is not None and not torch.cuda.is_available():
            item.add_marker(pytest.mark.skip(reason="no CUDA GPU"))


def pytest_runtest_setup(item):
    """A test that needs the shipped checkpoint fails (not skips) when the file is missing."""
    if item.get_closest_marker("needs_checkpoint") is not None:
        from volsmpl.models import model_kind
        path = model_kind("volsmpl").default_checkpoint.with_suffix(".safetensors")
        if not path.exists():
            pytest.fail(f"the shipped checkpoint {path} is missing: restore it (git checkout core/assets) before "
                        "running the tests that need it", pytrace=False)


@pytest.fixture(scope="session")
def body():
    return volsmpl.create_body()


@pytest.fixture(scope="session")
def tiny_config():
    return VolumeConfig(latent_dim=16, encoder_hidden=16, encoder_blocks=2, n_surface_samples=64,
                        decoder_hidden=16, nbw_rank=2)


def random_pose(B: int, scale: float = 0.4, seed: int = 0, dtype=torch.float32, num_betas: int = 10):
    g = torch.Generator().manual_seed(seed)
    return dict(
        betas=torch.randn(B, num_betas, generator=g, dtype=dtype),
        global_orient=torch.randn(B, 3, generator=g, dtype=dtype) * scale,
        body_pose=torch.randn(B, 69, generator=g, dtype=dtype) * scale,
        transl=torch.randn(B, 3, generator=g, dtype=dtype) * 0.2,
    )
