"""volsmpl: VolumetricSMPL, a neural volumetric (SDF) human body model.

    import volsmpl
    body = volsmpl.create_body()          # free default body (Anny exported to SMPL format)
    volsmpl.attach_volume(body)           # or smplx.create(...) SMPL / SMPL-H / SMPL-X models
    out = body(body_pose=...)
    sdf = body.volume.query(out, points)
"""
from volsmpl.body.model import Body, BodyOutput, create_body
from volsmpl.body.partition import Partition
from volsmpl.volume.attach import attach_volume
from volsmpl.volume.learned import Volume

__all__ = ["Body", "BodyOutput", "create_body", "Partition", "Volume", "attach_volume"]
__version__ = "0.1.0"
