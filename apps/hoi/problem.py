"""The joint stage's problem for a batch of cases: every tensor the optimisation reads, padded to the batch.

B cases are optimised together (one Adam over their stacked variables; their losses are summed, so each case
moves as if alone, `volsmpl.optim.harness`). What differs in size between cases is padded with a copy of a valid
row and masked: object vertices (`obj_mask`; placed 1 km away, `FAR`), silhouette pixels and vertices, and the
contact pairs, which are flattened over the batch (pair p belongs to case `pair_case[p]`) with their part vertices
(`part_mask`) and region points padded; the regions' triangles are not padded (`tri_owner`: the pair of each). The
body is posed once for all B cases (its pose and shape are the first stage's and stay fixed); contact and
penetration are measured in each case's body frame.

What the terms see has a fixed budget, whatever the object's mesh: a pair's part vertices (an even stride, at most
`part_points`), its region's points (`region_points` area-weighted samples), its region's triangles (at most
`REGION_TRIANGLES`: a region with more is simplified to that many by quadric decimation, `region_triangles`), the
silhouette's pixels and the projected vertices (strides), and the object points of the penetration term (`pen_v`,
`pen_mask`): its mesh's vertices after `max_edge_frac` splitting, or PEN_POINTS area-weighted surface samples where
it has more (a scan of 50k faces costs what a template does). The metrics (fit.case_metrics) measure the exact
mesh's vertices (`obj_v`), not the budget.

    prob = Problem([case_a, case_b], body, volume, FitConfig()).prepare(volume)
    state = prob.variables([case_a.init, case_b.init])    # Variables (B, ...) for volsmpl.optim.optimize
"""
from __future__ import annotations

import math

import numpy as np
import torch

from volsmpl.geometry.rotations import matrix_to_rotation_6d, rotation_6d_to_matrix

from .case import (ANY_REGION, HoiCase, check_case, is_handheld, object_mesh, object_size_m, object_size_spread,
                   object_template)
from .losses import body_query, contact_terms, relative_similarity, to_camera

__all__ = ["REGION_TRIANGLES", "Problem", "object_scale_prior", "region_triangles"]

FAR = 1000.0  # metres: where padded object vertices sit (object frame), far outside the body
#: the most triangles a contact pair's region keeps for the contact term's exact distances: the templates' largest
#: region (the ball's 'grasp', 1,280), so every template keeps its own; a user's finer mesh is simplified to it
REGION_TRIANGLES = 1280
#: the most object points the penetration term reads: the templates' largest vertex count after subdivision
#: (max_edge_frac), so every template keeps its own vertices; a finer mesh is read at this many surface samples
PEN_POINTS = 6400


def object_scale_prior(case: HoiCase, mesh) -> float:
    """The object's scale that gives its real size by the largest bounding-box extent: the case's `size_m` when it
    has one, else its category's mean size (volsmpl.scene.objects.SIZE_PRIOR; case.object_size_m)."""
    return float(object_size_m(case.category, case.size_m) / np.asarray(mesh.extents).max())


def region_triangles(mesh, faces, budget: int = REGION_TRIANGLES) -> np.ndarray:
    """The triangles (F, 3, 3) the contact term measures a region by: the region's own (`faces`, ids of `mesh`) when
    there are at most `budget`, else the region simplified to at most `budget` triangles by quadric decimation
    (open3d; the region's vertices merged first, so its surface stays closed), which keeps it within about a
    millimetre of the original on the objects of a person's hand (a 0.22 m sphere of 20,480 triangles -> 1,280:
    1.5 mm at most, 0.5 mm on average), with the triangles' winding (outward normals). Degenerate triangles are
    dropped; decimation that cannot reach the budget (a triangle soup) keeps an even stride of what it left.

    Shape: -> (min(len(faces), budget), 3, 3) float64, in the mesh's frame.
    Example:
        >>> sphere = trimesh.creation.icosphere(5)                      # 20,480 triangles
        >>> region_triangles(sphere, np.arange(20480)).shape
        (1280, 3, 3)
    """
    import open3d as o3d
    import trimesh

    faces = np.asarray(faces, dtype=np.int64)
    v, f = np.asarray(mesh.vertices, dtype=np.float64), np.asarray(mesh.faces, dtype=np.int64)[faces]
    if len(f) <= budget:
        return v[f]
    sub = trimesh.Trimesh(v, f, process=False)
    sub.merge_vertices()
    sub.remove_unreferenced_vertices()
    o = o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(np.array(sub.vertices, dtype=np.float64)),
                                  o3d.utility.Vector3iVector(np.array(sub.faces, dtype=np.int32)))
    d = o.simplify_quadric_decimation(target_number_of_triangles=int(budget))
    tris = np.asarray(d.vertices, dtype=np.float64)[np.asarray(d.triangles, dtype=np.int64)]
    area = np.linalg.norm(np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0]), axis=1)
    tris = tris[area > 1e-12 * max(float(area.max(initial=0.0)), 1e-30)]
    if len(tris) == 0:  # nothing usable came back: an even stride of the region's own triangles
        tris = v[f]
    return tris[:: -(-len(tris) // budget)] if len(tris) > budget else tris


def _pad(rows: list, dev, dtype=torch.float32, fill=None):
    """Arrays (n_i, ...) -> (len, max n_i, ...) padded with each array's first row (or `fill`), and its mask
    (len, max n_i)."""
    n = max(len(r) for r in rows)
    out, mask = [], torch.zeros(len(rows), n, dtype=torch.bool, device=dev)
    for i, r in enumerate(rows):
        r = torch.as_tensor(r if torch.is_tensor(r) else np.asarray(r), dtype=dtype, device=dev)
        pad = r[:1] if fill is None else torch.as_tensor(fill, dtype=dtype, device=dev).expand(1, *r.shape[1:])
        out.append(torch.cat([r, pad.expand(n - len(r), *r.shape[1:])]) if len(r) < n else r)
        mask[i, : len(r)] = True
    return torch.stack(out), mask


def _similar(tris: torch.Tensor, owner: torch.Tensor, s: torch.Tensor, R: torch.Tensor, t: torch.Tensor):
    """Triangles (T, 3, 3) moved by their owners' similarities x -> s R x + t (s (P,), R (P, 3, 3), t (P, 3))."""
    return s[owner, None, None] * tris @ R[owner].transpose(1, 2) + t[owner, None]


class Problem:
    """Everything the optimisation of B cases reads (module docstring). `cases`: one HoiCase or a list of them,
    all for `body`; `volume`: the model kind (its partition names the parts; `prepare` makes its query)."""

    def __init__(self, cases, body, volume, cfg):
        import trimesh

        from volsmpl.body.fingerprint import fingerprint_of_model
        from volsmpl.scene.points import sample_surface

        cases = [cases] if isinstance(cases, HoiCase) else list(cases)
        if not cases:
            raise ValueError("a Problem needs at least one case")
        dev, dt = torch.device(cfg.device), torch.float32
        part_names = list(volume.partition.table.part_names)
        labels = volume.partition.vertex_labels.cpu().numpy()
        fingerprint = fingerprint_of_model(body)
        self.cases, self.meshes = cases, []
        self.faces = torch.as_tensor(np.asarray(body.faces), device=dev)
        with torch.no_grad():
            self.out = body(**{k: torch.stack([torch.as_tensor(c.body[k]) for c in cases]).to(dev)
                               for k in cases[0].body})
        self.body_v = self.out.vertices.detach()
        self.body_n = torch.stack([torch.as_tensor(np.array(trimesh.Trimesh(v, np.asarray(body.faces), process=False)
                                                            .vertex_normals), dtype=dt, device=dev)
                                   for v in self.body_v.cpu().numpy()])
        self.joints = self.out.joints[:, :24].detach()
        # the contact pairs of all cases, flattened: (part vertices, their normals, region points, region normals,
        # the region's triangles), the part's in the body frame, the region's in the object frame
        self.pairs, pair_case = [], []
        samples, priors = [], []
        for i, case in enumerate(cases):
            mesh, regions = object_mesh(case, object_template(case))
            check_case(case, fingerprint, part_names, regions)
            base, budgeted = mesh, {}  # the regions' budgeted triangles, made once per region of the case
            if cfg.max_edge_frac > 0:  # an even spread of vertices over the surface (the paper's objects: 1k-20k)
                v, f = trimesh.remesh.subdivide_to_size(mesh.vertices, mesh.faces, cfg.max_edge_frac * mesh.extents.max())
                mesh = trimesh.Trimesh(v, f, process=False)
            self.meshes.append(mesh)
            # dense, even surface samples for the contact metric (vertices of boxy objects are too sparse for it)
            samples.append(sample_surface(mesh, 4000, seed=0)[0])
            priors.append(object_scale_prior(case, mesh))
            for part, region in case.contacts:
                ids = np.nonzero(labels == part_names.index(part))[0]
                ids = ids[:: max(1, -(-len(ids) // cfg.part_points))]
                faces = np.arange(len(base.faces)) if region == ANY_REGION else regions[region]
                pts, nrm = sample_surface(base, cfg.region_points, seed=0, faces=faces)
                if region not in budgeted:
                    budgeted[region] = region_triangles(base, faces)  # (F, 3, 3), F <= REGION_TRIANGLES
                tris = budgeted[region]
                self.pairs.append((self.body_v[i, ids], self.body_n[i, ids], pts, nrm, tris))
                pair_case.append(i)
        # padding 1 km away from the object: outside every part box, so the learned kinds decode nothing there
        self.obj_v, self.obj_mask = _pad([m.vertices for m in self.meshes], dev, fill=FAR)
        self.pen_v, self.pen_mask = _pad([m.vertices if len(m.vertices) <= PEN_POINTS else
                                          sample_surface(m, PEN_POINTS, seed=0)[0] for m in self.meshes], dev, fill=FAR)
        self.obj_samples = torch.as_tensor(np.stack(samples), dtype=dt, device=dev)
        self.prior_object = torch.tensor(priors, dtype=dt, device=dev)
        handheld = [is_handheld(c) for c in cases]
        self.handheld = torch.tensor(handheld, device=dev)  # (B,) bool: FitConfig.w_pen_handheld
        # the scale prior's free band (FitConfig.scale_free_std): that many of the category's relative spread of real
        # sizes, in scale; none for a handheld object
        self.prior_object_free = self.prior_object * torch.tensor(
            [0.0 if h else cfg.scale_free_std * object_size_spread(c.category, c.size_m) for c, h in zip(cases, handheld)],
            dtype=dt, device=dev)
        self.pair_case = torch.tensor(pair_case, dtype=torch.long, device=dev)
        if self.pairs:
            cols = list(zip(*self.pairs))
            (self.part_v, self.part_mask), (self.part_n, _) = _pad(cols[0], dev), _pad(cols[1], dev)
            (self.reg_p, self.reg_mask), (self.reg_n, _) = _pad(cols[2], dev), _pad(cols[3], dev)
            # the regions' triangles unpadded (their counts differ most: 2 on a seat, 1,280 on a whole ball)
            self.reg_tri = torch.as_tensor(np.concatenate(cols[4]), dtype=dt, device=dev)  # (T, 3, 3)
            self.tri_owner = torch.repeat_interleave(torch.arange(len(self.pairs), device=dev),
                                                     torch.tensor([len(t) for t in cols[4]], device=dev))
            # each pair's contact patch: this share of its part's vertices (at least one)
            self.patch_k = torch.tensor([max(1, math.ceil(cfg.contact_fraction * len(p[0]))) for p in self.pairs],
                                        device=dev)
        self.contact_fraction, self.contact_huber = cfg.contact_fraction, cfg.contact_huber
        self.contact_margin = cfg.contact_margin
        self.rotation_start = round(cfg.rotation_after * cfg.iters)  # the first step that turns the object
        self.K = torch.as_tensor(np.stack([c.K for c in cases]), dtype=dt, device=dev)
        self.kp = torch.as_tensor(np.stack([c.keypoints_2d for c in cases]), dtype=dt, device=dev)
        self.sil, self.sil_mask = _pad([c.silhouette[:: max(1, -(-len(c.silhouette) // cfg.silhouette_points))]
                                        for c in cases], dev)
        self.sil_v, self.sil_v_mask = _pad([np.asarray(m.vertices)[:: max(1, -(-len(m.vertices) // cfg.silhouette_vertices))]
                                            for m in self.meshes], dev)
        self.query = None  # the penetration query of the bodies (losses.body_query), made by `prepare`
        # the centres the rotations turn about (see `similarity`): (B, 3) each
        m = self.obj_mask.to(dt)[..., None]
        self.centre = {"human": self.body_v.mean(dim=1), "object": (self.obj_v * m).sum(1) / m.sum(1)}

    @property
    def batch(self) -> int:
        """B, the number of cases."""
        return len(self.cases)

    def prepare(self, volume):
        """The penetration query of the cases' (fixed) bodies for a model kind: made once per fit."""
        self.query = body_query(volume, self.out)
        return self

    def variables(self, sims) -> dict:
        """Optimisation variables (B, ...) from one similarity pair {'human': Similarity, 'object': Similarity}
        per case (a list; a single dict for B = 1): the human's log-scale, the object's log-scale relative to the
        human's, a 6D rotation and a translation each, the rotation about the centre of each one's vertices and
        the translation divided by its own scale (see `similarity`)."""
        from volsmpl.optim import Variable

        sims = [sims] if isinstance(sims, dict) else list(sims)
        if len(sims) != self.batch:
            raise ValueError(f"{len(sims)} similarity pairs for {self.batch} cases")
        dev = self.K.device
        out = {}
        for who in ("human", "object"):
            R = torch.as_tensor(np.stack([s[who].rotation for s in sims]), dtype=torch.float32, device=dev)
            t = torch.as_tensor(np.stack([s[who].translation / s[who].scale for s in sims]), dtype=torch.float32,
                                device=dev)
            out[f"{who}_rot6d"] = Variable(matrix_to_rotation_6d(R), start=self.rotation_start if who == "object" else 0)
            out[f"{who}_transl"] = Variable(t + (R @ self.centre[who][..., None])[..., 0])
        hs = np.array([s["human"].scale for s in sims])
        os_ = np.array([s["object"].scale for s in sims])
        out["human_log_scale"] = Variable(torch.tensor(np.log(hs)[:, None], dtype=torch.float32, device=dev))
        out["object_rel_log_scale"] = Variable(torch.tensor(np.log(os_ / hs)[:, None], dtype=torch.float32, device=dev))
        return out

    def similarity(self, state, who: str):
        """(scale (B,), R (B, 3, 3), t (B, 3)) of 'human' or 'object' in the camera frame from the optimisation
        state, x_cam = s (R (x - c) + t') with c the centre of its vertices: a rotation turns it about its centre,
        so the contact's first pulls move the object rather than swing it about the template's floor point. The
        state holds the object's log-scale relative to the human's: a change of the human's log-scale alone scales
        the pair about the camera centre, which leaves both projections, the contact and the penetration as they
        are (the depth-scale ambiguity of one view), so only the scale priors move it; the relative log-scale
        moves the object along its camera ray against the human."""
        log_s = state["human_log_scale"][:, 0]
        if who == "object":
            log_s = log_s + state["object_rel_log_scale"][:, 0]
        scale = log_s.exp()
        R = rotation_6d_to_matrix(state[f"{who}_rot6d"])
        return scale, R, (state[f"{who}_transl"] - (R @ self.centre[who][..., None])[..., 0]) * scale[:, None]

    def usable(self, variables: dict) -> torch.Tensor:
        """(B,) bool: the cases whose similarities and object vertices in the body frame are finite: what the
        harness lets on (volsmpl.optim.optimize's `usable`; a log-scale past ~88 overflows float32)."""
        human, obj = self.similarity(variables, "human"), self.similarity(variables, "object")
        ok = torch.ones(self.batch, dtype=torch.bool, device=self.K.device)
        for x in (*human, *obj, to_camera(self.obj_v, *relative_similarity(human, obj))):
            ok &= torch.isfinite(x.reshape(self.batch, -1)).all(dim=1)
        return ok

    def placed(self, state) -> dict:
        """The geometry at the state's similarities: the object's vertices in the body frame ('obj_body') and the
        contact terms there (B,), the object's silhouette vertices and the body joints in the camera frame."""
        human, obj = self.similarity(state, "human"), self.similarity(state, "object")
        rel = relative_similarity(human, obj)
        sh = human[0]
        contact = normal = sh.new_zeros(sh.shape)
        if self.pairs:
            s, R, t = (x[self.pair_case] for x in rel)  # each pair's case
            c, nc, _, _ = contact_terms(self.part_v, self.part_n, to_camera(self.reg_p, s, R, t),
                                        self.reg_n @ R.transpose(1, 2), self.reg_mask, self.contact_fraction,
                                        _similar(self.reg_tri, self.tri_owner, s, R, t), None,
                                        huber=self.contact_huber, part_mask=self.part_mask, patch_k=self.patch_k,
                                        tri_owner=self.tri_owner, margin=self.contact_margin)
            contact = contact.index_add(0, self.pair_case, c)
            normal = normal.index_add(0, self.pair_case, nc)
        return {"human": human, "object": obj, "obj_body": to_camera(self.obj_v, *rel),
                "pen_body": to_camera(self.pen_v, *rel),
                "sil_cam": to_camera(self.sil_v, *obj), "joints_cam": to_camera(self.joints, *human),
                "contact": contact, "normal": normal}
