"""Range limits answered, not silently wrong: training configs out of range refused in one line (also at the
CLI), far points (1e20 .. 1e30 m) get finite distances from the learned kinds (the box SDF no longer squares them
into inf) and a clear refusal from the exact kind."""
from __future__ import annotations

import math

import pytest
import torch

import volsmpl
from volsmpl.cli import main
from volsmpl.nn.analytic import box_sdf
from volsmpl.train.config import TrainConfig


@pytest.mark.parametrize("field,value,error", [
    ("batch_size", -1, ValueError), ("batch_size", 0, ValueError), ("batch_size", 2.5, TypeError),
    ("lr", -1.0, ValueError), ("lr", float("nan"), ValueError), ("lr", float("inf"), ValueError), ("lr", 0.0, ValueError),
    ("lr_final", float("nan"), ValueError), ("steps", 0, ValueError), ("micro_batch", 0, ValueError),
    ("n_uniform", -3, ValueError), ("ckpt_every", 0, ValueError), ("keep_ckpts", 0, ValueError),
    ("abs_weight", float("nan"), ValueError), ("gt_rays", 2, ValueError), ("seed", "1", TypeError),
    ("surface_sigma", (), ValueError), ("surface_sigma", (-0.01, 0.01), ValueError), ("surface_sigma", ("a",), ValueError),
    ("body_surface_sigma", (float("nan"), 0.01), ValueError), ("num_threads", True, TypeError),
])
def test_train_config_out_of_range(field, value, error):
    with pytest.raises(error, match=field):
        TrainConfig(**{field: value})
    with pytest.raises(error, match=field):
        TrainConfig.from_dict({field: value})


def test_train_config_no_query_points():
    with pytest.raises(ValueError, match="no query points"):
        TrainConfig(n_uniform=0, n_surface=0, n_body_surface=0)
    TrainConfig(n_uniform=0, n_surface=1)  # one kind of point is enough


def test_train_config_sigma_mixtures_accepted():
    TrainConfig(surface_sigma=(0.01, 0.05, 0.002), body_surface_sigma=(0.0,))  # one or more, 0 on the surface


@pytest.mark.parametrize("setting", ["batch_size=-1", "lr=-1", "steps=0", "micro_batch=0"])
def test_train_cli_bad_setting_exits_non_zero_in_one_line(tmp_path, capsys, setting):
    assert main(["train", "--out", str(tmp_path / "run"), "--set", setting, "--max-steps", "0"]) == 2
    err = [ln for ln in capsys.readouterr().err.splitlines() if ln.strip()]
    assert len(err) == 1 and "Traceback" not in err[0] and setting.split("=")[0] in err[0]
    assert not (tmp_path / "run" / "latest").exists()


@pytest.mark.parametrize("flags", [["--max-steps", "-1"], ["--max-hours", "nan"], ["--max-hours", "0"]])
def test_train_cli_bad_limits(tmp_path, capsys, flags):
    assert main(["train", "--out", str(tmp_path / "run"), *flags]) == 2
    err = [ln for ln in capsys.readouterr().err.splitlines() if ln.strip()]
    assert len(err) == 1 and flags[0] in err[0]


def test_box_sdf_far_points_exact():
    lo, hi = torch.tensor([-0.1, -0.2, -0.3]), torch.tensor([0.1, 0.2, 0.3])
    for s in (1e3, 1e19, 1e20, 1e30, 1e37):
        x = torch.tensor([[s, 0.0, 0.0], [s, -s, 0.5 * s], [0.0, 0.0, -s]], requires_grad=True)
        d = box_sdf(x, lo, hi)
        xd = x.detach().double()
        q = (xd.abs() - hi.double()).clamp(min=0)  # the box is centred at 0
        ref = torch.sqrt((q / s).square().sum(-1)) * s  # float64, scaled: exact to rounding
        assert torch.isfinite(d).all()
        assert torch.allclose(d.double(), ref, rtol=1e-6)
        d.sum().backward()  # the gradient of a distance is the unit direction away from the box
        assert torch.allclose(x.grad.double(), torch.sign(xd) * q / ref[:, None], atol=1e-6)
    assert math.isinf(float(box_sdf(torch.tensor([3e38, 3e38, 0.0]), lo, hi)))  # 4.2e38 m does not fit float32


@pytest.mark.parametrize("model", ["volsmpl", "coap"])
def test_learned_query_far_points_finite(tiny_config, model):
    b = volsmpl.create_body()
    kw = dict(config=tiny_config) if model == "volsmpl" else {}
    vol = volsmpl.attach_volume(b, pretrained=False, model=model, **kw)
    with torch.no_grad():
        out = b(body_pose=torch.zeros(1, 69))
        for s in (1e20, 1e30):
            pts = torch.tensor([[[s, 0.0, 0.0], [0.0, -s, s]]])
            d = vol.signed(out, pts)
            assert torch.isfinite(d).all()
            if model == "volsmpl":  # far from a body within a few metres of the origin: the distance is |x|
                assert torch.allclose(d.double(), pts.double().norm(dim=-1), rtol=1e-6)
            else:
                assert (d > 0).all()  # outside


def test_mesh_kind_refuses_far_points():
    b = volsmpl.create_body()
    vol = volsmpl.attach_volume(b, model="mesh")
    with torch.no_grad():
        out = b(body_pose=torch.zeros(1, 69))
        with pytest.raises(ValueError, match=r"1e\+30 m from the origin.*within 1e\+18 m"):
            vol.query(out, torch.tensor([[[1e30, 0.0, 0.0]]]))
        assert torch.isfinite(vol.query(out, torch.tensor([[[1e15, 0.0, 0.0]]]))).all()
