"""`MeshVolume`: the 'mesh' model kind, the exact reference beside the learned volumes.

    volsmpl.attach_volume(body, model="mesh")
    sdf = body.volume.query(out, points)        # exact signed distance to the posed mesh, (B, N)

The same calls as `Volume` (query, signed, query_parts, collision_loss, selfpen_loss, extract_mesh) with
exact values: the distance to the posed mesh's nearest triangle (volsmpl.geometry.point_mesh_distance), signed by its
winding number, recomputed from the posed vertices at every call (no cache, no network): the quality
ceiling and the cost ceiling. Values are differentiable with respect to the points and the vertices (so
poses and shapes). Per part: the distance to the part's own triangles, signed by the generalised winding
number of that open piece of surface (inside above 1/2), inside the part's padded box, and the exact
distance to the box outside it, as the learned volumes do.
"""
from __future__ import annotations

import torch

from volsmpl.geometry.boxes import inside_boxes
from volsmpl.geometry.groundtruth import closed_mesh_problems
from volsmpl.geometry.point_mesh_distance import mesh_signed_distance
from volsmpl.nn.analytic import box_sdf
from volsmpl.body.partition import Partition
from volsmpl.volume.self_penetration import SELFPEN_TAU, overlap_samples, reduce_selfpen, sdf_penalty
from volsmpl.volume.input_checks import check_points
from volsmpl.volume.api import BodyVolume, check_output



#: largest coordinate (metres) the exact kind answers: open3d's squared distances overflow float32 above ~1e19 m
MAX_COORDINATE = 1e18


class MeshVolume(BodyVolume):
    """The exact mesh reference (module docstring). backend: nearest-triangle search, see
    volsmpl.geometry.point_mesh_distance.nearest_faces ('auto': open3d's BVH when it imports, else torch brute force)."""

    kind = "mesh"
    is_sdf = True
    level = 0.0

    def __init__(self, partition: Partition, fingerprint: str, backend: str = "auto"):
        super().__init__()
        self.partition, self.fingerprint, self.backend = partition, fingerprint, backend
        self.closed = closed_mesh_problems(partition.faces.cpu().numpy()) is None
        self.meta = {}

    def occupied(self, values: torch.Tensor) -> torch.Tensor:
        return values < 0

    def to_signed(self, values: torch.Tensor) -> torch.Tensor:
        return values

    def penetration(self, values: torch.Tensor) -> torch.Tensor:
        return torch.relu(-values)

    def _check(self, out, points):
        check_output(out)
        points = check_points(points, out.vertices)
        far = points.detach().abs().amax() if points.numel() else 0.0
        if far > MAX_COORDINATE:
            raise ValueError(f"points lie up to {float(far):.3g} m from the origin; the exact mesh distance is computed "
                             f"only within {MAX_COORDINATE:.0e} m (its squared distances overflow beyond): drop or "
                             f"rescale those points (the learned kinds answer up to float32's range).")
        if out.vertices.device != self.device:
            raise ValueError(f"the body output is on {out.vertices.device} but the volume is on {self.device}; "
                             f"move it with body.volume.to('{out.vertices.device}').")
        return points

    def query(self, out, points: torch.Tensor, dense: bool | None = None) -> torch.Tensor:
        """Exact signed distance (metres, negative inside) of points (B, N, 3) or (N, 3) -> (B, N)."""
        points = self._check(out, points)
        faces = self.partition.faces
        return torch.stack([mesh_signed_distance(out.vertices[b], faces, points[b], self.closed, self.backend)
                            for b in range(points.shape[0])])

    def _frames(self, out):
        G = self.partition.part_transforms(out.full_pose, out.joints)
        return (G, *self.partition.boxes(out.vertices, G))

    def _part_values(self, out, points: torch.Tensor, frames) -> torch.Tensor:
        """(B, K, N) exact per-part signed distances inside the padded boxes, box distances outside."""
        G, box_min, box_max = frames
        x = Partition.canonicalize(points, G)
        inside = inside_boxes(x, box_min, box_max)
        values = box_sdf(x, box_min[:, :, None], box_max[:, :, None])
        faces, labels = self.partition.faces, self.partition.face_labels
        for b in range(points.shape[0]):
            for k in range(self.num_parts):
                n = inside[b, k].nonzero()[:, 0]
                if len(n):
                    d = mesh_signed_distance(out.vertices[b], faces[labels == k], points[b, n], False, self.backend)
                    values = values.index_put((torch.full_like(n, b), torch.full_like(n, k), n), d)
        return values

    def query_parts(self, out, points: torch.Tensor, dense: bool | None = None) -> torch.Tensor:
        """Per-part exact signed distance (module docstring): points (B, N, 3) or (N, 3) -> (B, K, N)."""
        points = self._check(out, points)
        return self._part_values(out, points, self._frames(out))

    def selfpen_loss(self, out, n_points: int = 300, generator: torch.Generator | None = None,
                     return_points: bool = False, tau: float = SELFPEN_TAU, code_grad: bool = True):
        """Volume.selfpen_loss with exact per-part distances (code_grad has no meaning here: no codes)."""
        if not tau > 0:
            raise ValueError(f"tau must be > 0 (metres: the SDF scale of the soft occupancy), got {tau}")
        check_output(out)
        frames = self._frames(out)
        mask = self.partition.collision_mask
        _, samples, padded = overlap_samples(*frames, mask, n_points, generator)
        if padded is None:
            loss = (out.vertices.sum() * 0).expand(frames[0].shape[0]).clone()
            return (loss, samples) if return_points else loss
        part = self._part_values(out, padded, frames)
        return reduce_selfpen(part, part < 0, mask, samples, self.selfpen_penalty(tau), return_points)

    def selfpen_penalty(self, tau: float = SELFPEN_TAU):
        return sdf_penalty(tau)

    @torch.no_grad()
    def extract_mesh(self, out, resolution: int = 128, body_index: int = 0, padding: float = 0.05):
        """The posed mesh itself (the exact zero level set) of one body, as a trimesh.Trimesh."""
        import trimesh

        from volsmpl.volume.extraction import check_extract_args
        _, body_index, _ = check_extract_args(out, resolution, body_index, padding)  # same contract as Volume's
        return trimesh.Trimesh(out.vertices[body_index].detach().cpu().numpy(), self.partition.faces.cpu().numpy(),
                               process=False)
