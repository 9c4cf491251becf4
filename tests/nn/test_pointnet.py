import pytest
import torch

from volsmpl.nn.config import VolumeConfig
from volsmpl.nn.pointnet import ResnetPointNet


def _net():
    torch.manual_seed(0)
    net = ResnetPointNet(latent_dim=16, hidden=12, n_blocks=4)
    # non-zero residual branches so every layer matters in the tests
    for blk in net.blocks:
        torch.nn.init.normal_(blk.fc_1.weight, std=0.2)
    return net.double()


def test_shapes_and_config():
    net = ResnetPointNet.from_config(VolumeConfig())
    assert net(torch.randn(3, 50, 3)).shape == (3, 128)
    assert len(net.blocks) == 4


def test_permutation_invariance():
    net = _net()
    pts = torch.randn(4, 64, 3, dtype=torch.float64)
    perm = torch.randperm(64)
    torch.testing.assert_close(net(pts), net(pts[:, perm]))


def test_batch_independence():
    net = _net()
    pts = torch.randn(5, 32, 3, dtype=torch.float64)
    full = net(pts)
    for i in range(5):
        torch.testing.assert_close(full[i:i + 1], net(pts[i:i + 1]))
    pts2 = pts.clone()
    pts2[0] += 1.0
    out2 = net(pts2)
    torch.testing.assert_close(out2[1:], full[1:])
    assert not torch.allclose(out2[0], full[0])


def test_global_context_reaches_every_block():
    # Only max-pooled (set) information is used: duplicating points leaves the code unchanged.
    net = _net()
    pts = torch.randn(1, 20, 3, dtype=torch.float64)
    torch.testing.assert_close(net(pts), net(torch.cat([pts, pts[:, :5]], 1)))


def test_input_errors():
    net = ResnetPointNet(8, 8, 2)
    with pytest.raises(ValueError, match=r"\(N, P, 3\)"):
        net(torch.zeros(10, 3))
    with pytest.raises(ValueError, match="empty"):
        net(torch.zeros(2, 0, 3))


def test_cloud_chunking_does_not_change_codes():
    torch.manual_seed(0)
    enc = ResnetPointNet(latent_dim=8, hidden=8, n_blocks=2)
    x = torch.randn(13, 20, 3)
    enc.cloud_chunk = 100
    whole = enc(x)
    enc.cloud_chunk = 4
    assert torch.allclose(enc(x), whole, atol=1e-6)


def _literal(net, points):
    """The architecture written out literally (module docstring of volsmpl.nn.pointnet): concatenations and
    full 2h -> h linears, the reference for the factored forward."""
    x = net.fc_pos(points)
    for i, blk in enumerate(net.blocks):
        if i > 0:
            x = torch.cat([x, x.amax(dim=1, keepdim=True).expand_as(x)], dim=-1)
        x = blk.shortcut(x) + blk.fc_1(torch.relu(blk.fc_0(torch.relu(x))))
    return net.fc_c(torch.relu(x.amax(dim=1)))


def test_factored_forward_equals_the_literal_architecture():
    """Values and gradients (weights and points) of the factored forward equal the literal form in float64."""
    net = _net()
    for p in net.parameters():
        torch.nn.init.normal_(p, std=0.3)
    pts = torch.randn(3, 40, 3, dtype=torch.float64, requires_grad=True)
    got, ref = net(pts), _literal(net, pts)
    torch.testing.assert_close(got, ref, rtol=1e-12, atol=1e-12)
    w = torch.randn_like(got)
    g1 = torch.autograd.grad((got * w).sum(), [pts, *net.parameters()])
    g2 = torch.autograd.grad((_literal(net, pts) * w).sum(), [pts, *net.parameters()])
    for a, b in zip(g1, g2):
        torch.testing.assert_close(a, b, rtol=1e-10, atol=1e-12)
    # float32 at the shipped size: the same function up to rounding
    big = ResnetPointNet.from_config(VolumeConfig())
    for blk in big.blocks:
        torch.nn.init.normal_(blk.fc_1.weight, std=0.05)
    x = torch.randn(4, 512, 3)
    torch.testing.assert_close(big(x), _literal(big, x), rtol=1e-4, atol=1e-5)
