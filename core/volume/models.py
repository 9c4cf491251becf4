"""The model registry: one table decides what each kind of volume is.

    kind = model_kind("coap")
    kind.output                       # 'occupancy': what Volume.query returns
    net = kind.build_network(16)      # the network with its default config
    kind.default_checkpoint           # core/assets/coap_anny (without .safetensors)

Kinds:
- 'volsmpl': VolumetricSMPL (this paper): NBW decoders, signed distance in metres, negative inside.
- 'coap': the COAP baseline (Mihajlovic et al. 2022): part occupancy in [0, 1], surface at 0.5.
- 'mesh': the exact reference: signed distance of points to the posed mesh itself (no network); the
  quality and cost ceiling every app reports beside the two learned models.

Every kind answers the same calls (`query`, `signed`, `occupied`, `collision_loss`, `selfpen_loss`), so a
consumer never branches on the kind: `signed` is negative inside and positive outside for all of them.
"""
from __future__ import annotations

import importlib
import os
from dataclasses import dataclass
from pathlib import Path

from volsmpl.io.checkpoint import load_checkpoint

ASSETS = Path(__file__).resolve().parents[1] / "assets"


@dataclass(frozen=True)
class ModelKind:
    """One entry of the registry.

    Attributes:
        name: the kind's name ('volsmpl', 'coap', 'mesh').
        summary: one line for help texts and reports.
        output: what `query` returns: 'sdf' (metres, negative inside) or 'occupancy' ([0, 1], inside above `level`).
        learned: True for network models (checkpoints, training), False for the exact mesh reference.
        network: 'module:Class' of the network (learned kinds).
        config: 'module:Class' of the network's config (learned kinds).
        checkpoint: file stem (in core/assets) of the shipped checkpoint for the default body, or None.
        train_loss: the training objective of `volsmpl train`: 'sdf' (eq. 3) or 'occupancy' (binary cross-entropy).
        grouped: True when the network decodes (point, part) pairs by grouped matmuls (`decode_grouped`, the
            query engine's pair_decoder 'grouped'); the others decode them by chunks (`decode_pairs`).
    """

    name: str
    summary: str
    output: str
    learned: bool
    network: str | None = None
    config: str | None = None
    checkpoint: str | None = None
    train_loss: str | None = None
    grouped: bool = False

    @property
    def default_checkpoint(self) -> Path | None:
        """Path (without .safetensors) of the shipped checkpoint, or None for kinds without one."""
        return ASSETS / self.checkpoint if self.checkpoint else None

    def config_class(self):
        """The config dataclass of a learned kind."""
        return _load(self._require("config"))

    def default_config(self):
        return self.config_class()()

    def config_from_dict(self, d: dict):
        """Rebuild the config saved in a checkpoint (the 'model' key is the kind's name, not a field)."""
        cls = self.config_class()
        return cls.from_dict(d) if self.name == "coap" else cls.from_dict({k: v for k, v in d.items() if k != "model"})

    def build_network(self, num_parts: int, config=None):
        """The network of this kind for a body with `num_parts` parts (default config when None)."""
        return _load(self._require("network"))(num_parts, config if config is not None else self.default_config())

    def _require(self, field: str) -> str:
        value = getattr(self, field)
        if value is None:
            raise ValueError(f"model '{self.name}' has no {field}: it is not a network "
                             f"(learned models: {', '.join(learned_models())}).")
        return value


def _load(path: str):
    module, name = path.split(":")
    return getattr(importlib.import_module(module), name)


MODELS: dict[str, ModelKind] = {
    "volsmpl": ModelKind(
        "volsmpl", "VolumetricSMPL: NBW part decoders, signed distance (this paper)", output="sdf", learned=True,
        network="volsmpl.nn.volsmpl_net:VolumetricSMPLNet", config="volsmpl.nn.config:VolumeConfig",
        checkpoint="volsmpl_anny", train_loss="sdf", grouped=True),
    "coap": ModelKind(
        "coap", "COAP baseline: part occupancy networks (Mihajlovic et al. 2022)", output="occupancy", learned=True,
        network="volsmpl.nn.coap_net:CoapNet", config="volsmpl.nn.coap_net:CoapConfig",
        checkpoint="coap_anny", train_loss="occupancy"),
    "mesh": ModelKind(
        "mesh", "exact signed distance to the posed mesh (reference: the quality and cost ceiling)", output="sdf",
        learned=False),
}


def model_kind(name: str) -> ModelKind:
    """The registry entry of `name`; a clear error naming the known kinds otherwise."""
    if name not in MODELS:
        raise ValueError(f"unknown model {name!r}; available: {', '.join(MODELS)}.")
    return MODELS[name]


def learned_models() -> tuple[str, ...]:
    """Names of the kinds that are networks (have checkpoints and can be trained)."""
    return tuple(n for n, k in MODELS.items() if k.learned)


def kind_of_config(config: dict) -> str:
    """Which learned kind a checkpoint's config dict describes (its 'model' key; 'volsmpl' when absent)."""
    name = config.get("model", "volsmpl") if isinstance(config, dict) else "volsmpl"
    if name not in MODELS or not MODELS[name].learned:
        raise ValueError(f"the checkpoint config names model {name!r}; known networks: {', '.join(learned_models())}.")
    return name


def kind_of_network(net) -> str:
    """Which learned kind a network instance is (by the registry's network classes)."""
    for name in learned_models():
        if type(net) is _load(MODELS[name].network):
            return name
    raise ValueError(f"{type(net).__name__} is not a registered network; known: {', '.join(learned_models())}.")


def parse_models(text: str) -> list[str]:
    """A comma-separated `--model` value -> the list of kind names (duplicates dropped, order kept)."""
    names = [m.strip() for m in str(text).split(",") if m.strip()]
    bad = [m for m in names if m not in MODELS]
    if bad or not names:
        raise ValueError(f"unknown model(s) {bad or text!r}; --model takes a comma-separated list of {', '.join(MODELS)}")
    return list(dict.fromkeys(names))


def checkpoint_model(path: str | os.PathLike) -> str:
    """Which registered model kind a checkpoint holds (volsmpl.volume.models), read from its JSON (weights not loaded)."""
    _, cfg, _ = load_checkpoint(path, weights=False)
    return kind_of_config(cfg)


def expect_checkpoint_model(path: str | os.PathLike, model: str, option: str, fix: str) -> None:
    """ValueError in one line when the checkpoint given by `option` holds another model kind than `model`;
    `fix` is the remedy, with '{held}' standing for the kind it holds. Example:
        >>> expect_checkpoint_model(p, "coap", "--checkpoint-coap", "pass it as --checkpoint-{held}.")"""
    held = checkpoint_model(path)
    if held != model:
        raise ValueError(f"{option} {path} holds a {held} model, not {model}; " + fix.format(held=held))
