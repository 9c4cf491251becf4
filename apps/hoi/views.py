"""The three views of one human–object placement in a case figure (apps/hoi/figures.py), each framed on what it
shows so the body fills its panel, with the object's vertices inside the body drawn on top in red (large, never
hidden by the body's surface):

- `camera_view`: through the case's camera, zoomed onto the bounding box of the body and the object, over the
  case's image (greyed, so its own marks do not read as ours) where there is one;
- `close_up`: orthographic, halfway between the camera's direction and the side view's (45 deg or so about the
  vertical from each, the world's vertical kept upright: an object off in depth, which the camera's view hides,
  shows beside the body), framed on the contact: the body parts in contact and the object near them (the whole
  object when it is small), and the object's vertices inside the body;
- `side_view`: orthographic, from the side of the body: the view turned 90 deg about the vertical axis of the body's
  frame (the body model's Y up) from the body's front (its pelvis' forward direction; a lying body's spine), to
  the side where the object is.

The close-up and the side view are drawn in the body's frame (the camera frame taken back through the human's
similarity), where up is up. Only triangles near the close-up's frame are drawn, and triangles are split relative
to what is shown, so a large object costs no more than a small one.

    views = PlacementViews(vertices, faces, obj_vertices, obj_faces, inside, human, part_vertices, facing)
    side = views.object_side()     # one side for every placement of a case
    panels = [views.camera_view(K, image, 300), views.close_up(300, side), views.side_view(300, side)]
"""
from __future__ import annotations

import cv2
import numpy as np
from volsmpl.viz.render import (
    render_camera_view,
    render_scene,
    scene_pixels,
    scene_view,
)

__all__ = ["BODY", "INSIDE", "OBJECT", "PlacementViews", "body_facing"]

BODY, OBJECT, INSIDE = (0.78, 0.78, 0.78), (0.35, 0.55, 0.85), (0.9, 0.1, 0.1)
NEAR_M = 0.15  # metres: the close-up shows the object within this distance of the contact parts
SMALL_OBJECT_M = 0.6  # metres: an object no larger than this is shown whole in the close-up
MIN_CLOSE_UP_M = 0.12  # metres: the close-up's smallest width
SPLIT = 12  # triangles are split to 1/SPLIT of what a view shows (painter's order between body and object)


def body_facing(global_orient) -> np.ndarray:
    """The horizontal direction (body model frame, Y up) the body's front faces: its pelvis' forward (+Z) turned by
    global_orient (axis-angle); for a body lying down, its spine's direction (+Y turned) instead, so a side view
    looks across it. (3,) unit vector with y = 0."""
    from scipy.spatial.transform import Rotation

    R = Rotation.from_rotvec(np.asarray(global_orient, dtype=np.float64).reshape(3)).as_matrix()
    for axis in (R[:, 2], R[:, 1]):
        f = np.array([axis[0], 0.0, axis[2]])
        if np.linalg.norm(f) > 0.5:
            return f / np.linalg.norm(f)
    return np.array([0.0, 0.0, 1.0])


def _yaw_pitch(toward_viewer: np.ndarray) -> tuple[float, float]:
    """render_scene's yaw and pitch (degrees) that turn `toward_viewer` (the direction from the scene to the
    viewer, Y up) onto the view's +Z: the viewer looks along its opposite, the world's vertical kept upright."""
    a = np.asarray(toward_viewer, dtype=np.float64)
    h = float(np.hypot(a[0], a[2]))
    return float(-np.degrees(np.arctan2(a[0], a[2]))), float(np.degrees(np.arctan2(a[1], h)))


def _dots(img: np.ndarray, px: np.ndarray, radius: int) -> np.ndarray:
    """The inside points drawn on top: red discs with a dark rim, (P, 2) pixel centres."""
    rgb = tuple(int(c * 255) for c in INSIDE)
    for x, y in np.round(px * 16).astype(np.int64):
        cv2.circle(img, (int(x), int(y)), (radius + 1) * 16, (90, 0, 0), -1, cv2.LINE_AA, 4)
        cv2.circle(img, (int(x), int(y)), radius * 16, rgb, -1, cv2.LINE_AA, 4)
    return img


def _frame(points: np.ndarray, yaw: float, pitch: float, margin: float, least: float = 1e-3):
    """(center (3,) world, extent) that frame `points` in a view at yaw/pitch, `margin` times their larger side."""
    q = scene_view(points, yaw, pitch)
    lo, hi = q[:, :2].min(0), q[:, :2].max(0)
    c2 = 0.5 * (lo + hi)
    extent = max(float((hi - lo).max()) * margin, least)
    # the world point at the image centre: view (c2, 0) taken back (the view rotation is orthonormal)
    center = np.linalg.solve(scene_view(np.eye(3), yaw, pitch).T, np.array([c2[0], c2[1], 0.0]))
    return center, extent


def _split(meshes: list, max_edge: float) -> list:
    """The object's triangles (all but the first mesh, the body's, whose triangles are small already) split until
    none is longer than max_edge, for painter's order between a box's few large faces and the body."""
    import trimesh

    out = [meshes[0]]
    for v, f, rgb in meshes[1:]:
        if len(f):
            v, f = trimesh.remesh.subdivide_to_size(v, f, max_edge, max_iter=8)
        out.append((v, f, rgb))
    return out


def _within(meshes, yaw: float, pitch: float, center, extent: float) -> list:
    """The meshes cut to the triangles whose view bounding box meets the frame (a little wider): what a
    close-up draws (a mesh may be left without triangles)."""
    c2 = scene_view(np.asarray(center)[None], yaw, pitch)[0, :2]
    half = 0.55 * extent / 0.9
    out = []
    for v, f, rgb in meshes:
        q = scene_view(v, yaw, pitch)[:, :2][f]  # (F, 3, 2)
        out.append((v, f[((q.min(1) <= c2 + half) & (q.max(1) >= c2 - half)).all(1)], rgb))
    return out


class PlacementViews:
    """One placement's geometry in the camera frame: the body's vertices (V, 3) and faces, the object's vertices
    and faces (what is drawn), `inside` (K, 3), the object's points inside the body; `human`, the body's
    similarity into the camera frame (case.Similarity); `part_vertices` (P, 3), the contact parts' vertices in the
    body's frame (may be empty); `facing`, the body's front (body_facing); `coarse`: optional (vertices, faces)
    of the same body with fewer triangles, drawn in the wide views (the close-up draws the full body);
    `obj_points`: optional (N, 3) points spread evenly over the object (camera frame) that frame the close-up
    (default: its vertices, too sparse on a box)."""

    def __init__(self, vertices, faces, obj_vertices, obj_faces, inside, human, part_vertices, facing,
                 coarse=None, obj_points=None):
        self.v, self.f = np.asarray(vertices, np.float64), np.asarray(faces, np.int64)
        self.o, self.of = np.asarray(obj_vertices, np.float64), np.asarray(obj_faces, np.int64)
        self.ins = np.asarray(inside, np.float64).reshape(-1, 3)
        self.human = human
        self.part = np.asarray(part_vertices, np.float64).reshape(-1, 3)
        self.facing = np.asarray(facing, np.float64)
        cv, cf = coarse if coarse is not None else (self.v, self.f)
        self.cv, self.cf = np.asarray(cv, np.float64), np.asarray(cf, np.int64)
        self.op = self.o if obj_points is None else np.asarray(obj_points, np.float64).reshape(-1, 3)

    def _to_body(self, x: np.ndarray) -> np.ndarray:
        """Camera frame -> the body's frame (the human's similarity undone)."""
        h = self.human
        return (np.asarray(x) - h.translation) @ h.rotation / h.scale

    def _meshes(self, frame: str = "body", coarse: bool = True):
        """[(body), (object)] as render_scene's meshes and the inside points, in the body's or the camera frame."""
        v, f = (self.cv, self.cf) if coarse else (self.v, self.f)
        move = (lambda x: x) if frame == "camera" else self._to_body
        return [(move(v), f, BODY), (move(self.o), self.of, OBJECT)], move(self.ins)

    def camera_view(self, K, image: np.ndarray | None, size: int) -> np.ndarray:
        """Through the case's camera (K (3, 3)), zoomed onto the bounding box of the body and the object in the
        image, `size` x `size`, over the image (greyed) where one is given."""
        import torch
        from kornia.geometry.camera import PinholeCamera

        K = np.asarray(K, np.float64)
        meshes, ins = self._meshes("camera")
        pts = np.concatenate([self.cv, self.o])
        pts = pts[pts[:, 2] > 0.05]
        if len(pts):
            uv = pts[:, :2] / pts[:, 2:] * K.diagonal()[:2] + K[:2, 2]
            lo, hi = uv.min(0), uv.max(0)
        else:  # all behind the camera: the whole image
            lo, hi = np.zeros(2), 2 * K[:2, 2]
        side = max(float((hi - lo).max()) * 1.12, 16.0)
        s, x0 = size / side, 0.5 * (lo + hi) - side / 2
        K2 = K.copy()
        K2[:2, :2] *= s
        K2[:2, 2] = (K[:2, 2] - x0) * s
        K4 = torch.eye(4, dtype=torch.float64)[None]
        K4[0, :3, :3] = torch.as_tensor(K2)
        cam = PinholeCamera(K4, torch.eye(4, dtype=torch.float64)[None], torch.tensor([float(size)]),
                            torch.tensor([float(size)]))
        extent = float(np.ptp(np.concatenate([self.cv, self.o]), axis=0).max())
        img = render_camera_view(_split(meshes, extent / SPLIT), cam, max_edge=None)
        if image is not None:
            M = np.float32([[s, 0, -x0[0] * s], [0, s, -x0[1] * s]])
            grey = cv2.cvtColor(cv2.cvtColor(image, cv2.COLOR_RGB2GRAY), cv2.COLOR_GRAY2RGB)
            bg = cv2.warpAffine((0.55 * grey + 0.45 * 255).astype(np.uint8), M, (size, size), flags=cv2.INTER_AREA,
                                borderValue=(255, 255, 255))
            drawn = (img != 255).any(-1)
            bg[drawn] = (0.8 * img[drawn] + 0.2 * bg[drawn]).astype(np.uint8)
            img = bg
        ins = ins[ins[:, 2] > 0.05]
        if len(ins):
            _dots(img, ins[:, :2] / ins[:, 2:] * K2.diagonal()[:2] + K2[:2, 2], max(2, size // 110))
        return img

    def close_up(self, size: int, side: int | None = None) -> np.ndarray:
        """Orthographic, halfway between the camera's direction and the side view's (module docstring; side as
        in side_view), framed on the contact parts, the object near them (whole when small) and the object's
        vertices inside the body."""
        from scipy.spatial import cKDTree

        meshes, ins = self._meshes(coarse=False)
        body_v, obj_v = meshes[0][0], self._to_body(self.op)
        yaw_cam, pitch = _yaw_pitch(self.human.rotation.T @ np.array([0.0, 0.0, -1.0]))
        yaw_side = _yaw_pitch(self._side_axis(side))[0]
        yaw = yaw_cam + ((yaw_side - yaw_cam + 180.0) % 360.0 - 180.0) / 2  # the middle of the shorter arc
        obj_small = float(np.ptp(obj_v, axis=0).max()) <= SMALL_OBJECT_M
        if len(self.part):
            near = cKDTree(self.part).query(obj_v, distance_upper_bound=NEAR_M)[0] < NEAR_M
            show = [self.part, obj_v if obj_small or not near.any() else obj_v[near]]
        else:  # no contact named: the body near the object, and the object
            near = cKDTree(obj_v).query(body_v, distance_upper_bound=NEAR_M)[0] < NEAR_M
            show = [body_v[near] if near.any() else body_v[cKDTree(body_v).query(obj_v.mean(0))[1]][None], obj_v]
        center, extent = _frame(np.concatenate(show + [ins]), yaw, pitch, 1.25, MIN_CLOSE_UP_M)
        kept = _within(_split(_within(meshes, yaw, pitch, center, extent), extent / SPLIT), yaw, pitch, center, extent)
        kept = [m for m in kept if len(m[1])]  # cut, split, and cut again: a shelf's pieces outside are dropped
        img = (render_scene(kept, size, yaw, pitch, extent, center, max_edge=None) if kept
               else np.full((size, size, 3), 255, np.uint8))
        if len(ins):
            _dots(img, scene_pixels(ins, size, yaw, pitch, extent, center), max(3, size // 60))
        return img

    def object_side(self) -> int:
        """+1 or -1: the side of the body the object is on (which way `side_view` looks from), its front turned
        90 deg about the vertical one way or the other."""
        meshes, _ = self._meshes()
        f = self.facing
        return 1 if np.array([f[2], 0.0, -f[0]]) @ (meshes[1][0].mean(0) - meshes[0][0].mean(0)) >= 0 else -1

    def _side_axis(self, side: int | None) -> np.ndarray:
        """The direction from the body to the side view's viewer (body frame): its front turned 90 deg about the
        vertical, to `side` (default: the object's)."""
        f = self.facing
        return np.array([f[2], 0.0, -f[0]]) * (self.object_side() if side is None else side)

    def side_view(self, size: int, side: int | None = None) -> np.ndarray:
        """Orthographic, from the side of the body (module docstring), framed on the body and the object; side
        +1 / -1 (object_side; default: this placement's), so that the views of a case's placements match."""
        meshes, ins = self._meshes()
        yaw, pitch = _yaw_pitch(self._side_axis(side))
        center, extent = _frame(np.concatenate([meshes[0][0], meshes[1][0]]), yaw, pitch, 1.0)
        img = render_scene(_split(meshes, extent / SPLIT), size, yaw, pitch, extent, center, max_edge=None)
        if len(ins):
            _dots(img, scene_pixels(ins, size, yaw, pitch, extent, center), max(2, size // 90))
        return img
