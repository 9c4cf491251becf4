"""Scenes and objects shared by the human-object, egocentric and scene-constrained motion applications.

- `objects`: procedural object templates with real-world sizes (cup, bottle, box, ball, bat, phone, skateboard,
  laptop, backpack, suitcase, umbrella, chair, stool, table, sofa, bed, shelf, cart): `make_object`, the size
  prior `SIZE_PRIOR`, named interaction regions (grasp, handle, seat, back, top, deck...), seats and supports,
  rotational symmetries `SYMMETRY` and the symmetry-aware `rotation_error_deg`.
- `object_shapes`: the per-category procedural shape builders behind `make_object`.
- `rooms`: procedural furnished rooms from an integer seed (`make_room`, `ROOM_COUNT` standard seeds) and the
  cached 16,384-point FPS scene cloud (`room_points`).
- `room`: the `Room` record and its queries: scene mesh, items, free-space grid and exact clearance, start/goal
  sampling, seats, walls, support surfaces, viewpoints.
- `furnish`: the layout generator (`furnish_room`): furniture per room kind, overlap-free placement.
- `points`: surface sampling with normals, farthest-point sampling (open3d), cube crops, fixed-size subsampling,
  torch conversion.
- `camera`: pinhole cameras on kornia (OpenCV axes): intrinsics from a field of view, look-at extrinsics,
  projection with depth and visibility, back-projection; batched and differentiable.
- `scan`: a user's scene file (any format trimesh reads, or an array of points) in metres and Y up: `read_scan`,
  and `open_scan` for scenes of any size, whose points are taken inside a region at a spacing in metres.
- `floor`: the floor of a cloud: the up axis (`estimate_floor`, `floor_up`) and the floor's level (`floor_level`).
- `cache`: the user cache folder for generated data (`cached(name, version, seed, build_fn)`, atomic writes; versions
  that carry a digest of the generator's source: `code_version`).

Rendering of scenes (several meshes, dots, camera views with keypoints) is in `volsmpl.viz.render`.
"""
from .cache import cache_dir, cache_path, cached, code_version
from .camera import (camera_center, camera_to_world, intrinsics_from_fov, look_at, make_camera, orbit_eye, project,
                     unproject, world_to_camera)
from .objects import (CATEGORIES, HANDHELD, REGIONS, SITTABLE, SIZE_PRIOR, SYMMETRY, ObjectTemplate, make_object,
                      rotation_error_deg)
from .points import crop_cube, farthest_point_sample, sample_surface, subsample, to_torch
from .room import GRID_CELL, Item, Room, Seat, Surface
from .rooms import ROOM_COUNT, ROOM_KINDS, ROOM_VERSION, make_room, room_points

__all__ = [
    "cache_dir", "cache_path", "cached", "code_version",
    "camera_center", "camera_to_world", "intrinsics_from_fov", "look_at", "make_camera", "orbit_eye", "project",
    "unproject", "world_to_camera",
    "CATEGORIES", "HANDHELD", "REGIONS", "SITTABLE", "SIZE_PRIOR", "SYMMETRY", "ObjectTemplate", "make_object",
    "rotation_error_deg",
    "crop_cube", "farthest_point_sample", "sample_surface", "subsample", "to_torch",
    "GRID_CELL", "ROOM_COUNT", "ROOM_KINDS", "ROOM_VERSION", "Item", "Room", "Seat", "Surface", "make_room",
    "room_points",
]
