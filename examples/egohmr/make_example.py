"""Makes this example's two files: `room.ply` (a 5 x 4 m room as a scan shows it: the floor and the four walls'
inner sides, a chair and a table; millimetres, z up, as many scanners write) and `frame.json` (a person of the
default body sitting on the chair, seen by a head-mounted camera 2 m away: K, image_size, the 24 joints' 2D
keypoints with a detector's noise and confidences, and world_to_camera in the room's Y-up world, metres).

    .venv/bin/python examples/egohmr/make_example.py        # rewrites room.ply and frame.json next to this file

The keypoints are the projections of the person's joints plus 2 px of noise (seeded), confidences 0.75-0.98 (the
wrists' and hands' 0.6 times that, as a detector's are lower there; a joint outside the image would get 0).
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import torch
import trimesh

HERE = Path(__file__).resolve().parent
IMAGE_SIZE = (480, 640)       # (H, W)
FOV_DEG = 65.0
EYE = np.array([1.1, 1.6, 1.3])   # the camera wearer's eye, Y-up world (m)
SEAT = np.array([0.4, 0.0, -0.6])  # the chair's footprint centre (x, -, z)


def floor(lo, hi) -> trimesh.Trimesh:
    """The rectangle [lo, hi] (x, z) at y = 0, facing up (+y)."""
    (x0, z0), (x1, z1) = lo, hi
    v = np.array([[x0, 0, z0], [x1, 0, z0], [x1, 0, z1], [x0, 0, z1]], dtype=np.float64)
    return trimesh.Trimesh(v, [[0, 3, 2], [0, 2, 1]], process=False)


def wall(a, b, height: float = 2.5) -> trimesh.Trimesh:
    """The vertical rectangle from (x, z) = a to b, `height` tall, facing the room's centre (the origin), as a scan
    shows a wall: its inner side only."""
    (xa, za), (xb, zb) = a, b
    v = np.array([[xa, 0, za], [xb, 0, zb], [xb, height, zb], [xa, height, za]], dtype=np.float64)
    f = np.array([[0, 1, 2], [0, 2, 3]])
    n = np.cross(v[1] - v[0], v[2] - v[0])
    if n @ (-v[0]) < 0:
        f = f[:, ::-1]
    return trimesh.Trimesh(v, f, process=False)


def box(lo, hi) -> trimesh.Trimesh:
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    return trimesh.creation.box(extents=hi - lo, transform=trimesh.transformations.translation_matrix((lo + hi) / 2))


def person():
    """The sitting body (Y-up world, metres) and the chair's seat height under it."""
    import volsmpl
    from volsmpl.body import named_pose

    body = volsmpl.create_body()
    pose = torch.as_tensor(named_pose("sitting"), dtype=torch.float32).reshape(1, -1)
    with torch.no_grad():
        out = body(body_pose=pose)
    v = out.vertices[0].numpy().astype(np.float64)
    thighs = v[(np.abs(v[:, 0]) < 0.2) & (v[:, 2] < 0.25) & (v[:, 1] < out.joints[0, 0, 1].item())]
    seat_top = thighs[:, 1].min() - v[:, 1].min() + 0.01   # feet 1 cm above the floor
    shift = np.array([SEAT[0], seat_top - thighs[:, 1].min() + 0.003, SEAT[2] - thighs[:, 2].mean() + 0.05])
    return body, pose, shift, float(seat_top)


def room(seat_top: float) -> trimesh.Trimesh:
    """Floor, walls 2.5 m high (their inner sides), a chair under the person and a table beside it (Y-up,
    metres)."""
    sx, _, sz = SEAT
    parts = [floor([-2.5, -2.0], [2.5, 2.0]),
             wall([-2.5, -2.0], [-2.5, 2.0]), wall([2.5, -2.0], [2.5, 2.0]),                 # walls
             wall([-2.5, -2.0], [2.5, -2.0]), wall([-2.5, 2.0], [2.5, 2.0]),
             box([sx - 0.23, seat_top - 0.04, sz - 0.23], [sx + 0.23, seat_top, sz + 0.23]),      # seat
             box([sx - 0.23, seat_top, sz - 0.27], [sx + 0.23, seat_top + 0.5, sz - 0.23]),       # back
             box([-1.2, 0.72, -1.2], [-0.4, 0.75, -0.4])]                                    # table top
    for dx in (-0.2, 0.2):
        for dz in (-0.2, 0.2):
            parts.append(box([sx + dx - 0.02, 0, sz + dz - 0.02], [sx + dx + 0.02, seat_top - 0.04, sz + dz + 0.02]))
            parts.append(box([-0.8 + 2 * dx - 0.02, 0, -0.8 + 2 * dz - 0.02],
                             [-0.8 + 2 * dx + 0.02, 0.72, -0.8 + 2 * dz + 0.02]))          # table legs
    return trimesh.util.concatenate(parts)


def main() -> None:
    from volsmpl.scene import intrinsics_from_fov, look_at
    from volsmpl.scene.scan import from_y_up

    body, pose, shift, seat_top = person()
    with torch.no_grad():
        joints = body(body_pose=pose, transl=torch.as_tensor(shift, dtype=torch.float32)[None]).joints[0, :24]
    joints = joints.numpy().astype(np.float64)
    E = look_at(torch.as_tensor(EYE), torch.as_tensor(joints[3]))[0].numpy()      # aimed at the spine
    K = intrinsics_from_fov(IMAGE_SIZE, FOV_DEG, dtype=torch.float64)[0].numpy()
    cam = joints @ E[:3, :3].T + E[:3, 3]
    uv = cam[:, :2] / cam[:, 2:3] * K[[0, 1], [0, 1]] + K[:2, 2]
    rng = np.random.default_rng(0)
    uv += rng.normal(0.0, 2.0, uv.shape)
    H, W = IMAGE_SIZE
    inside = (uv[:, 0] >= 0) & (uv[:, 0] < W) & (uv[:, 1] >= 0) & (uv[:, 1] < H) & (cam[:, 2] > 0)
    conf = np.where(inside, rng.uniform(0.75, 0.98, 24), 0.0)
    conf[[20, 21, 22, 23]] *= 0.6                                                   # wrists and hands: less sure
    doc = {"K": np.round(K, 3).tolist(), "image_size": list(IMAGE_SIZE),
           "keypoints": np.round(np.where(inside[:, None], uv, 0.0), 1).tolist(), "conf": np.round(conf, 3).tolist(),
           "world_to_camera": np.round(E, 6).tolist()}
    (HERE / "frame.json").write_text(json.dumps(doc, indent=1) + "\n")
    scene = room(seat_top)
    scene.vertices = from_y_up(np.asarray(scene.vertices), "z") * 1000.0         # z up, millimetres
    scene.export(HERE / "room.ply")
    print(f"seat at {seat_top:.3f} m; {int(inside.sum())} keypoints in view; wrote {HERE / 'frame.json'} and "
          f"{HERE / 'room.ply'} ({len(scene.faces)} faces)")


if __name__ == "__main__":
    main()
