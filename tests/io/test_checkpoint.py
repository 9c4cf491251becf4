import json
import os

import pytest
import torch

from volsmpl.io.checkpoint import CheckpointError, checkpoint_paths, load_checkpoint, save_checkpoint
from volsmpl.volume.models import checkpoint_model
from volsmpl.nn.config import VolumeConfig


def _save(tmp_path, fp="abc123"):
    sd = {"a.weight": torch.randn(3, 4), "b": torch.arange(5), "c": torch.randn(2, 2).T}  # non-contiguous
    cfg = VolumeConfig(nbw_rank=4).to_dict()
    meta = {"body_fingerprint": fp, "parts": ["pelvis", "spine"], "training": {"steps": 10}}
    save_checkpoint(tmp_path / "model", sd, cfg, meta)
    return sd, cfg, meta


def test_round_trip(tmp_path):
    sd, cfg, meta = _save(tmp_path)
    assert sorted(os.listdir(tmp_path)) == ["model.json", "model.safetensors"]  # no temp files left
    for p in (tmp_path / "model", tmp_path / "model.safetensors", str(tmp_path / "model.json")):
        sd2, cfg2, meta2 = load_checkpoint(p, expected_fingerprint="abc123")
        assert sd2.keys() == sd.keys()
        for k in sd:
            assert torch.equal(sd2[k], sd[k]) and sd2[k].dtype == sd[k].dtype
        assert cfg2 == cfg and meta2 == meta
        assert VolumeConfig.from_dict(cfg2) == VolumeConfig(nbw_rank=4)
    doc = json.loads((tmp_path / "model.json").read_text())
    assert doc["format"] == "volsmpl-checkpoint" and doc["version"] == 1


def test_shared_storage_and_module_state(tmp_path):
    lin = torch.nn.Linear(3, 2)
    sd = {"w": lin.weight, "w_alias": lin.weight, "bias": lin.bias}
    save_checkpoint(tmp_path / "m", sd, {}, {})
    sd2, _, _ = load_checkpoint(tmp_path / "m")
    assert torch.equal(sd2["w_alias"], lin.weight.detach())


def test_config_only_and_model_kind(tmp_path):
    sd, cfg, meta = _save(tmp_path)
    none, cfg2, meta2 = load_checkpoint(tmp_path / "model", weights=False)
    assert none is None and cfg2 == cfg and meta2 == meta
    assert checkpoint_model(tmp_path / "model") == "volsmpl"
    from volsmpl.nn.coap_net import CoapConfig
    save_checkpoint(tmp_path / "coap", sd, CoapConfig().to_dict(), meta)
    assert checkpoint_model(tmp_path / "coap.safetensors") == "coap"
    with pytest.raises(CheckpointError, match="not found"):
        checkpoint_model(tmp_path / "nothing")


def test_missing_file(tmp_path):
    with pytest.raises(CheckpointError, match=r"not found: .*nothere\.json.*volsmpl train"):
        load_checkpoint(tmp_path / "nothere")
    _save(tmp_path)
    os.remove(tmp_path / "model.safetensors")
    with pytest.raises(CheckpointError, match=r"not found: .*model\.safetensors"):
        load_checkpoint(tmp_path / "model")


def test_folder_given_as_checkpoint_names_the_model_inside(tmp_path):
    """`volsmpl eval --checkpoint runs/x/ckpt-00000200` (a training-state folder) or `--init runs/x` (a run folder)
    said 'checkpoint file not found: runs/x/ckpt-00000200.json' (or '.../.json' with a trailing slash); the message
    now names the model checkpoint inside. A checkpoint beside a folder of its name still loads."""
    ck = tmp_path / "run" / "ckpt-00000002"
    ck.mkdir(parents=True)
    _save(ck)
    (tmp_path / "run" / "latest").write_text("ckpt-00000002\n")
    for given in (str(ck), str(ck) + "/"):
        with pytest.raises(CheckpointError, match="training-state folder") as e:
            load_checkpoint(given)
        assert str(ck / "model") + "." in str(e.value)
    with pytest.raises(CheckpointError, match="run folder") as e:
        load_checkpoint(tmp_path / "run")
    assert str(ck / "model") + "." in str(e.value)
    with pytest.raises(CheckpointError, match="is a folder, not a checkpoint"):
        load_checkpoint(tmp_path)
    (ck / "model").mkdir()  # a folder beside the pair of the same name: the pair is the checkpoint
    assert load_checkpoint(ck / "model")[0] is not None


def test_corrupt_safetensors(tmp_path):
    _save(tmp_path)
    p = tmp_path / "model.safetensors"
    data = p.read_bytes()
    p.write_bytes(data[: len(data) // 2])                  # truncated
    with pytest.raises(CheckpointError, match="corrupt"):
        load_checkpoint(tmp_path / "model")
    p.write_bytes(b"\x00" * 64)                            # garbage
    with pytest.raises(CheckpointError, match="corrupt"):
        load_checkpoint(tmp_path / "model")


def test_corrupt_json(tmp_path):
    _save(tmp_path)
    p = tmp_path / "model.json"
    p.write_text(p.read_text()[:20])
    with pytest.raises(CheckpointError, match=r"model\.json is corrupt"):
        load_checkpoint(tmp_path / "model")


def test_wrong_format_and_version(tmp_path):
    _save(tmp_path)
    p = tmp_path / "model.json"
    doc = json.loads(p.read_text())
    p.write_text(json.dumps({**doc, "format": "other"}))
    with pytest.raises(CheckpointError, match="not a volsmpl checkpoint"):
        load_checkpoint(tmp_path / "model")
    p.write_text(json.dumps({**doc, "version": 99}))
    with pytest.raises(CheckpointError, match="version 99"):
        load_checkpoint(tmp_path / "model")


def test_fingerprint_mismatch(tmp_path):
    _save(tmp_path, fp="aaaa")
    with pytest.raises(CheckpointError) as e:
        load_checkpoint(tmp_path / "model", expected_fingerprint="bbbb")
    msg = str(e.value)
    assert "trained for body aaaa, this body is bbbb" in msg and "volsmpl train" in msg
    load_checkpoint(tmp_path / "model")                    # no expectation -> loads


def test_no_fingerprint_recorded(tmp_path):
    save_checkpoint(tmp_path / "m", {"x": torch.zeros(1)}, {}, {})
    with pytest.raises(CheckpointError, match="no body fingerprint"):
        load_checkpoint(tmp_path / "m", expected_fingerprint="bbbb")


def test_save_rejects_bad_inputs(tmp_path):
    with pytest.raises(TypeError, match="only tensors"):
        save_checkpoint(tmp_path / "m", {"x": 3}, {}, {})
    with pytest.raises(TypeError, match="JSON-serialisable"):
        save_checkpoint(tmp_path / "m", {}, {"bad": object()}, {})
    assert not os.listdir(tmp_path)


def test_paths():
    assert checkpoint_paths("a/b") == ("a/b.safetensors", "a/b.json")
    assert checkpoint_paths("a/b.json") == ("a/b.safetensors", "a/b.json")


def test_config_dict_round_trip_and_unknown_keys():
    cfg = VolumeConfig()
    d = cfg.to_dict()
    assert d["skip_layers"] == [3] and json.loads(json.dumps(d)) == d
    assert VolumeConfig.from_dict(d) == cfg
    with pytest.raises(ValueError, match=r"unknown VolumeConfig key\(s\) \['nope'\]"):
        VolumeConfig.from_dict({**d, "nope": 1})
    with pytest.raises(ValueError, match="skip_layers"):
        VolumeConfig(skip_layers=(9,))


# ---------------------------------------------------------------- digests and non-finite weights
def test_damaged_weights_same_size_refused(tmp_path):
    _save(tmp_path)
    p = tmp_path / "model.safetensors"
    data = bytearray(p.read_bytes())
    data[-3] ^= 0x40  # one byte of the last tensor's data: same size, still parses
    p.write_bytes(bytes(data))
    with pytest.raises(CheckpointError, match=r"model\.safetensors does not match the weights digest"):
        load_checkpoint(tmp_path / "model")


def test_swapped_tensor_file_refused(tmp_path):
    _save(tmp_path / "a")
    sd = {"a.weight": torch.randn(3, 4), "b": torch.arange(5), "c": torch.randn(2, 2)}
    save_checkpoint(tmp_path / "b" / "model", sd, VolumeConfig(nbw_rank=4).to_dict(), {})
    os.replace(tmp_path / "b" / "model.safetensors", tmp_path / "a" / "model.safetensors")
    with pytest.raises(CheckpointError, match="weights digest"):
        load_checkpoint(tmp_path / "a" / "model")


@pytest.mark.parametrize("key,value", [("normalize_parts", True), ("box_padding", 0.2), ("n_surface_samples", 256)])
def test_edited_config_refused(tmp_path, key, value):
    _save(tmp_path)
    p = tmp_path / "model.json"
    doc = json.loads(p.read_text())
    assert doc["config"][key] != value
    doc["config"][key] = value
    p.write_text(json.dumps(doc))
    for weights in (True, False):
        with pytest.raises(CheckpointError, match=r"model\.json: its config differs .* digest mismatch"):
            load_checkpoint(tmp_path / "model", weights=weights)


def test_non_finite_weights_refused(tmp_path):
    from safetensors.torch import save_file
    with pytest.raises(ValueError, match=r"'w' \(1 of 4 entries\) .* NaN or inf"):
        save_checkpoint(tmp_path / "m", {"w": torch.tensor([0.0, float("nan"), 1.0, 2.0])}, {}, {})
    assert not os.listdir(tmp_path)  # nothing written
    # a file written by other means (no digests: the legacy path) holding inf
    save_checkpoint(tmp_path / "m", {"w": torch.zeros(4)}, {}, {})
    save_file({"w": torch.tensor([0.0, float("inf"), 1.0, 2.0])}, str(tmp_path / "m.safetensors"))
    doc = json.loads((tmp_path / "m.json").read_text())
    del doc["digests"]
    (tmp_path / "m.json").write_text(json.dumps(doc))
    with pytest.warns(UserWarning, match="records no digests"):
        with pytest.raises(CheckpointError, match=r"m\.safetensors holds NaN or inf weights in 'w' \(1 of 4"):
            load_checkpoint(tmp_path / "m")


def test_legacy_checkpoint_without_digests(tmp_path):
    """Loads with a warning (cannot be verified); add_digests records them, after which edits are caught."""
    from volsmpl.io.checkpoint import add_digests
    sd, cfg, meta = _save(tmp_path)
    p = tmp_path / "model.json"
    doc = json.loads(p.read_text())
    del doc["digests"]
    p.write_text(json.dumps(doc))
    with pytest.warns(UserWarning, match=r"model\.json records no digests.*add_digests"):
        sd2, _, _ = load_checkpoint(tmp_path / "model")
    assert torch.equal(sd2["a.weight"], sd["a.weight"])
    weights_before = (tmp_path / "model.safetensors").read_bytes()
    add_digests(tmp_path / "model")
    assert (tmp_path / "model.safetensors").read_bytes() == weights_before
    import warnings
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        load_checkpoint(tmp_path / "model")
    doc = json.loads(p.read_text())
    doc["config"]["box_padding"] = 0.3
    p.write_text(json.dumps(doc))
    with pytest.raises(CheckpointError, match="digest mismatch"):
        load_checkpoint(tmp_path / "model")


@pytest.mark.parametrize("kind", ["volsmpl", "coap"])
def test_shipped_checkpoints_carry_digests(kind):
    """The shipped checkpoints load verified (no legacy warning) and their digests match their weights."""
    import warnings
    from volsmpl.io.checkpoint import config_digest, weights_digest
    from volsmpl.volume.models import model_kind
    path = model_kind(kind).default_checkpoint
    doc = json.loads(open(checkpoint_paths(path)[1]).read())
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        sd, cfg, _ = load_checkpoint(path)
    assert doc["digests"] == {"weights": weights_digest(sd), "config": config_digest(cfg)}
