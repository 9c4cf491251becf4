"""`Body`: a small, smplx-free LBS body that loads SMPL-format `.npz` files (ours or official SMPL).

It returns the same fields as `smplx.SMPL` (vertices, joints, full_pose, ...), so everything in
volsmpl accepts either. The default body is exported from Anny (see `volsmpl.body.anny_export`).
"""
from __future__ import annotations

import json
import numbers
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import torch

from .fingerprint import body_fingerprint
from .lbs import kinematic_levels, pose_blend, rigid_chain, rodrigues, shape_blend, skin_vertices

ASSETS = Path(__file__).resolve().parent.parent / "assets"
DEFAULT_BODY_FILE = ASSETS / "anny_smpl_neutral.npz"
DEFAULT_SMPLX_FILE = ASSETS / "anny_smplx_neutral.npz"

SMPL_JOINT_NAMES = (
    "pelvis", "left_hip", "right_hip", "spine1", "left_knee", "right_knee", "spine2", "left_ankle",
    "right_ankle", "spine3", "left_foot", "right_foot", "neck", "left_collar", "right_collar", "head",
    "left_shoulder", "right_shoulder", "left_elbow", "right_elbow", "left_wrist", "right_wrist",
    "left_hand", "right_hand",
)
SMPL_PARENTS = (-1, 0, 0, 0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 9, 9, 12, 13, 14, 16, 17, 18, 19, 20, 21)
REQUIRED_KEYS = ("v_template", "shapedirs", "posedirs", "J_regressor", "weights", "kintree_table", "f")


@dataclass
class BodyOutput:
    """Result of a body forward pass (field names as `smplx`'s ModelOutput).

    vertices (B, V, 3); joints (B, J, 3) kinematic joints, posed, with translation;
    full_pose (B, J*3) axis-angle; betas (B, nb); global_orient (B, 3); body_pose (B, (J-1)*3);
    transl (B, 3); joint_transforms (B, J, 4, 4) rest-to-posed skinning transforms.
    """

    vertices: torch.Tensor
    joints: torch.Tensor
    full_pose: torch.Tensor
    betas: torch.Tensor
    global_orient: torch.Tensor
    body_pose: torch.Tensor
    transl: torch.Tensor
    joint_transforms: torch.Tensor | None = field(default=None, repr=False)

    def keys(self):
        return [k for k in self.__dataclass_fields__ if getattr(self, k) is not None]

    def __getitem__(self, key):
        return getattr(self, key)


def load_smpl_arrays(path: str | Path) -> dict:
    """Read and validate an SMPL-format `.npz` file.

    Returns a dict of numpy arrays with the SMPL key names. Raises ValueError/FileNotFoundError
    with the reason and the fix for anything that is not a 24-joint SMPL file.
    """
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"body model file not found: {path}. Pass the path of an SMPL-format .npz "
                                f"(e.g. SMPL_NEUTRAL.npz) or call volsmpl.create_body() for the default body.")
    if path.suffix == ".pkl":
        raise ValueError(f"{path}: .pkl SMPL files need chumpy to unpickle; volsmpl reads .npz only. Convert it once "
                         f"with smplx's tools (or np.savez the arrays {REQUIRED_KEYS}) and pass the .npz.")
    try:
        with np.load(path, allow_pickle=False) as data:
            arrays = {k: data[k] for k in data.files}
    except Exception as e:  # zip/format errors
        raise ValueError(f"{path}: not a readable .npz file ({e}). Re-export or re-download the body model.") from e
    missing = [k for k in REQUIRED_KEYS if k not in arrays]
    if missing:
        raise ValueError(f"{path}: not an SMPL-format file, missing arrays {missing} (needs {REQUIRED_KEYS}). "
                         f"MANO/FLAME files are not supported; SMPL-H/SMPL-X files go through smplx.create(...).")
    V = arrays["v_template"].shape[0]
    J = arrays["weights"].shape[1] if arrays["weights"].ndim == 2 else -1
    if J != 24:
        raise ValueError(f"{path}: has {J} skinning joints; volsmpl.Body poses SMPL (24 joints) files only. "
                         f"For SMPL-H/SMPL-X models use smplx.create(...) and volsmpl.attach_volume(model).")
    checks = {
        "v_template": (V, 3), "weights": (V, 24), "J_regressor": (24, V),
    }
    for k, shape in checks.items():
        if tuple(arrays[k].shape) != shape:
            raise ValueError(f"{path}: array '{k}' has shape {arrays[k].shape}, expected {shape} for a body with {V} vertices.")
    if arrays["shapedirs"].ndim != 3 or arrays["shapedirs"].shape[:2] != (V, 3):
        raise ValueError(f"{path}: 'shapedirs' has shape {arrays['shapedirs'].shape}, expected ({V}, 3, num_betas).")
    if arrays["f"].ndim != 2 or arrays["f"].shape[1] != 3 or arrays["f"].max() >= V or arrays["f"].min() < 0:
        raise ValueError(f"{path}: 'f' must be (F, 3) vertex indices below {V}.")
    for k in ("v_template", "shapedirs", "weights", "J_regressor"):
        if not np.isfinite(arrays[k]).all():
            raise ValueError(f"{path}: array '{k}' contains NaN or Inf; the file is corrupt.")
    return arrays


class Body(torch.nn.Module):
    """SMPL-format LBS body (24 joints), batched and differentiable, CPU or CUDA.

    Args:
        model_path: SMPL-format .npz file (ours or an official SMPL_*.npz).
        num_betas: number of shape coefficients used (<= shapedirs' last dimension).
        batch_size: batch size used for parameters left out of forward().
    """

    model_type = "smpl"
    NUM_JOINTS = 23  # non-root joints, as smplx.SMPL.NUM_JOINTS

    def __init__(self, model_path: str | Path = DEFAULT_BODY_FILE, num_betas: int = 10, batch_size: int = 1):
        super().__init__()
        for name, value in (("num_betas", num_betas), ("batch_size", batch_size)):
            if isinstance(value, bool) or not isinstance(value, numbers.Integral):
                raise TypeError(f"{name} must be an int, got {type(value).__name__} {value!r}; pass e.g. "
                                f"{name}={10 if name == 'num_betas' else 1}.")
        if batch_size < 1:
            raise ValueError(f"batch_size={batch_size}: the batch size of parameters left out of forward() must be >= 1.")
        arrays = load_smpl_arrays(model_path)
        self.model_path = str(model_path)
        nb_avail = arrays["shapedirs"].shape[-1]
        if not 0 <= num_betas <= nb_avail:
            raise ValueError(f"num_betas={num_betas} but {model_path} has {nb_avail} shape components; use 0..{nb_avail}.")
        self.num_betas, self.num_betas_available = int(num_betas), int(nb_avail)
        self.batch_size = int(batch_size)
        self.fingerprint = body_fingerprint(arrays)
        parents = arrays["kintree_table"][0].astype(np.int64)
        parents[0] = -1  # SMPL stores 4294967295
        if not all(0 <= parents[j] < j for j in range(1, len(parents))):
            raise ValueError(f"{model_path}: kintree_table parents must satisfy 0 <= parent[j] < j.")
        names = arrays.get("joint_names")
        self.joint_names = tuple(str(n) for n in names) if names is not None else SMPL_JOINT_NAMES
        self.faces = arrays["f"].astype(np.int64)
        f32 = torch.float32
        self.register_buffer("v_template", torch.as_tensor(arrays["v_template"], dtype=f32))
        self.register_buffer("shapedirs", torch.as_tensor(arrays["shapedirs"][..., :num_betas], dtype=f32))
        self.register_buffer("J_regressor", torch.as_tensor(arrays["J_regressor"], dtype=f32))
        self.register_buffer("lbs_weights", torch.as_tensor(arrays["weights"], dtype=f32))
        self.register_buffer("parents", torch.as_tensor(parents))
        self.parent_list = [int(p) for p in parents]  # the same on the host: forward kinematics reads no device value
        order, parent, self._chain_sizes = kinematic_levels(self.parent_list)  # forward kinematics by depth
        self.register_buffer("_chain_order", order, persistent=False)
        self.register_buffer("_chain_parent", parent, persistent=False)
        self.register_buffer("faces_tensor", torch.as_tensor(self.faces))
        posedirs = arrays["posedirs"].reshape(-1, arrays["posedirs"].shape[-1]).T  # (P, V*3)
        self.has_posedirs = bool(np.any(posedirs))
        self.register_buffer("posedirs", torch.as_tensor(posedirs, dtype=f32) if self.has_posedirs else torch.zeros(0))

    @property
    def num_joints(self) -> int:
        return int(self.parents.shape[0])

    def _param(self, name: str, value, width: int, batch: int, like: torch.Tensor) -> torch.Tensor:
        if value is None:
            return torch.zeros(batch, width, dtype=like.dtype, device=like.device)
        if not torch.is_tensor(value):
            raise TypeError(f"{name} must be a torch.Tensor of shape (B, {width}), got {type(value).__name__}")
        if value.ndim == 1 and value.shape[0] == width:
            value = value[None]
        if name == "betas" and value.ndim == 2 and value.shape[1] != width:
            n, avail = value.shape[1], self.num_betas_available
            fix = (f"create the body with volsmpl.create_body(num_betas={n}) (this file has {avail} components)"
                   if n <= avail else f"this file has {avail} shape components: pass at most {avail} columns")
            raise ValueError(f"betas has {n} columns but the body was created with num_betas={width}; {fix}, or pass "
                             f"betas of shape (B, {width}).")
        if value.ndim != 2 or value.shape[1] != width:
            raise ValueError(f"{name} has shape {tuple(value.shape)}, expected (B, {width})"
                             + (f"; reshape (B, {width // 3}, 3) axis-angle with .reshape(B, -1)" if width % 3 == 0 and name != "betas" else ""))
        if value.shape[0] != batch:
            raise ValueError(f"{name} has batch size {value.shape[0]} but other inputs have {batch}; give all parameters the same B.")
        if value.dtype != like.dtype or value.device != like.device:
            raise ValueError(f"{name} is {value.dtype} on {value.device} but the body is {like.dtype} on {like.device}; "
                             f"move one with .to(...) (e.g. body.to(device, dtype)).")
        return value

    def forward(self, betas=None, global_orient=None, body_pose=None, transl=None, **unused) -> BodyOutput:
        """Pose the body.

        Args:
            betas: (B, num_betas); global_orient: (B, 3); body_pose: (B, 69); transl: (B, 3).
                Missing ones are zeros with the batch size of the given ones (else self.batch_size).
        Returns:
            BodyOutput with vertices (B, V, 3), joints (B, 24, 3), full_pose (B, 72), ...
        """
        unknown = [k for k, v in unused.items() if v is not None and k not in ("return_verts", "return_full_pose")]
        if unknown:
            raise TypeError(f"Body.forward got unexpected arguments {unknown}; it takes betas, global_orient, body_pose, transl.")
        given = [v for v in (betas, global_orient, body_pose, transl) if torch.is_tensor(v)]
        batched = [v for v in given if v.ndim == 2]  # the batch of the first (B, width) one: a 1-D one is a batch of 1
        B = batched[0].shape[0] if batched else (1 if given else self.batch_size)
        if B < 1:
            params = dict(betas=betas, global_orient=global_orient, body_pose=body_pose, transl=transl)
            empty = [f"{k} has shape {tuple(v.shape)}" for k, v in params.items() if torch.is_tensor(v) and v.shape[:1] == (0,)]
            raise ValueError(f"Body.forward got a batch of 0 bodies ({empty[0] if empty else f'batch_size={B}'}); give "
                             f"at least one body: parameters of shape (B, ...) with B >= 1 (skip the call when there "
                             f"is nothing to pose).")
        like = self.v_template
        J = self.num_joints
        supplied = [k for k, v in (("betas", betas), ("global_orient", global_orient), ("body_pose", body_pose),
                                   ("transl", transl)) if v is not None]
        betas = self._param("betas", betas, self.num_betas, B, like)
        global_orient = self._param("global_orient", global_orient, 3, B, like)
        body_pose = self._param("body_pose", body_pose, (J - 1) * 3, B, like)
        transl = self._param("transl", transl, 3, B, like)
        if supplied:  # zeros stand for the others
            values = dict(betas=betas, global_orient=global_orient, body_pose=body_pose, transl=transl)
            finite = torch.stack([torch.isfinite(values[k]).all() for k in supplied]).tolist()  # one device read
            for name, ok in zip(supplied, finite):
                if not ok:
                    raise ValueError(f"{name} contains NaN or Inf.")

        full_pose = torch.cat([global_orient, body_pose], dim=1)
        v_shaped = shape_blend(self.v_template, self.shapedirs, betas)
        rest_joints = torch.einsum("jv,bvc->bjc", self.J_regressor, v_shaped)
        rot_mats = rodrigues(full_pose)
        v_posed = v_shaped + pose_blend(rot_mats, self.posedirs if self.has_posedirs else None)
        _, posed_joints, skin = rigid_chain(rot_mats, rest_joints, self.parent_list, self.chain_levels)
        vertices = skin_vertices(v_posed, self.lbs_weights, skin) + transl[:, None]
        skin = skin.clone()
        skin[..., :3, 3] = skin[..., :3, 3] + transl[:, None]
        return BodyOutput(vertices=vertices, joints=posed_joints + transl[:, None], full_pose=full_pose, betas=betas,
                          global_orient=global_orient, body_pose=body_pose, transl=transl, joint_transforms=skin)

    @property
    def chain_levels(self) -> tuple:
        """`lbs.kinematic_levels` of this body's tree, on its device (pass to `lbs.rigid_chain`)."""
        return self._chain_order, self._chain_parent, self._chain_sizes

    def extra_repr(self) -> str:
        return f"model_path={self.model_path}, vertices={self.v_template.shape[0]}, num_betas={self.num_betas}, fingerprint={self.fingerprint}"


def create_body(model_path: str | Path | None = None, num_betas: int = 10, batch_size: int = 1) -> Body:
    """The default body (Anny exported to SMPL format), or an SMPL-format file given by path."""
    if model_path is None:
        if not DEFAULT_BODY_FILE.exists():
            raise FileNotFoundError(f"the default body file {DEFAULT_BODY_FILE} is missing from the installation; "
                                    f"regenerate it with `volsmpl body export` (needs `pip install anny==0.6.2`).")
        model_path = DEFAULT_BODY_FILE
    return Body(model_path, num_betas=num_betas, batch_size=batch_size)


def default_body_metadata() -> dict:
    """Metadata written by the exporter next to the default body (anny_body.json)."""
    meta = ASSETS / "anny_body.json"
    if not meta.exists():
        raise FileNotFoundError(f"{meta} is missing; regenerate the default body with `volsmpl body export`.")
    return json.loads(meta.read_text())
