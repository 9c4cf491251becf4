"""Pictures, rendered headless on the CPU: meshes and scenes (OpenCV rasterisation), image grids, SDF slices."""
from volsmpl.viz.render import grid, part_palette, render_camera_view, render_mesh, render_scene, save_png
from volsmpl.viz.slice_view import sdf_slice, surfaces_side_by_side

__all__ = ["grid", "part_palette", "render_camera_view", "render_mesh", "render_scene", "save_png", "sdf_slice",
           "surfaces_side_by_side"]
