"""`volsmpl demo`: the main job on the default body. Writes into --out:
poses/<name>.ply (the default body in named poses), parts.png (the poses with parts coloured), and, with a
trained checkpoint (the shipped one, or --checkpoint), sdf_slice.png (the learned SDF on a frontal slice
with its zero level in black and the true mesh section in green) and surfaces.png (marching cubes of the
learned SDF beside the true mesh), plus learned_<pose>.ply."""
from __future__ import annotations

from pathlib import Path


def add_parser(sub):
    p = sub.add_parser("demo", help="pose the default body, write meshes and a part-coloured picture")
    p.add_argument("--out", default="out")
    p.add_argument("--poses", nargs="*", default=None, help="named poses (default: a selection)")
    p.add_argument("--checkpoint", default=None, help="volumetric model for the SDF pictures (default: the shipped one)")
    p.add_argument("--resolution", type=int, default=128, help="marching-cubes grid for surfaces.png")
    return p


def run(args) -> int:
    import numpy as np
    import torch
    import trimesh

    from volsmpl.body.model import create_body
    from volsmpl.body.poses import named_pose
    from volsmpl.body.partition import Partition
    from volsmpl.io.outputs import check_writable
    from volsmpl.viz.render import grid, part_palette, render_mesh, save_png

    out_dir = check_writable(args.out, "dir", "--out")
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
    _volume_pictures(args, body, out_dir)
    return 0


def _volume_pictures(args, body, out_dir: Path) -> None:
    import torch

    from volsmpl.body.poses import named_pose
    from volsmpl.viz.render import save_png
    from volsmpl.viz.slice_view import sdf_slice, surfaces_side_by_side
    from volsmpl.volume.attach import attach_volume
    from volsmpl.volume.models import model_kind

    ckpt = args.checkpoint
    if ckpt is None and not model_kind("volsmpl").default_checkpoint.with_suffix(".safetensors").exists():
        print("no trained checkpoint ships yet: SDF pictures skipped (train one with `volsmpl train`, "
              "then `volsmpl demo --checkpoint PATH`)")
        return
    vol = attach_volume(body, checkpoint=ckpt)
    with torch.no_grad():
        out = body(body_pose=named_pose("walking"))
    save_png(out_dir / "sdf_slice.png", sdf_slice(vol, out, body.faces))
    print(f"wrote {out_dir / 'sdf_slice.png'}")
    try:
        save_png(out_dir / "surfaces.png", surfaces_side_by_side(vol, out, body.faces, resolution=args.resolution))
        vol.extract_mesh(out, resolution=args.resolution).export(out_dir / "learned_walking.ply")
        print(f"wrote {out_dir / 'surfaces.png'} and {out_dir / 'learned_walking.ply'}")
    except RuntimeError as e:  # an untrained field may have no zero level set
        print(f"surfaces.png skipped: {e}")
