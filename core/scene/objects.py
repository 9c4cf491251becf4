"""Procedural object templates with real-world sizes, for human-object interaction and furnished rooms.

This module holds the template class (`ObjectTemplate`), the size prior, the named regions and `make_object`;
the per-category shape builders are in `object_shapes.py`. Every template is built from trimesh primitives (boxes,
cylinders, solids of revolution, tori, cones); no asset is downloaded. The geometry is this project's own
procedural work, released with it under Apache-2.0.

Conventions (the project's): metres, Y up, right-handed. The canonical frame of a template:

- it rests on the floor: its lowest point is at y = 0; its bounding box is centred in x and z;
- its "front" faces +Z: the side a person sits down from (chair, stool, sofa, bed foot end), the open side of a
  shelf, the screen of a laptop, the nose of a skateboard, the side a cart is pushed towards (its handle is at -Z);
  a cup's handle points to +X; a phone lies screen up with its top edge towards -Z;
- long hand-held things stand upright: the bat on its barrel end (handle up), the bottle on its base, the open
  umbrella on its handle end.

Meshes: one `trimesh.Trimesh` per template, the concatenation of closed components (each watertight and wound
outward, positive volume; vertices are not merged between components, so the whole mesh is watertight too).
Components touch at their joints; a few interpenetrate by millimetres (cup handle in the wall, cart and umbrella
joints): for inside/outside use winding numbers (`volsmpl.geometry.groundtruth.mesh_sdf(sign='winding')`), which count the
union as inside, rather than ray parity.

Sizes: `SIZE_PRIOR` is a hand-made table of real-world sizes (bounding-box height/width/depth along y/x/z, in
metres, as (mean, std)), compiled from common product dimensions (mugs, 500 ml bottles, regulation balls and bats,
phones, standard chairs, beds and tables); it stands in for the language-model size prior of the paper's HOI
application. `make_object(category, seed)` draws each size from a normal truncated at +-2 std (seed=None: the
means) and builds the object to that exact bounding box.

Interaction hints: `ObjectTemplate.regions` names surface regions as sorted face-index arrays ('grasp', 'handle',
'seat', 'back', 'top', 'deck', ...; see `REGIONS`); `region_points` samples points and normals on them; `seats()`
and `supports()` give sitting places and horizontal support rectangles in the object frame.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import trimesh

from .object_shapes import BUILDERS, Parts

# (mean, std) in metres. height: y extent, width: x extent, depth: z extent of the bounding box (canonical frame);
# seat_height: top of the seat / mattress above the floor.
SIZE_PRIOR: dict[str, dict[str, tuple[float, float]]] = {
    "cup": {"height": (0.095, 0.008), "width": (0.120, 0.006), "depth": (0.082, 0.005)},  # mug, width with handle
    "bottle": {"height": (0.250, 0.040), "width": (0.070, 0.007), "depth": (0.070, 0.007)},
    "box": {"height": (0.300, 0.070), "width": (0.420, 0.080), "depth": (0.320, 0.060)},  # cardboard box
    "ball": {"height": (0.220, 0.012), "width": (0.220, 0.012), "depth": (0.220, 0.012)},  # football/basketball
    "bat": {"height": (0.840, 0.030), "width": (0.066, 0.003), "depth": (0.066, 0.003)},  # baseball bat
    "phone": {"height": (0.008, 0.0008), "width": (0.072, 0.004), "depth": (0.148, 0.008)},
    "skateboard": {"height": (0.110, 0.008), "width": (0.205, 0.008), "depth": (0.800, 0.025)},
    "laptop": {"height": (0.220, 0.012), "width": (0.330, 0.020), "depth": (0.300, 0.015)},  # open at ~110 deg
    "backpack": {"height": (0.460, 0.030), "width": (0.310, 0.020), "depth": (0.200, 0.025)},
    "suitcase": {"height": (0.680, 0.060), "width": (0.440, 0.030), "depth": (0.260, 0.025)},
    "umbrella": {"height": (0.850, 0.050), "width": (1.000, 0.080), "depth": (1.000, 0.080)},  # open
    "chair": {"height": (0.900, 0.050), "width": (0.460, 0.030), "depth": (0.520, 0.030),
              "seat_height": (0.450, 0.020)},
    "stool": {"height": (0.500, 0.080), "width": (0.360, 0.030), "depth": (0.360, 0.030)},
    "table": {"height": (0.750, 0.015), "width": (1.400, 0.220), "depth": (0.850, 0.080)},
    "sofa": {"height": (0.850, 0.050), "width": (2.000, 0.220), "depth": (0.920, 0.050), "seat_height": (0.440, 0.025)},
    "bed": {"height": (1.000, 0.100), "width": (1.500, 0.220), "depth": (2.080, 0.050), "seat_height": (0.550, 0.040)},
    "shelf": {"height": (1.800, 0.200), "width": (0.800, 0.100), "depth": (0.320, 0.040)},
    "cart": {"height": (0.950, 0.050), "width": (0.500, 0.040), "depth": (0.850, 0.070)},  # two-tier utility cart
}
CATEGORIES = tuple(SIZE_PRIOR)
#: sizes drawn once and copied (round things): {category: {key: copied_from}}
_TIED = {"ball": {"width": "height", "depth": "height"}, "bottle": {"depth": "width"}, "bat": {"depth": "width"},
         "stool": {"depth": "width"}, "umbrella": {"depth": "width"}}
#: objects a person picks up; the others are furniture standing on the floor
HANDHELD = ("cup", "bottle", "box", "ball", "bat", "phone", "skateboard", "laptop", "backpack", "umbrella")
SITTABLE = ("chair", "stool", "sofa", "bed")
#: rotational symmetry of a category's shapes (object_shapes): 'sphere' (every rotation maps it onto itself) or
#: 'axis_y' (any rotation about its canonical y axis does); categories left out have none
SYMMETRY = {"ball": "sphere", "bottle": "axis_y", "bat": "axis_y"}


def rotation_error_deg(R_est, R_true, symmetry: str | None = None) -> float | None:
    """Angle (degrees) of the smallest rotation between two object orientations, modulo the object's symmetry:
    the geodesic angle of R_est^T R_true without symmetry, the angle between the rotated y axes for 'axis_y',
    None for 'sphere' (no orientation to get wrong).

    Shape: R_est, R_true (3, 3) canonical -> world rotations.
    Example:
        >>> Rz = np.array([[0., -1, 0], [1, 0, 0], [0, 0, 1]])
        >>> rotation_error_deg(np.eye(3), Rz), rotation_error_deg(np.eye(3), Rz, "axis_y")
        (90.0, 90.0)
    """
    R_est, R_true = np.asarray(R_est, dtype=np.float64), np.asarray(R_true, dtype=np.float64)
    if symmetry == "sphere":
        return None
    if symmetry == "axis_y":
        c = float(np.clip(R_est[:, 1] @ R_true[:, 1], -1.0, 1.0))
    elif symmetry is None:
        c = float(np.clip((np.trace(R_est.T @ R_true) - 1) / 2, -1.0, 1.0))
    else:
        raise ValueError(f"symmetry must be None, 'sphere' or 'axis_y', got {symmetry!r}")
    return float(np.degrees(np.arccos(c)))


# --------------------------------------------------------------------------------------------- regions
_UP, _DOWN = (0, 1, 0), (0, -1, 0)
_X, _Z = (1, 0, 0), (0, 0, 1)
_SIDE = "side"  # any horizontal normal
_RADIAL = "radial"  # horizontal normal pointing away from the component's vertical axis
#: {category: {region: [(component names, normal filter or None, (y_lo, y_hi) as fractions of height or None)]}};
#: a component name matches 'leg' when it is 'leg' or 'leg' followed by digits ('leg0', 'leg1', ...).
REGIONS: dict[str, dict[str, list]] = {
    "cup": {"handle": [(("handle",), None, None)], "grasp": [(("handle",), None, None), (("body",), _RADIAL, None)],
            "bottom": [(("body",), _DOWN, (0, 0.01))]},
    "bottle": {"grasp": [(("body",), _RADIAL, (0.1, 0.62))], "neck": [(("body",), _RADIAL, (0.82, 0.94))],
               "bottom": [(("body",), _DOWN, (0, 0.01))]},
    "box": {"top": [(("body",), _UP, None)], "grasp": [(("body",), _X, None), (("body",), (-1, 0, 0), None)],
            "bottom": [(("body",), _DOWN, None)]},
    "ball": {"grasp": [(("body",), None, None)]},
    "bat": {"handle": [(("body",), _RADIAL, (0.70, 0.985))], "grasp": [(("body",), _RADIAL, (0.70, 0.985))],
            "barrel": [(("body",), _RADIAL, (0.0, 0.35))]},
    "phone": {"screen": [(("body",), _UP, None)], "back": [(("body",), _DOWN, None)],
              "grasp": [(("body",), _X, None), (("body",), (-1, 0, 0), None)]},
    "skateboard": {"deck": [(("deck",), _UP, None)], "grasp": [(("deck",), _X, None), (("deck",), (-1, 0, 0), None)],
                   "wheels": [(("wheel",), None, None)]},
    "laptop": {"keyboard": [(("base",), _UP, None)], "screen": [(("lid",), "lid_front", None)],
               "grasp": [(("base",), _X, None), (("base",), (-1, 0, 0), None), (("base",), _Z, None)]},
    "backpack": {"handle": [(("handle",), None, None)], "straps": [(("strap",), None, None)],
                 "grasp": [(("handle",), None, None)]},
    "suitcase": {"handle": [(("handle",), None, None)], "grasp": [(("handle",), None, None)],
                 "top": [(("body",), _UP, None)]},
    "umbrella": {"handle": [(("handle",), _SIDE, None)], "grasp": [(("handle",), _SIDE, None)],
                 "canopy": [(("canopy",), None, None)]},
    "chair": {"seat": [(("seat",), _UP, None)], "back": [(("back",), _Z, None)],
              "grasp": [(("back", "leg_back"), _UP, (0.9, 1.01))]},
    "stool": {"seat": [(("seat",), _UP, None)], "grasp": [(("seat",), _RADIAL, None)]},
    "table": {"top": [(("top",), _UP, None)], "grasp": [(("top",), _SIDE, None)]},
    "sofa": {"seat": [(("seat",), _UP, None)], "back": [(("back",), _Z, None)], "armrest": [(("arm",), _UP, None)]},
    "bed": {"seat": [(("mattress",), _UP, None)], "top": [(("mattress",), _UP, None)],
            "back": [(("headboard",), _Z, None)]},
    "shelf": {"top": [(("top",), _UP, None)], "boards": [(("board", "bottom"), _UP, None)]},
    "cart": {"handle": [(("handle",), None, None)], "grasp": [(("handle",), None, None)],
             "top": [(("platform_top",), _UP, None)]},
}
#: regions whose upward faces are horizontal support rectangles (see ObjectTemplate.supports)
SUPPORT_REGIONS = ("top", "boards", "seat", "deck", "keyboard")


def _select_faces(mesh: trimesh.Trimesh, comp: np.ndarray, names: list[str], specs, height: float) -> np.ndarray:
    normals, centres = mesh.face_normals, mesh.triangles_center
    keep = np.zeros(len(mesh.faces), bool)
    for prefixes, normal, yr in specs:
        ids = [i for i, n in enumerate(names)
               if any(n == q or n.startswith(q) and n[len(q):].isdigit() for q in prefixes)]
        m = np.isin(comp, ids)
        if normal == _SIDE:
            m &= np.abs(normals[:, 1]) < 0.3
        elif normal == _RADIAL:
            axis = np.zeros((len(m), 3))
            for i in ids:  # each component's own vertical axis through its bbox centre
                sel = comp == i
                axis[sel] = mesh.vertices[mesh.faces[sel]].reshape(-1, 3).mean(0)
            r = (centres - axis)[:, [0, 2]]
            m &= (np.abs(normals[:, 1]) < 0.95) & (np.einsum("ij,ij->i", r, normals[:, [0, 2]]) > 0)
        elif normal == "lid_front":
            m &= (normals[:, 2] > 0.3) & (normals[:, 1] > 0)
        elif normal is not None:
            m &= normals @ np.asarray(normal, dtype=np.float64) > 0.9
        if yr is not None:
            m &= (centres[:, 1] >= yr[0] * height) & (centres[:, 1] <= yr[1] * height)
        keep |= m
    return np.flatnonzero(keep)


# --------------------------------------------------------------------------------------------- template
@dataclass
class ObjectTemplate:
    """One generated object in its canonical frame (see the module docstring).

    Attributes:
        category: one of CATEGORIES.
        mesh: the closed, outward-wound triangle mesh (metres; vertices not merged between components).
        sizes: the drawn sizes {'height', 'width', 'depth', ...} in metres; the mesh's bounding box is
            exactly (width, height, depth) along (x, y, z) times `scale`.
        regions: {name: sorted face indices} of named interaction regions (REGIONS lists them per category).
        component: (F,) component id per face; component_names: the components' names.
        seed: the seed it was drawn with (None: mean sizes).
    """

    category: str
    mesh: trimesh.Trimesh
    sizes: dict[str, float]
    regions: dict[str, np.ndarray]
    component: np.ndarray
    component_names: tuple[str, ...]
    seed: int | None = None
    scale: np.ndarray = field(default_factory=lambda: np.ones(3))

    @property
    def extents(self) -> np.ndarray:
        """(3,) bounding-box size along x, y, z in metres."""
        return self.mesh.bounds[1] - self.mesh.bounds[0]

    def region_points(self, name: str, n: int = 256, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
        """Area-uniform points and outward normals on a named region.

        Shape: -> points (n, 3), normals (n, 3), canonical frame.

        Example:
            >>> pts, nrm = make_object("chair").region_points("seat", 100)
        """
        if name not in self.regions:
            raise ValueError(f"{self.category} has no region {name!r}; it has {sorted(self.regions)}.")
        from .points import sample_surface
        return sample_surface(self.mesh, n, seed=seed, faces=self.regions[name])

    def _region_box(self, name: str) -> tuple[np.ndarray, np.ndarray]:
        v = self.mesh.vertices[self.mesh.faces[self.regions[name]]].reshape(-1, 3)
        return v.min(0), v.max(0)

    def seats(self) -> list[dict]:
        """Places to sit in the canonical frame: dicts with 'position' (3,) on the seat surface (where the
        pelvis goes), 'height' (m above the floor) and 'facing' (3,) unit (the direction a sitter looks, +Z).
        Sofas give one place per 0.6 m of seat width; beds give places along the foot end. Empty if not sittable."""
        if "seat" not in self.regions:
            return []
        lo, hi = self._region_box("seat")
        width = hi[0] - lo[0]
        k = max(1, int(width // 0.6)) if self.category in ("sofa", "bed") else 1
        xs = lo[0] + width * (np.arange(k) + 0.5) / k
        z = hi[2] - 0.3 if self.category == "bed" else 0.5 * (lo[2] + hi[2])
        return [{"position": np.array([x, hi[1], z]), "height": float(hi[1]), "facing": np.array([0.0, 0.0, 1.0])}
                for x in xs]

    def supports(self) -> list[dict]:
        """Horizontal support rectangles (things can stand on them) in the canonical frame: dicts with 'name'
        (the region), 'center' (3,), 'half_size' (2,) along x and z, 'height'. One per upward component face
        of the regions in SUPPORT_REGIONS (e.g. each shelf board)."""
        out = []
        for name in SUPPORT_REGIONS:
            if name not in self.regions or name == "seat" and self.category == "bed":
                continue
            faces = self.regions[name]
            for c in np.unique(self.component[faces]):
                v = self.mesh.vertices[self.mesh.faces[faces[self.component[faces] == c]]].reshape(-1, 3)
                lo, hi = v.min(0), v.max(0)
                out.append({"name": name, "center": 0.5 * (lo + hi), "half_size": 0.5 * (hi - lo)[[0, 2]],
                            "height": float(hi[1])})
        return out


def _draw_sizes(category: str, rng: np.random.Generator | None) -> dict[str, float]:
    sizes = {}
    for key, (mean, std) in SIZE_PRIOR[category].items():
        z = 0.0 if rng is None else float(np.clip(rng.standard_normal(), -2.0, 2.0))
        sizes[key] = mean + std * z
    for key, src in _TIED.get(category, {}).items():
        sizes[key] = sizes[src]
    return sizes


def make_object(category: str, seed: int | None = None, scale=None) -> ObjectTemplate:
    """Build an object template of a category with realistic, seed-varied proportions.

    Args:
        category: one of CATEGORIES.
        seed: None gives the mean sizes of SIZE_PRIOR (and default discrete choices); an int draws each size from
            its prior truncated at +-2 std, and the discrete choices (number of shelf boards, stool legs...);
            the same seed gives byte-identical vertices.
        scale: None, a positive float, or positive (sx, sy, sz) applied after building (e.g. a low coffee table:
            make_object('table', scale=(0.8, 0.6, 0.7))).

    Returns:
        an ObjectTemplate; its mesh's bounding box is exactly (width, height, depth) * scale, resting on y = 0
        and centred in x and z.

    Shape: mesh (V, 3) vertices, (F, 3) faces.

    Example:
        >>> chair = make_object("chair", seed=3)
        >>> chair.mesh.is_watertight, chair.seats()[0]["height"]
    """
    if category not in BUILDERS:
        raise ValueError(f"unknown object category {category!r}; known: {', '.join(CATEGORIES)}.")
    if seed is not None and (not isinstance(seed, (int, np.integer)) or seed < 0):
        raise ValueError(f"seed must be None or a non-negative int, got {seed!r}.")
    sc = np.ones(3) if scale is None else np.broadcast_to(np.asarray(scale, dtype=np.float64), (3,)).copy()
    if not (np.isfinite(sc).all() and (sc > 0).all()):
        raise ValueError(f"scale must be a positive float or three positive floats, got {scale!r}.")
    rng = None if seed is None else np.random.default_rng([int(seed), CATEGORIES.index(category)])
    sizes = _draw_sizes(category, rng)
    parts = Parts()
    BUILDERS[category](parts, sizes, rng if rng is not None else np.random.default_rng(0))
    counts = [len(m.faces) for m in parts.meshes]
    offsets = np.cumsum([0] + [len(m.vertices) for m in parts.meshes])
    v = np.concatenate([m.vertices for m in parts.meshes])
    f = np.concatenate([m.faces + o for m, o in zip(parts.meshes, offsets[:-1])])
    comp = np.repeat(np.arange(len(counts)), counts)
    # snap the bounding box exactly to the drawn sizes (tessellation leaves it off by < 2%), then apply scale
    lo, hi = v.min(0), v.max(0)
    target = np.array([sizes["width"], sizes["height"], sizes["depth"]])
    v = (v - 0.5 * (lo + hi)) * (target / (hi - lo)) * sc
    v[:, 1] += 0.5 * target[1] * sc[1]
    mesh = trimesh.Trimesh(v, f, process=False)
    names = tuple(parts.names)
    regions = {name: _select_faces(mesh, comp, list(names), specs, target[1] * sc[1])
               for name, specs in REGIONS[category].items()}
    return ObjectTemplate(category, mesh, sizes, regions, comp, names, seed, sc)
