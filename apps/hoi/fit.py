"""Joint human–object optimisation of one case on the shared harness (paper Sec. 4.2.1, supplementary D.1).

The body's pose and shape are fixed (first stage); optimised are the human's and the object's similarities into
the camera frame (Problem.variables: the human's log-scale, the object's log-scale relative to it, a rotation
(6D) and a translation held divided by its own scale each), from the case's first-stage estimates, with Adam
(lr 2e-3, 1,000 steps) on

    L = 1e5 L_contact + 1e3 L_normal + 1e4 L_pen (1e3 with the exact mesh, as the paper) + 1e3 L_scale
        + w_keypoints L_keypoints + w_silhouette L_silhouette

(apps/hoi/losses.py). The body is posed once; contact and penetration are measured in its frame (the object placed
by the relative similarity), so its part vertices are constants and the penetration term queries the model kind
(`volume`) at the object vertices only: 'volsmpl' and 'coap' encode the body once (losses.body_query) and 'mesh'
measures exact distances to the posed mesh at every step. Metrics (`case_metrics`) use exact mesh tests.

    res = fit_case(case, body, volume, FitConfig())
"""
from __future__ import annotations

from dataclasses import asdict, dataclass, field

import numpy as np
import torch

from volsmpl.mesh_distance import mesh_signed_distance
from volsmpl.optim import Term, Variable, optimize
from volsmpl.rotations import matrix_to_rotation_6d, rotation_6d_to_matrix
from volsmpl.scene import SYMMETRY, rotation_error_deg

from .case import ANY_REGION, HoiCase, Similarity, check_case, object_mesh, object_template
from .losses import (body_query, contact_terms, keypoint_term, penetration, relative_similarity, scale_prior,
                     silhouette_term, to_body_frame, to_camera)

CONTACT_RADIUS = 0.02  # metres: ground-truth contact regions are the points within this distance of the other surface


@dataclass
class FitConfig:
    """Weights and optimiser settings (supp. D.1: lambda = 1e5, 1e3, 1e4, 1e3; lambda_3 = 1e3 for the mesh SDF;
    Adam lr 2e-3, 1,000 steps). The image-term weights are ours (the paper keeps the first stage's image
    alignment without stating its weight): tuned on the tuning split (apps/hoi/tune.py)."""

    iters: int = 1000
    lr: float = 2e-3
    w_contact: float = 1e5
    w_normal: float = 1e3
    w_pen: float = 1e4
    w_pen_mesh: float = 1e3
    w_scale: float = 1e3
    # tuned: docs/hoi_tune.json (the first 13 tuning cases, one of each kind, volsmpl; 1e5 / 1e6 / 1e7; the lowest
    # mean contact_cm + obj_trans_err_cm + collision_pct)
    w_keypoints: float = 1e6
    w_silhouette: float = 1e6
    # the share of a contact part's vertices (those facing the region) that the contact term pulls onto it: the part's
    # contact patch (losses.contact_terms); 1: the whole part (the plain one-way Chamfer). Set on the tuning half:
    # 3-9 % of a hand's, pelvis' or thigh's vertices are within 2 cm of the object at the truth, and 0.03 is the
    # largest share whose patch lies within 1 cm of the region at the truth (median over the pairs: 0.8 cm; 1.0: 5 cm)
    contact_fraction: float = 0.03
    # metres: the contact's squared distances become linear beyond this (pseudo-Huber, losses.contact_terms); 0: the
    # plain squared distance (its first steps, tens of cm off, stall Adam for the rest of the run)
    contact_huber: float = 0.02
    region_points: int = 256  # points sampled on each object contact region
    part_points: int = 1024  # body part vertices per contact pair (an even stride through the part's vertices)
    silhouette_points: int = 500  # silhouette pixels used (an even stride through the case's sample)
    silhouette_vertices: int = 1000  # object vertices projected for the silhouette term (an even stride)
    # the object's triangles are split until no edge is longer than this fraction of its largest extent, so its
    # vertices (penetration term, metrics) cover the surface evenly; 0 keeps the mesh as it is
    max_edge_frac: float = 0.08  # 600-6,000 vertices for the templates
    device: str = "cpu"

    def __post_init__(self):
        if not isinstance(self.iters, int) or self.iters < 0:
            raise ValueError(f"iters must be an integer >= 0, got {self.iters!r}")
        if not self.lr > 0:
            raise ValueError(f"lr must be > 0, got {self.lr}")
        if not 0.0 < self.contact_fraction <= 1.0:
            raise ValueError(f"contact_fraction must be in (0, 1], got {self.contact_fraction}")
        if not (np.isfinite(self.contact_huber) and self.contact_huber >= 0):
            raise ValueError(f"contact_huber must be a finite length >= 0 (metres), got {self.contact_huber}")
        for k, v in asdict(self).items():
            if k.startswith("w_") and not (np.isfinite(v) and v >= 0):
                raise ValueError(f"{k} must be a finite weight >= 0, got {v}")


@dataclass
class FitResult:
    name: str
    model: str
    status: str
    iterations: int
    ms_per_iter: float
    total_s: float
    peak_mem_mb: float
    human: dict  # fitted similarity (Similarity.to_dict)
    object: dict
    before: dict = field(default_factory=dict)  # case_metrics of the first-stage estimates
    after: dict = field(default_factory=dict)  # case_metrics of the fit
    loss: list = field(default_factory=list)  # total loss every 50 steps


class Problem:
    """Everything a case's optimisation reads, as tensors (batch of one case)."""

    def __init__(self, case: HoiCase, body, volume, cfg: FitConfig):
        from volsmpl.body.fingerprint import fingerprint_of_model
        from volsmpl.scene.points import sample_surface

        dev, dt = torch.device(cfg.device), torch.float32
        tmpl = object_template(case)
        mesh, regions = object_mesh(case, tmpl)
        base = mesh
        if cfg.max_edge_frac > 0:  # an even spread of vertices over the surface (the paper's objects: 1k-20k vertices)
            import trimesh
            v, f = trimesh.remesh.subdivide_to_size(mesh.vertices, mesh.faces, cfg.max_edge_frac * mesh.extents.max())
            mesh = trimesh.Trimesh(v, f, process=False)
        part_names = list(volume.partition.table.part_names)
        check_case(case, fingerprint_of_model(body), part_names, regions)
        self.case, self.mesh, self.faces = case, mesh, torch.as_tensor(np.asarray(body.faces), device=dev)
        with torch.no_grad():
            self.out = body(**{k: v[None].to(dev) for k, v in case.body.items()})
        vb = self.out.vertices[0].detach().cpu().numpy()
        import trimesh
        normals = trimesh.Trimesh(vb, np.asarray(body.faces), process=False).vertex_normals
        self.body_v = self.out.vertices.detach()
        self.body_n = torch.as_tensor(np.array(normals), dtype=dt, device=dev)[None]
        self.joints = self.out.joints[:, :24].detach()
        self.obj_v = torch.as_tensor(np.asarray(mesh.vertices), dtype=dt, device=dev)[None]
        self.obj_mask = torch.ones(self.obj_v.shape[:2], dtype=torch.bool, device=dev)
        # dense, even surface samples for the contact metric (vertices of boxy objects are too sparse for it)
        self.obj_samples = torch.as_tensor(np.asarray(sample_surface(mesh, 4000, seed=0)[0]), dtype=dt, device=dev)[None]
        labels = volume.partition.vertex_labels.cpu().numpy()
        # (part vertices (1, P, 3), their normals, region points (1, Q, 3), region normals, the region's triangles
        # (1, F, 3, 3)): the part's in the body frame (constants: the pose is fixed), the region's in the object frame
        # (on the mesh as given: its regions index its faces)
        self.pairs = []
        for part, region in case.contacts:
            ids = np.nonzero(labels == part_names.index(part))[0]
            ids = torch.as_tensor(ids[:: max(1, -(-len(ids) // cfg.part_points))], device=dev)
            faces = np.arange(len(base.faces)) if region == ANY_REGION else regions[region]
            pts, nrm = sample_surface(base, cfg.region_points, seed=0, faces=faces)
            tris = np.asarray(base.vertices)[np.asarray(base.faces)[faces]]  # (F, 3, 3): the region's triangles
            self.pairs.append((self.body_v[:, ids], self.body_n[:, ids],
                               *(torch.as_tensor(np.asarray(x), dtype=dt, device=dev)[None] for x in (pts, nrm, tris))))
        self.contact_fraction, self.contact_huber = cfg.contact_fraction, cfg.contact_huber
        self.K = torch.as_tensor(case.K, dtype=dt, device=dev)[None]
        self.kp = torch.as_tensor(case.keypoints_2d, dtype=dt, device=dev)[None]
        sil = case.silhouette[:: max(1, -(-len(case.silhouette) // cfg.silhouette_points))]
        self.sil = torch.as_tensor(sil, dtype=dt, device=dev)[None]
        self.sil_mask = torch.ones(self.sil.shape[:2], dtype=torch.bool, device=dev)
        self.sil_v = self.obj_v[:, :: max(1, -(-self.obj_v.shape[1] // cfg.silhouette_vertices))]
        self.sil_v_mask = torch.ones(self.sil_v.shape[:2], dtype=torch.bool, device=dev)
        self.prior_object = object_scale_prior(case, mesh)
        self.query = None  # the penetration query of the body (losses.body_query), made by `prepare`
        # the centres the rotations turn about (see `similarity`)
        self.centre = {"human": self.body_v[0].mean(dim=0), "object": self.obj_v[0].mean(dim=0)}

    def prepare(self, volume):
        """The penetration query of this case's (fixed) body for a model kind: made once per fit."""
        self.query = body_query(volume, self.out)
        return self

    def variables(self, sim: dict) -> dict:
        """Optimisation variables from similarities {'human': Similarity, 'object': Similarity}: the human's
        log-scale, the object's log-scale relative to the human's, a 6D rotation and a translation each, the
        rotation about the centre of each one's vertices and the translation divided by its own scale (see
        `similarity`)."""
        dev = self.K.device
        out = {}
        for who, s in sim.items():
            R = torch.as_tensor(s.rotation, dtype=torch.float32, device=dev)
            c = self.centre[who]
            out[f"{who}_rot6d"] = Variable(matrix_to_rotation_6d(R)[None])
            out[f"{who}_transl"] = Variable((torch.as_tensor(s.translation / s.scale, dtype=torch.float32, device=dev)
                                             + R @ c)[None])
        out["human_log_scale"] = Variable(torch.tensor([[np.log(sim["human"].scale)]], dtype=torch.float32, device=dev))
        out["object_rel_log_scale"] = Variable(torch.tensor([[np.log(sim["object"].scale / sim["human"].scale)]],
                                                            dtype=torch.float32, device=dev))
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
        return scale, R, (state[f"{who}_transl"] - R @ self.centre[who]) * scale[:, None]

    def placed(self, state) -> dict:
        """The geometry at the state's similarities: the object's vertices in the body frame ('obj_body') and the
        contact terms there, the object's silhouette vertices and the body joints in the camera frame."""
        human, obj = self.similarity(state, "human"), self.similarity(state, "object")
        rel = relative_similarity(human, obj)
        sh = human[0]
        contact = normal = sh.new_zeros(sh.shape)
        for p, n, q, nq, tri in self.pairs:
            c, nc, _, _ = contact_terms(p, n, to_camera(q, *rel), nq @ rel[1].transpose(1, 2),
                                        torch.ones(q.shape[:2], dtype=torch.bool, device=q.device),
                                        self.contact_fraction, to_camera(tri.flatten(1, 2), *rel).view(tri.shape),
                                        huber=self.contact_huber)
            contact, normal = contact + c, normal + nc
        return {"human": human, "object": obj, "obj_body": to_camera(self.obj_v, *rel),
                "sil_cam": to_camera(self.sil_v, *obj), "joints_cam": to_camera(self.joints, *human),
                "contact": contact, "normal": normal}


def object_scale_prior(case: HoiCase, mesh) -> float:
    """The object's scale that gives its category's mean real size (volsmpl.scene.objects.SIZE_PRIOR, by the
    largest bounding-box extent)."""
    from volsmpl.scene.objects import SIZE_PRIOR

    prior = SIZE_PRIOR[case.category]
    mean = max(prior[k][0] for k in ("height", "width", "depth") if k in prior)
    return float(mean / np.asarray(mesh.extents).max())


def _terms(problem: Problem, volume, cfg: FitConfig) -> dict:
    w_pen = cfg.w_pen_mesh if volume.kind == "mesh" else cfg.w_pen

    terms = {
        "contact": Term(lambda s: s.placed["contact"], cfg.w_contact),
        "normal": Term(lambda s: s.placed["normal"], cfg.w_normal),
        "penetration": Term(lambda s: penetration(problem.query, s.placed["obj_body"], problem.obj_mask), w_pen),
        "scale": Term(lambda s: scale_prior(s.placed["object"][0], problem.prior_object)
                      + scale_prior(s.placed["human"][0], 1.0), cfg.w_scale),
        "keypoints": Term(lambda s: keypoint_term(s.placed["joints_cam"], problem.kp, problem.K), cfg.w_keypoints),
        "silhouette": Term(lambda s: silhouette_term(s.placed["sil_cam"], problem.sil_v_mask, problem.sil,
                                                     problem.sil_mask, problem.K), cfg.w_silhouette),
    }
    return {k: t for k, t in terms.items() if t.weight > 0}  # a term weighted 0 is not evaluated


def fit_case(case: HoiCase, body, volume, cfg: FitConfig = FitConfig(), problem: Problem | None = None) -> FitResult:
    """Optimise one case's human and object similarities against `volume` (any model kind); metrics before/after."""
    problem = (problem or Problem(case, body, volume, cfg)).prepare(volume)
    run = optimize(problem.variables(case.init), _terms(problem, volume, cfg),
                   prepare=lambda s: {"placed": problem.placed(s)}, optimizer="adam", lr=cfg.lr,
                   max_iters=cfg.iters, frozen=[volume], device=cfg.device, progress=None, desc=case.name)
    fitted = {}
    for who in ("human", "object"):
        sc, R, t = problem.similarity(run.variables, who)
        fitted[who] = Similarity(float(sc[0]), R[0].double().cpu().numpy(), t[0].double().cpu().numpy())
    steps = run.step_ms()
    return FitResult(
        name=case.name, model=volume.kind, status=run.status[0], iterations=run.iterations[0],
        ms_per_iter=float(np.mean(steps)) if steps else float("nan"), total_s=run.seconds,
        peak_mem_mb=run.peak_bytes / 2 ** 20, human=fitted["human"].to_dict(), object=fitted["object"].to_dict(),
        before=case_metrics(problem, case.init), after=case_metrics(problem, fitted),
        loss=[r.total[0] for r in run.records[::50]])


@torch.no_grad()
def case_metrics(problem: Problem, sim: dict) -> dict:
    """Exact metrics of a placement {'human': Similarity, 'object': Similarity}: object vertices inside the body
    (%, exact mesh test), and with ground truth: contact (cm: symmetric Chamfer, mean nearest distance, between the
    ground-truth contact regions as placed: the body's vertices and the object's surface samples within 2 cm of the
    other surface in the ground truth), object translation (cm, centroid) and rotation (deg) errors, object
    and human scale errors (%)."""
    dev = problem.K.device
    h, o = sim["human"], sim["object"]
    args = lambda s: (torch.tensor([s.scale], device=dev), torch.as_tensor(s.rotation, dtype=torch.float32, device=dev)[None],  # noqa: E731
                      torch.as_tensor(s.translation, dtype=torch.float32, device=dev)[None])
    obj_cam = to_camera(problem.obj_v, *args(o))
    x = to_body_frame(obj_cam, *args(h))
    d = mesh_signed_distance(problem.body_v[0], problem.faces, x[0], closed=True)
    m = {"collision_pct": float((d < 0).float().mean() * 100)}
    truth = problem.case.truth
    if truth is None:
        return m
    body_t = to_camera(problem.body_v, *args(truth["human"]))[0]
    obj_t = to_camera(problem.obj_samples, *args(truth["object"]))[0]
    near_b = torch.cdist(body_t, obj_t).min(dim=1).values < CONTACT_RADIUS
    near_o = torch.cdist(obj_t, body_t).min(dim=1).values < CONTACT_RADIUS
    if near_b.any() and near_o.any():
        b = to_camera(problem.body_v, *args(h))[0][near_b]
        ob = to_camera(problem.obj_samples, *args(o))[0][near_o]
        dd = torch.cdist(b, ob)
        m["contact_cm"] = float((dd.min(dim=1).values.mean() + dd.min(dim=0).values.mean()) / 2 * 100)
    c = problem.obj_v[0].mean(dim=0, keepdim=True)
    ct = to_camera(c[None], *args(truth["object"]))[0, 0]
    cf = to_camera(c[None], *args(o))[0, 0]
    m["obj_trans_err_cm"] = float((cf - ct).norm() * 100)
    # modulo the category's symmetry (a bottle turned about its axis is not wrong; a ball has no rotation error)
    m["obj_rot_err_deg"] = rotation_error_deg(o.rotation, truth["object"].rotation, SYMMETRY.get(problem.case.category))
    m["scale_err_pct"] = float(abs(o.scale / truth["object"].scale - 1) * 100)
    m["human_scale_err_pct"] = float(abs(h.scale / truth["human"].scale - 1) * 100)
    return m
