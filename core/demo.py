"""`volsmpl demo`: the main job on the default body. Writes into --out:
poses/<name>.ply (the default body in named poses) and parts.png (the poses with parts coloured)."""
from __future__ import annotations

from pathlib import Path


def add_parser(sub):
    p = sub.add_parser("demo", help="pose the default body, write meshes and a part-coloured picture")
    p.add_argument("--out", default="out")
    p.add_argument("--poses", nargs="*", default=None, help="named poses (default: a selection)")
    return p


def run(args) -> int:
    import numpy as np
    import torch
    import trimesh

    from .body.model import create_body
    from .body.poses import named_pose
    from .partition import Partition
    from .render import grid, part_palette, render_mesh, save_png

    out_dir = Path(args.out)
    (out_dir / "poses").mkdir(parents=True, exist_ok=True)
    body = create_body()
    part = Partition(body)
    names = args.poses or ["t_pose", "a_pose", "sitting", "squatting", "reaching", "arms_crossed", "lunge", "walking"]
    colors = part_palette(part.num_parts)[part.face_labels.numpy()]
    images = []
    with torch.no_grad():
        outs = [body(body_pose=named_pose(n)) for n in names]
    extent = max(float((o.vertices[0].amax(0) - o.vertices[0].amin(0)).max()) for o in outs)
    for n, o in zip(names, outs):
        v = o.vertices[0].numpy()
        trimesh.Trimesh(v, body.faces, face_colors=(colors * 255).astype(np.uint8), process=False).export(out_dir / "poses" / f"{n}.ply")
        images.append(render_mesh(v, body.faces, colors, size=384, yaw=25, pitch=8, extent=extent))
    save_png(out_dir / "parts.png", grid(images, names, cols=4))
    print(f"wrote {len(names)} posed meshes to {out_dir / 'poses'} and {out_dir / 'parts.png'}")
    return 0
