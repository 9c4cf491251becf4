"""`attach_volume(body, model=...)`: build the volume of a registered model kind (volsmpl.volume.models) for a
body and attach it as `body.volume`."""
from __future__ import annotations

from pathlib import Path

from volsmpl.body.fingerprint import fingerprint_of_model
from volsmpl.io.checkpoint import load_checkpoint
from volsmpl.volume.models import kind_of_config, model_kind
from volsmpl.body.partition import Partition


#: the buffers attach_volume reads of a body module (volsmpl.Body and smplx SMPL/SMPL-H/SMPL-X have them all)
BODY_ATTRIBUTES = ("v_template", "faces", "lbs_weights", "parents", "J_regressor", "shapedirs")


def _check_body(body) -> None:
    """TypeError in one line unless `body` is a body module (volsmpl.Body or smplx SMPL/SMPL-H/SMPL-X)."""
    import torch

    missing = [a for a in BODY_ATTRIBUTES if not hasattr(body, a)]
    if not isinstance(body, torch.nn.Module) or missing:
        detail = f" (it lacks {', '.join(missing)})" if isinstance(body, torch.nn.Module) and missing else ""
        hint = ("; call attach_volume on the body module itself, e.g. attach_volume(volsmpl.create_body()), "
                "not on its output" if hasattr(body, "vertices") else "; e.g. attach_volume(volsmpl.create_body())")
        raise TypeError(f"attach_volume: expected a volsmpl.Body or an smplx SMPL/SMPL-H/SMPL-X model, got "
                        f"{type(body).__name__}{detail}{hint}.")


def attach_volume(body, checkpoint: str | Path | None = None, pretrained: bool = True, model: str = "volsmpl",
                  config=None, dense: bool = False, trainable: bool | None = None):
    """Attach a volumetric model as `body.volume` (and return it), on the body's device and in its float dtype.

    Args:
        body: volsmpl.Body or smplx SMPL / SMPL-H / SMPL-X model.
        checkpoint: trained weights (path with or without .safetensors); default: the shipped checkpoint
            of `model` for the default body.
        pretrained: False gives randomly initialised weights (tests, or the start of training).
        model: a registered kind (volsmpl.volume.models.MODELS): 'volsmpl' (signed distance, this paper), 'coap'
            (occupancy baseline, COAP) or 'mesh' (exact signed distance to the posed mesh, no weights).
        config: architecture for pretrained=False (VolumeConfig / CoapConfig; checkpoints carry their own).
        dense: use the dense reference query path (every part decoder on every point).
        trainable: whether the network's weights require gradients. Default: False for pretrained weights (queries
            then build no graph for 3.6 M weights; gradients still reach poses, shapes and points), True for random
            weights (the start of training). Unfreeze a pretrained volume for fine-tuning with trainable=True or
            `body.volume.requires_grad_(True)`.
    Example:
        >>> body = volsmpl.create_body()
        >>> volume = attach_volume(body, model="mesh")
    """
    _check_body(body)
    kind = model_kind(model)
    fp = fingerprint_of_model(body)
    if not kind.learned:
        from volsmpl.volume.mesh_kind import MeshVolume
        if checkpoint is not None or config is not None:
            raise ValueError(f"model '{model}' has no weights: pass neither checkpoint nor config")
        volume = MeshVolume(Partition(body), fp).to(body.v_template.device, _float_dtype(body))
        _attach(body, volume)
        return volume
    from volsmpl.volume.learned import Volume

    if checkpoint is not None and not pretrained:
        raise ValueError(f"attach_volume: checkpoint={str(checkpoint)!r} with pretrained=False would give random "
                         f"weights and ignore the checkpoint; drop pretrained=False to load it, or the checkpoint "
                         f"for random weights.")
    if config is not None and pretrained:
        raise ValueError("attach_volume: config is the architecture of random weights (pretrained=False) and would "
                         "be ignored: a checkpoint carries its own; pass pretrained=False with it, or drop config.")
    meta, state = {}, None
    if pretrained:
        path = Path(checkpoint) if checkpoint is not None else kind.default_checkpoint
        if checkpoint is None and not Path(str(path) + ".safetensors").exists():
            raise FileNotFoundError(
                f"no trained {model} checkpoint ships for this body (fingerprint {fp}). Train one with "
                f"`volsmpl train` and pass checkpoint=PATH, or use attach_volume(body, pretrained=False) for random weights.")
        state, cfg_dict, meta = load_checkpoint(path, expected_fingerprint=fp)
        held = kind_of_config(cfg_dict)
        if held != model:
            raise ValueError(f"{path} holds a {held} model; call attach_volume(body, checkpoint=..., model='{held}').")
        config = kind.config_from_dict(cfg_dict)
    partition = Partition(body, n_samples=(config.n_surface_samples if config else 1000),
                          box_padding=(config.box_padding if config else 0.125),
                          draws=(config.encoder_draws if config else 1))
    net = kind.build_network(partition.num_parts, config)
    if state is not None:
        try:
            net.load_state_dict(state)
        except RuntimeError as e:
            raise ValueError(f"checkpoint {checkpoint} does not fit the {model} network for this body "
                             f"({partition.num_parts} parts): {str(e)[:300]}") from e
    volume = Volume(net, partition, fp, dense=dense).to(body.v_template.device, _float_dtype(body))
    volume.meta = meta
    volume.eval()
    volume.requires_grad_(not pretrained if trainable is None else bool(trainable))
    _attach(body, volume)
    return volume


def _float_dtype(body):
    """The floating dtype of a body's vertices (a body moved by .double() before attach_volume gets a float64
    volume, as one moved after it does), float32 for a body whose template is not floating point."""
    dtype = getattr(body.v_template, "dtype", None)
    return dtype if dtype is not None and dtype.is_floating_point else None


def _apply_with_volume(body, fn, *args, **kwargs):
    """Module._apply of a body that also applies fn to its attached volume (body.to / .cuda / .double move both)."""
    result = type(body)._apply(body, fn, *args, **kwargs)
    volume = body.__dict__.get("volume")
    if volume is not None:
        volume._apply(fn, *args, **kwargs)
    return result


def _attach(body, volume) -> None:
    """Set body.volume as a plain attribute (not a submodule: the body's parameters and state dict stay those of the
    body) that moves with the body: body.to(device or dtype), .cuda(), .double() also move the volume."""
    import types

    object.__setattr__(body, "volume", volume)
    object.__setattr__(body, "_apply", types.MethodType(_apply_with_volume, body))
