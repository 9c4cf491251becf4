"""tools/selfpen_seeds.py on hand-made selfpen results: means over seeds, the removed-per-second ratio, refusals."""
import importlib.util
import json
from pathlib import Path

import pytest

spec = importlib.util.spec_from_file_location("selfpen_seeds", Path(__file__).parents[3] / "tools" / "selfpen_seeds.py")
tool = importlib.util.module_from_spec(spec)
spec.loader.exec_module(tool)


def _run(folder: Path, seed: int, scale: float, lr: float = 0.01):
    row = {k: scale * (i + 1) for i, k in enumerate(tool.MEAN_KEYS)}
    summary = {"volsmpl": dict(row), "coap": {**row, "removed_per_s": 2.0 * scale}}
    folder.mkdir()
    (folder / "results.json").write_text(json.dumps({"config": {"lr": lr, "seed": seed}, "summary": summary}))
    return folder


def test_means_and_ratio(tmp_path):
    a, b = _run(tmp_path / "a", 0, 1.0), _run(tmp_path / "b", 1, 3.0)
    out = tmp_path / "seeds.json"
    assert tool.main([str(a), str(b), "--command", "cmd", "--out", str(out)]) == 0
    res = json.loads(out.read_text())
    assert res["config"] == {"lr": 0.01} and list(res["per_seed"]) == ["0", "1"]
    assert res["mean_over_seeds"]["volsmpl"]["step_ms"] == pytest.approx(2.0)      # (1 + 3) / 2
    assert res["mean_over_seeds"]["coap"]["removed_per_s"] == pytest.approx(4.0)   # (2 + 6) / 2
    # removed_per_s is the 9th column: volsmpl 9 * scale against coap 2 * scale
    assert res["removed_per_s_ratio_volsmpl_over_coap"] == {"0": pytest.approx(4.5), "1": pytest.approx(4.5)}


def test_refuses_runs_with_other_settings(tmp_path, capsys):
    a, b = _run(tmp_path / "a", 0, 1.0), _run(tmp_path / "b", 1, 1.0, lr=0.1)
    assert tool.main([str(a), str(b), "--command", "cmd", "--out", str(tmp_path / "x.json")]) == 2
    assert "differs" in capsys.readouterr().err and not (tmp_path / "x.json").exists()
