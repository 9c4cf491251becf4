"""The apps' shared options (volsmpl.apps.table): the code refinement options checked before any work in every
app, set on the learned kinds' volumes, recorded in results.json and in the case records' keys."""
from __future__ import annotations

import json
from pathlib import Path

import pytest

from types import SimpleNamespace

from volsmpl.apps.table import CaseRecords, learned_pass_defaults, volumes
from volsmpl.body.model import create_body
from volsmpl.cli import main as cli_main

ROOT = Path(__file__).resolve().parents[2]
R3 = str(ROOT / "checkpoints" / "volsmpl_r3" / "ckpt-00057000" / "model")
NO_PASSES = str(ROOT / "checkpoints" / "volsmpl_b8q" / "ckpt-00050000" / "model")   # step 50,000: no learned passes


@pytest.mark.parametrize("argv, words", [
    (["selfpen", "--model", "volsmpl", "--cases", "deep_squat", "--refine-warm"],
     ["--refine-warm carries", "--refine-steps 1"]),
    (["selfpen", "--model", "mesh", "--cases", "deep_squat", "--refine-steps", "2"],
     ["--refine-steps refines the part codes of volsmpl and coap", "--model mesh"]),
    (["hoi", "run", "--model", "volsmpl", "--refine-steps", "-1"], ["--refine-steps -1", "integer >= 0"]),
    (["hoi", "tune", "--refine-steps", "1"], ["--refine-steps", "does not apply to `volsmpl hoi tune`"]),
    (["motion", "--model", "mesh", "--refine-steps", "1", "--refine-warm"], ["--refine-steps refines", "--model mesh"]),
    (["egohmr", "sample", "--model", "none", "--refine-steps", "1"], ["--refine-steps", "no guide"]),
    (["selfpen", "--model", "volsmpl", "--cases", "deep_squat", "--pass-every", "0"],
     ["--pass-every 0", "integer >= 1"]),
    (["motion", "--model", "mesh", "--pass-every", "2"], ["--pass-every 2 sets VolumetricSMPL's", "--model mesh"]),
    (["selfpen", "--model", "volsmpl", "--cases", "deep_squat", "--pass-every", "2", "--refine-steps", "1",
      "--refine-warm"], ["--pass-every 2", "--refine-warm", "use one of them"]),
    (["selfpen", "--model", "volsmpl", "--cases", "deep_squat", "--pass-every", "2",
      "--checkpoint-volsmpl", NO_PASSES], ["--pass-every 2", "no learned code-refinement passes"]),
    (["hoi", "tune", "--pass-every", "2"], ["--pass-every", "does not apply to `volsmpl hoi tune`"]),
    (["selfpen", "--model", "volsmpl", "--cases", "deep_squat", "--passes", "-1"], ["--passes -1", "integer >= 0"]),
    (["motion", "--model", "coap,mesh", "--passes", "1"], ["--passes 1 sets VolumetricSMPL's", "--model coap,mesh"]),
    (["selfpen", "--model", "volsmpl", "--cases", "deep_squat", "--checkpoint-volsmpl", R3, "--passes", "0",
      "--pass-every", "2"], ["--pass-every 2", "--passes 0 runs none"]),
    (["selfpen", "--model", "volsmpl", "--cases", "deep_squat", "--checkpoint-volsmpl", R3, "--passes", "3"],
     ["--passes 3: this model has 2 learned code-refinement passes"]),
    (["hoi", "tune", "--passes", "1"], ["--passes", "does not apply to `volsmpl hoi tune`"]),
    (["selfpen", "--model", "volsmpl", "--cases", "deep_squat", "--checkpoint-volsmpl", R3, "--pass-every", "2"],
     ["--pass-every 2", "this app runs none by default (--passes 0)", "give --passes 1 or more"]),
])
def test_refinement_options_are_checked_before_any_work(argv, words, tmp_path, capsys):
    assert cli_main(argv + ["--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "Traceback" not in err, err
    for w in words:
        assert w in err, err


def test_volumes_get_the_setting_and_case_keys_hold_it(tmp_path):
    body = create_body()
    refine = {"steps": 2, "warm": True}
    vols = volumes(body, ["volsmpl", "coap", "mesh"], {"volsmpl": None, "coap": None}, refine=refine)
    assert (vols["volsmpl"].refine_steps, vols["volsmpl"].refine_warm) == (2, True)
    assert (vols["coap"].refine_steps, vols["coap"].refine_warm) == (2, True)
    plain = volumes(body, ["volsmpl"], {"volsmpl": None})["volsmpl"]
    assert plain.refine_steps == 0 and not plain.refine_warm
    store = CaseRecords(tmp_path, "selfpen")
    keys = {store.key({"case": "a"}, plain), store.key({"case": "a"}, vols["volsmpl"])}
    plain.set_code_refinement(2)
    keys.add(store.key({"case": "a"}, plain))
    assert len(keys) == 3                                  # none, warm and cold refinement make different records
    every = volumes(body, ["volsmpl", "coap"], {"volsmpl": R3, "coap": None}, refine={"steps": 0, "warm": False,
                                                                                    "pass_every": 4})
    assert every["volsmpl"].pass_every == 4 and every["coap"].pass_every == 1
    once = volumes(body, ["volsmpl"], {"volsmpl": R3})["volsmpl"]
    assert store.key({"case": "a"}, every["volsmpl"]) != store.key({"case": "a"}, once)


def test_a_warm_run_records_its_setting(tmp_path):
    rc = cli_main(["selfpen", "--model", "volsmpl", "--cases", "arm_through_head", "--max-iters", "2",
                   "--n-points", "32", "--threads", "1", "--render", "0", "--refine-steps", "1", "--refine-warm",
                   "--out", str(tmp_path)])
    assert rc == 0
    res = json.loads((tmp_path / "results.json").read_text())
    assert res["config"]["code_refinement"] == {"steps": 1, "warm": True, "passes": 0, "pass_every": 1}
    (case,) = res["cases"]["volsmpl"]
    assert case["name"] == "arm_through_head" and len(case["body_pose"]) == 69


def test_a_run_with_passes_at_an_interval_records_it(tmp_path):
    rc = cli_main(["selfpen", "--model", "volsmpl", "--cases", "arm_through_head", "--max-iters", "3",
                   "--n-points", "32", "--threads", "1", "--render", "0", "--checkpoint-volsmpl", R3,
                   "--passes", "2", "--pass-every", "2", "--out", str(tmp_path)])
    assert rc == 0
    res = json.loads((tmp_path / "results.json").read_text())
    assert res["config"]["code_refinement"] == {"steps": 0, "warm": False, "passes": 2, "pass_every": 2}


@pytest.mark.parametrize("models, ckpt, given, app, want", [
    # an app's defaults (passes 1, every 4th iteration) where the checkpoint has two passes
    (["volsmpl"], R3, (None, None), (1, 4), (1, 4)),
    (["volsmpl", "coap"], R3, (None, None), (None, 4), (None, 4)),     # default passes: all the checkpoint has
    (["volsmpl"], R3, (2, None), (1, 4), (2, 4)),                      # given values stay
    (["volsmpl"], R3, (None, 2), (1, 4), (1, 2)),
    (["volsmpl"], R3, (None, None), (0, 4), (0, 1)),                   # no passes run: no interval
    (["volsmpl"], NO_PASSES, (None, None), (1, 4), (None, 1)),         # a checkpoint without passes runs none
    (["volsmpl"], NO_PASSES, (None, None), (None, 4), (None, 1)),
    (["coap", "mesh"], None, (None, None), (1, 4), (None, 1)),          # without volsmpl: nothing set
])
def test_an_apps_pass_defaults_follow_the_checkpoint(models, ckpt, given, app, want):
    args = SimpleNamespace(passes=given[0], pass_every=given[1], app_passes=app[0], app_pass_every=app[1])
    learned_pass_defaults(args, models, {"volsmpl": ckpt} if "volsmpl" in models else {})
    assert (args.passes, args.pass_every) == want
