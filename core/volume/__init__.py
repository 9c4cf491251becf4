"""Volumes attached to a body: the model registry, the shared `BodyVolume` answers (one sign convention), the
learned `Volume` (VolumetricSMPL, COAP), the exact 'mesh' kind, and what they share (collision and
self-penetration reductions, input checks, mesh extraction, the encoding cache, reduced precision, code
refinement, cold or carried along an optimisation, and learned passes at an interval with their correction
carried). `volume.engine` holds the query engine's internals.

    vol = attach_volume(body, model="coap")         # any registered kind: "volsmpl", "coap", "mesh"
    d = vol.signed(out, points)                     # (B, N): negative inside
"""
from volsmpl.volume.api import BodyVolume
from volsmpl.volume.attach import attach_volume
from volsmpl.volume.carried_passes import CarriedPasses
from volsmpl.volume.collision import reduce_penetration
from volsmpl.volume.learned import Volume
from volsmpl.volume.mesh_kind import MeshVolume
from volsmpl.volume.models import MODELS, ModelKind, checkpoint_model, learned_models, model_kind, parse_models
from volsmpl.volume.precision import PRECISIONS
from volsmpl.volume.warm_codes import WarmCodes

__all__ = ["MODELS", "PRECISIONS", "BodyVolume", "CarriedPasses", "MeshVolume", "ModelKind", "Volume", "attach_volume",
           "WarmCodes", "checkpoint_model", "learned_models", "model_kind", "parse_models", "reduce_penetration"]
