"""One case's body as a posable rig: pose helpers, forward kinematics and the hands' inverse kinematics.

What it holds: Euler-angle pose helpers on the 23 body joints (`named_euler`, `clip_limits`, `jitter`, `set_joints`,
all within `JOINT_LIMITS`), `euler_matrix` (one joint's local rotation), and `Rig`: one case's body (shape, rest joints,
palm reference points) with forward kinematics of the 24 joints in torch (`Rig.fk`, `Rig.joints`, `Rig.palm`), the body
model's output (`Rig.pose`, `Rig.part_vertices`) and a small inverse kinematics bringing the palms onto targets
(`Rig.reach`: the arm chains' angles bounded by the anatomical limits through a sigmoid, solved by L-BFGS).
The interaction recipes built on it are in interactions.py.

Conventions: the body frame of an upright body (Y up, facing +Z, transl 0); angles in radians, in
`volsmpl.body.poses.EULER_ORDER` per joint.
"""
from __future__ import annotations

import numpy as np
import torch
from scipy.spatial.transform import Rotation

from volsmpl.body.model import SMPL_JOINT_NAMES, SMPL_PARENTS
from volsmpl.body.poses import BODY_JOINTS, EULER_ORDER, JOINT_LIMITS, NAMED_POSES, euler_to_body_pose

__all__ = ["ARM", "named_euler", "clip_limits", "jitter", "set_joints", "euler_matrix", "Rig"]

_LIM = np.array([JOINT_LIMITS[j] for j in BODY_JOINTS])  # (23, 3, 2)
_J = {n: i for i, n in enumerate(SMPL_JOINT_NAMES)}
ARM = {s: [f"{s}_collar", f"{s}_shoulder", f"{s}_elbow", f"{s}_wrist"] for s in ("left", "right")}


def named_euler(name: str) -> np.ndarray:
    """(23, 3) Euler angles of a named pose."""
    e = np.zeros((23, 3))
    for joint, angles in NAMED_POSES[name].items():
        e[BODY_JOINTS.index(joint)] = angles
    return e


def clip_limits(e: np.ndarray, margin: float = 1e-4) -> np.ndarray:
    return np.clip(e, _LIM[..., 0] + margin, _LIM[..., 1] - margin)


def jitter(e: np.ndarray, rng: np.random.Generator, sd: float = 0.06, joints=None) -> np.ndarray:
    """Seeded variation: Gaussian (sd radians, clipped at 2 sd) on the given joints (default all), within limits."""
    e = e.copy()
    idx = range(23) if joints is None else [BODY_JOINTS.index(j) for j in joints]
    for i in idx:
        e[i] += np.clip(rng.standard_normal(3), -2, 2) * sd
    return clip_limits(e)


def set_joints(e: np.ndarray, **joints) -> np.ndarray:
    """Set the Euler angles of the named joints of e (23, 3) in place; returns e."""
    for j, v in joints.items():
        e[BODY_JOINTS.index(j)] = v
    return e


# ----------------------------------------------------------------------------------------------- kinematics
def euler_matrix(ang: torch.Tensor, order: str) -> torch.Tensor:
    """(3,) angles (x, y, z) -> (3, 3), intrinsic rotations in `order` (scipy's upper-case convention)."""
    out = torch.eye(3, dtype=ang.dtype)
    for a in order:
        i = "XYZ".index(a)
        c, s = torch.cos(ang[i]), torch.sin(ang[i])
        one, zero = torch.ones_like(c), torch.zeros_like(c)
        if a == "X":
            m = torch.stack([one, zero, zero, zero, c, -s, zero, s, c])
        elif a == "Y":
            m = torch.stack([c, zero, s, zero, one, zero, -s, zero, c])
        else:
            m = torch.stack([c, -s, zero, s, c, zero, zero, zero, one])
        out = out @ m.reshape(3, 3)
    return out


class Rig:
    """The body of one case: shape, rest joints and hand/foot reference points, with forward kinematics.

    palm(side): a point on the palm's skin (mean of the palm vertices), its outward normal and the finger
    direction, rigidly attached to the hand joint."""

    def __init__(self, body, partition, betas: torch.Tensor):
        self.body, self.partition, self.betas = body, partition, betas.reshape(1, -1)
        with torch.no_grad():
            out = body(betas=self.betas)
        self.rest_joints = out.joints[0].double()
        v = out.vertices[0].double().numpy()
        import trimesh
        nrm = trimesh.Trimesh(v, partition.faces.numpy(), process=False).vertex_normals
        lab = partition.vertex_labels.numpy()
        names = partition.table.part_names
        self.palm_rest = {}
        for side, sign in (("left", 1.0), ("right", -1.0)):
            wx = float(self.rest_joints[_J[f"{side}_wrist"], 0])
            x = sign * (v[:, 0] - wx)
            sel = (lab == names.index(f"{side}_hand")) & (nrm[:, 1] < -0.6) & (x > 0.02) & (x < 0.10)
            self.palm_rest[side] = torch.as_tensor(v[sel].mean(0))
        self.parents = SMPL_PARENTS

    def fk(self, euler: torch.Tensor, global_R: torch.Tensor):
        """euler (23, 3) -> global rotations (24, 3, 3), joint positions (24, 3) (transl 0)."""
        Rs, P = [global_R], [self.rest_joints[0]]
        for j in range(1, 24):
            p = self.parents[j]
            loc = euler_matrix(euler[j - 1], EULER_ORDER[BODY_JOINTS[j - 1]])
            Rs.append(Rs[p] @ loc)
            P.append(P[p] + Rs[p] @ (self.rest_joints[j] - self.rest_joints[p]))
        return torch.stack(Rs), torch.stack(P)

    def palm(self, R, P, side: str):
        """Palm point, outward palm normal, finger direction from fk output."""
        h = _J[f"{side}_hand"]
        sign = 1.0 if side == "left" else -1.0
        p = P[h] + R[h] @ (self.palm_rest[side] - self.rest_joints[h])
        n = R[h] @ torch.tensor([0.0, -1.0, 0.0], dtype=R.dtype)
        f = R[h] @ torch.tensor([sign, 0.0, 0.0], dtype=R.dtype)
        return p, n, f

    def reach(self, euler: np.ndarray, global_R: np.ndarray, targets: dict, iters: int = 60) -> tuple[np.ndarray, float]:
        """Move the arms (collar, shoulder, elbow, wrist) so that each side's palm meets its target.

        targets: {side: {'p': (3,) palm point, 'n': (3,) palm normal (optional), 'f': (3,) finger direction
        (optional)}}, in the body frame. Angles stay inside JOINT_LIMITS (sigmoid bounds). Returns the new
        euler (23, 3) and the largest palm position error (m)."""
        sides = list(targets)
        idx = [BODY_JOINTS.index(j) for s in sides for j in ARM[s]]
        lo = torch.as_tensor(_LIM[idx, :, 0]) + 1e-4
        hi = torch.as_tensor(_LIM[idx, :, 1]) - 1e-4
        x0 = torch.as_tensor(np.clip(euler[idx], lo.numpy() + 1e-3, hi.numpy() - 1e-3))
        u0 = (x0 - lo) / (hi - lo)
        theta = torch.log(u0 / (1 - u0)).clone().requires_grad_(True)
        gR = torch.as_tensor(global_R, dtype=torch.float64)
        with torch.no_grad():  # the trunk is fixed: only the arm chains move
            R0, P0 = self.fk(torch.as_tensor(euler), gR)
        tg = {s: {k: torch.as_tensor(np.asarray(v, dtype=np.float64)) for k, v in t.items()} for s, t in targets.items()}
        chains = {s: [_J[j] for j in ARM[s]] + [_J[f"{s}_hand"]] for s in sides}
        hand_local = {s: euler_matrix(torch.as_tensor(euler[_J[f"{s}_hand"] - 1]), EULER_ORDER[f"{s}_hand"]) for s in sides}

        def arm_fk(ang, s):
            """ang (4, 3): collar..wrist -> hand joint rotation and position."""
            j0 = chains[s][0]
            p = self.parents[j0]
            R, P = R0[p], P0[p]
            for k, j in enumerate(chains[s]):
                P = P + R @ (self.rest_joints[j] - self.rest_joints[self.parents[j]])
                loc = euler_matrix(ang[k], EULER_ORDER[BODY_JOINTS[j - 1]]) if k < 4 else hand_local[s]
                R = R @ loc
            return R, P

        def palm_of(ang, s):
            R, P = arm_fk(ang, s)
            sign = 1.0 if s == "left" else -1.0
            p = P + R @ (self.palm_rest[s] - self.rest_joints[_J[f"{s}_hand"]])
            return p, -R[:, 1], sign * R[:, 0]

        def loss_fn():
            a = lo + (hi - lo) * torch.sigmoid(theta)
            loss = 1e-3 * ((a - x0) ** 2).sum()
            for i, s in enumerate(sides):
                t = tg[s]
                p, n, f = palm_of(a[4 * i:4 * i + 4], s)
                loss = loss + 1e3 * ((p - t["p"]) ** 2).sum()
                if "n" in t:
                    loss = loss + 2.0 * (1 - n @ t["n"])
                if "f" in t:
                    loss = loss + 0.5 * (1 - f @ t["f"])
            return loss

        opt = torch.optim.LBFGS([theta], lr=1, max_iter=iters, line_search_fn="strong_wolfe")

        def closure():
            opt.zero_grad()
            loss = loss_fn()
            loss.backward()
            return loss

        opt.step(closure)
        with torch.no_grad():
            a = lo + (hi - lo) * torch.sigmoid(theta)
            err = max(float((palm_of(a[4 * i:4 * i + 4], s)[0] - tg[s]["p"]).norm()) for i, s in enumerate(sides))
            e = euler.copy()
            e[idx] = np.round(a.numpy(), 6)
        return e, err

    def joints(self, euler: np.ndarray, global_R: np.ndarray):
        with torch.no_grad():
            return self.fk(torch.as_tensor(euler), torch.as_tensor(global_R, dtype=torch.float64))

    def pose(self, euler: np.ndarray, global_R: np.ndarray):
        """Body output (float32) of euler angles and a root rotation."""
        go = torch.as_tensor(Rotation.from_matrix(global_R).as_rotvec(), dtype=torch.float32)[None]
        with torch.no_grad():
            return self.body(betas=self.betas, global_orient=go, body_pose=euler_to_body_pose(euler[None]))

    def part_vertices(self, vertices: np.ndarray, *parts: str) -> np.ndarray:
        names = self.partition.table.part_names
        lab = self.partition.vertex_labels.numpy()
        return vertices[np.isin(lab, [names.index(p) for p in parts])]
