"""Scene rendering: render_scene agrees with render_mesh, colours and dots, the camera view matches the camera's
projection, near-plane clipping, keypoints."""
from __future__ import annotations

import numpy as np
import torch
import trimesh

from volsmpl.viz.render import draw_keypoints, render_camera_view, render_mesh, render_scene
from volsmpl.scene.camera import make_camera, project

WHITE = np.array([255, 255, 255])


def test_render_scene_one_mesh_equals_render_mesh():
    m = trimesh.creation.icosphere(2, radius=0.5)
    col = np.random.default_rng(0).random((len(m.faces), 3))
    a = render_mesh(m.vertices, m.faces, col, 128, yaw=30, pitch=20)
    b = render_scene([(m.vertices, m.faces, col)], 128, yaw=30, pitch=20, max_edge=None)
    assert np.array_equal(a, b)


def test_render_scene_colours_and_dots():
    left = trimesh.creation.box(extents=(1, 1, 1)).apply_translation([-1, 0, 0])
    right = trimesh.creation.box(extents=(1, 1, 1)).apply_translation([1, 0, 0])
    img = render_scene([(left.vertices, left.faces, (1, 0, 0)), (right.vertices, right.faces, (0, 0, 1))], 200)
    h, w = img.shape[:2]
    lp, rp = img[h // 2, w // 4].astype(int), img[h // 2, 3 * w // 4].astype(int)
    assert lp[0] > 100 and lp[2] == 0 and rp[2] > 100 and rp[0] == 0  # each box in its own colour
    # a dot in front of the right box is drawn; one behind it is hidden (same painter's order as the triangles)
    pts = np.array([[1.0, 0.0, 0.8], [1.0, 0.3, -0.8]])
    img = render_scene([(right.vertices, right.faces, (0, 0, 1))], 200, points=pts,
                       point_colors=np.array([[1, 0, 0], [0, 1, 0]]), point_radius=3, extent=4.0,
                       center=[1.0, 0.0, 0.0])
    assert (img[100, 100] == [255, 0, 0]).all()
    green = (img[..., 1] > 200) & (img[..., 0] < 50)
    assert not green.any()


def test_camera_view_matches_projection():
    box = trimesh.creation.box(extents=(0.6, 0.6, 0.6)).apply_translation([0.2, 1.0, 0.0])
    cam = make_camera([0.5, 1.6, 2.5], [0.0, 1.0, 0.0], (240, 320), 60.0)
    img = render_camera_view([(box.vertices, box.faces, (0.2, 0.6, 0.3))], cam, max_edge=None)
    assert img.shape == (240, 320, 3)
    fg = np.argwhere((img != 255).any(-1))
    uv, _, vis = project(torch.as_tensor(box.vertices, dtype=torch.float32)[None], cam)
    assert vis.all()
    uv = uv[0].numpy()
    assert np.abs(fg.min(0) - np.floor(uv.min(0))[::-1]).max() <= 2
    assert np.abs(fg.max(0) - np.ceil(uv.max(0))[::-1]).max() <= 2
    kp = np.array([[0.2, 1.3, 0.3]])  # top front edge of the box
    img = render_camera_view([(box.vertices, box.faces, (0.2, 0.6, 0.3))], cam, keypoints=kp,
                             keypoint_color=(255, 0, 0))
    u, v = project(torch.as_tensor(kp, dtype=torch.float32)[None], cam)[0][0, 0].numpy().round().astype(int)
    assert (img[v, u] == [255, 0, 0]).all()


def test_near_plane_clipping():
    """A floor reaching behind the camera covers the whole lower half of the view (dropping the triangles that
    cross the near plane would leave it empty: the floor is two triangles)."""
    floor = trimesh.Trimesh(np.array([[-1, 0, -1], [1, 0, -1], [1, 0, 1], [-1, 0, 1]]) * 1000.0, [[0, 2, 1], [0, 3, 2]])
    cam = make_camera([0.0, 1.5, 0.0], [0.0, 1.5, -1.0], (120, 160), 60.0)
    img = render_camera_view([(floor.vertices, floor.faces, (0.5, 0.5, 0.5))], cam, max_edge=None)
    assert (img[70:] != 255).any(-1).all() and (img[:55] == 255).all()


def test_draw_keypoints():
    img = np.full((50, 50, 3), 255, np.uint8)
    draw_keypoints(img, np.array([[10.0, 20.0], [40.0, 5.0]]), np.array([True, False]), (0, 0, 255), radius=2)
    assert (img[20, 10] == [0, 0, 255]).all() and (img[5, 40] == 255).all()
