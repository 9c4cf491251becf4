"""Geometry in torch: rigid part boxes, rotation parametrisations, exact point-to-mesh queries (closest
triangles, winding numbers, ray hits), differentiable mesh distances, and the exact ground truth (mesh SDFs)."""
from volsmpl.geometry.boxes import boxes_overlap, inside_boxes
from volsmpl.geometry.groundtruth import SIGN_MODES, batch_mesh_sdf, batch_sdf, closed_mesh_problems, mesh_sdf, winding_number
from volsmpl.geometry.point_mesh_distance import mesh_signed_distance, nearest_faces, winding_numbers
from volsmpl.geometry.rotations import (axis_angle_to_matrix, axis_angle_to_rotation_6d, matrix_to_axis_angle,
                                        matrix_to_rotation_6d, rotation_6d_to_axis_angle, rotation_6d_to_matrix)
from volsmpl.geometry.triangle_queries import MeshQuery, closest_points_on_triangles, first_hits

__all__ = ["SIGN_MODES", "MeshQuery", "axis_angle_to_matrix", "axis_angle_to_rotation_6d", "batch_mesh_sdf", "batch_sdf",
           "boxes_overlap", "closed_mesh_problems", "closest_points_on_triangles", "first_hits", "inside_boxes",
           "matrix_to_axis_angle", "matrix_to_rotation_6d", "mesh_sdf", "mesh_signed_distance", "nearest_faces",
           "rotation_6d_to_axis_angle", "rotation_6d_to_matrix", "winding_number", "winding_numbers"]
