import math

import pytest
import torch

from volsmpl.nn.posenc import PositionalEncoding, positional_encoding, posenc_dim


def test_levels_two_layout():
    x = torch.randn(4, 5, 3, dtype=torch.float64)
    y = positional_encoding(x, 2)
    assert y.shape == (4, 5, 15) and posenc_dim(3, 2) == 15
    expected = torch.cat([x, torch.sin(math.pi * x), torch.cos(math.pi * x),
                          torch.sin(2 * math.pi * x), torch.cos(2 * math.pi * x)], -1)
    torch.testing.assert_close(y, expected)


def test_levels_zero_is_identity():
    x = torch.randn(7, 3)
    assert torch.equal(positional_encoding(x, 0), x)
    assert posenc_dim(3, 0) == 3


def test_known_values():
    y = positional_encoding(torch.tensor([[0.5, 0.0, 1.0]], dtype=torch.float64), 1)
    torch.testing.assert_close(y[0], torch.tensor([0.5, 0.0, 1.0, 1.0, 0.0, 0.0, 0.0, 1.0, -1.0],
                                                  dtype=torch.float64), atol=1e-12, rtol=0)


def test_module_and_errors():
    m = PositionalEncoding(3)
    assert m.out_dim == 21 and m(torch.zeros(2, 3)).shape == (2, 21)
    with pytest.raises(ValueError, match="levels"):
        PositionalEncoding(-1)
    with pytest.raises(ValueError, match=r"\(\.\.\., 3\)"):
        m(torch.zeros(2, 4))
