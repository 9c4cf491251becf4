"""Pictures of a learned field: an SDF slice through the body with the true mesh contour, and the
marching-cubes surface beside the true mesh."""
from __future__ import annotations

import cv2
import numpy as np
import torch
import trimesh

from volsmpl.viz.render import grid, render_mesh
from volsmpl.body.view import select_body


def sdf_slice(volume, out, faces: np.ndarray, axis: int = 2, size: int = 384, margin: float = 0.1) -> np.ndarray:
    """RGB image (size, size, 3) of the field on the plane through the pelvis normal to `axis` (2: frontal plane).

    Colours: signed distance (blue inside, red outside, white at 0; occupancy fields are shown as 0.5 - occ),
    black: the learned zero level set, green: the exact section of the posed mesh.
    """
    v = out.vertices[0].detach()
    c = out.joints[0, 0].detach()
    axes = [a for a in range(3) if a != axis]
    lo, hi = v.amin(0) - margin, v.amax(0) + margin
    half = 0.5 * float(max(hi[axes[0]] - lo[axes[0]], hi[axes[1]] - lo[axes[1]]))
    mid = 0.5 * (lo + hi)
    u = torch.linspace(float(mid[axes[0]]) - half, float(mid[axes[0]]) + half, size, dtype=v.dtype)
    w = torch.linspace(float(mid[axes[1]]) + half, float(mid[axes[1]]) - half, size, dtype=v.dtype)  # image rows go down
    W, U = torch.meshgrid(w, u, indexing="ij")
    pts = torch.empty(size * size, 3, dtype=v.dtype)
    pts[:, axes[0]], pts[:, axes[1]], pts[:, axis] = U.reshape(-1), W.reshape(-1), c[axis]
    with torch.no_grad():
        f = volume.query(select_body(out, 0), pts[None])[0].reshape(size, size).numpy()
    d = f if volume.is_sdf else (volume.level - f) * 0.1  # occupancy: map to a pseudo-distance for colouring
    t = np.clip(d / 0.1, -1, 1)
    img = np.empty((size, size, 3), np.float64)
    img[..., 0] = np.where(t > 0, 1.0, 1.0 + t)       # R
    img[..., 2] = np.where(t < 0, 1.0, 1.0 - t)       # B
    img[..., 1] = 1.0 - np.abs(t)                     # G
    img = (img * 255).astype(np.uint8)
    zero = (d < 0).astype(np.uint8)
    cnts, _ = cv2.findContours(zero, cv2.RETR_LIST, cv2.CHAIN_APPROX_NONE)
    cv2.drawContours(img, cnts, -1, (0, 0, 0), 1, cv2.LINE_AA)
    mesh = trimesh.Trimesh(v.numpy(), faces, process=False)
    normal = np.zeros(3)
    normal[axis] = 1.0
    sec = mesh.section(plane_origin=c.numpy(), plane_normal=normal)
    if sec is not None:
        scale = (size - 1) / (2 * half)
        for seg in sec.discrete:
            px = np.stack([(seg[:, axes[0]] - (float(mid[axes[0]]) - half)) * scale,
                           ((float(mid[axes[1]]) + half) - seg[:, axes[1]]) * scale], -1)
            cv2.polylines(img, [np.round(px * 16).astype(np.int32)], False, (0, 160, 0), 1, cv2.LINE_AA, shift=4)
    return img


def surfaces_side_by_side(volume, out, faces: np.ndarray, resolution: int = 128, size: int = 384) -> np.ndarray:
    """Marching-cubes mesh of the learned field (left) beside the true posed mesh (right), RGB image."""
    learned = volume.extract_mesh(out, resolution=resolution)
    true_v = out.vertices[0].detach().numpy()
    ext = float((true_v.max(0) - true_v.min(0)).max()) * 1.05
    a = render_mesh(learned.vertices, learned.faces, None, size=size, yaw=25, pitch=8, extent=ext)
    b = render_mesh(true_v, faces, None, size=size, yaw=25, pitch=8, extent=ext)
    return grid([a, b], ["learned (marching cubes)", "true mesh"], cols=2)
