"""Joint human–object optimisation of a batch of cases on the shared harness (paper Sec. 4.2.1, supplementary D.1).

The body's pose and shape are fixed (first stage); optimised are the human's and the object's similarities into
the camera frame (Problem.variables: the human's log-scale, the object's log-scale relative to it, a rotation
(6D) and a translation held divided by its own scale each), from the case's first-stage estimates, with Adam
(lr 2e-3, 1,000 steps) on

    L = 1e5 L_contact + 1e2 L_normal + w_pen L_pen + 1e3 L_scale + w_keypoints L_keypoints + w_silhouette L_silhouette

(apps/hoi/losses.py; w_pen 3e5 for an object a person picks up, case.is_handheld, 1e5 for the others; a patch vertex
within `contact_margin`, 1 cm, of its region counts as touching it. FitConfig's defaults are the preset 'tuned',
PRESETS['paper'] the paper's weights: normal 1e3, penetration 1e4, 1e3 with the exact mesh, no contact margin). Coarse to fine: the object is first moved along its camera ray to the
depth of the lowest loss (`along_ray`), its rotation then held for the first 40 % of the steps (`rotation_after`). The body is posed once; contact and penetration are measured in its frame (the object placed
by the relative similarity), so its part vertices are constants and the penetration term queries the model kind
(`volume`) at the object vertices only: 'volsmpl' and 'coap' encode the body once (losses.body_query) and 'mesh'
measures exact distances to the posed mesh at every step. Metrics (`case_metrics`) use exact mesh tests.
Cases are batched (apps/hoi/problem.py: padded and masked where their sizes differ), each optimised as if alone.

    res = fit_case(case, body, volume, FitConfig())
    a, b = fit_cases([case_a, case_b], body, volume, FitConfig())
    meshes = placed_meshes(case, asdict(res), body)   # {'body': (V, F), 'object': (V, F)}, camera frame, metres

What a result holds for a user (FitResult): the fitted body (`body`: volsmpl.apps.outputs.body_record, its params
in the body model's frame, its joints and its placement in the camera frame) and the fitted object (`object`: its
similarity into the camera frame, its category and the first stage's similarity). The frame of both is the
camera's (OpenCV axes: x right, y down, z forward; metres), the frame of the case (apps/hoi/case.py).
"""
from __future__ import annotations

from dataclasses import asdict, dataclass, field

import numpy as np
import torch

from volsmpl.geometry.point_mesh_distance import mesh_signed_distance
from volsmpl.optim import State, Term, optimize
from volsmpl.scene import SYMMETRY, rotation_error_deg

from .case import HoiCase, Similarity
from .losses import keypoint_term, penetration, scale_prior, silhouette_term, to_body_frame, to_camera
from .plausibility import judge_fit
from .problem import Problem, object_scale_prior

__all__ = ["CAMERA_FRAME", "PRESETS", "FitConfig", "FitResult", "Problem", "along_ray", "body_placed_record", "case_metrics", "fit_case",
           "fit_cases", "object_record", "object_scale_prior", "penetration_weights", "placed_meshes"]

CONTACT_RADIUS = 0.02  # metres: ground-truth contact regions are the points within this distance of the other surface
CAMERA_FRAME = "camera (OpenCV axes: x right, y down, z forward; metres)"  # the frame of a case's placements


#: weight sets: 'paper' (supp. D.1: lambda = 1e5, 1e3, 1e4, 1e3; lambda_3 = 1e3 for the mesh SDF; the first stage's
#: placement optimised from its first step) and 'tuned' (FitConfig's defaults). Measured on the tuning half's 16
#: handheld cases (volsmpl, every fit started at the ground truth): with the normal term at 1e3 the object turns by
#: 20 deg median (1 + cos of the contact patches' mean normals is 0.05-0.5 at the truth, its rotation gradient 100x
#: the silhouette's), at 1e2 by 6.7 deg. Penetration: the contact's pull on a handheld object is balanced by the
#: penetration term's push, w_pen times the share of the object's vertices inside, so a weight sets how far the
#: contact pulls it in (the database's phones lie 1 cm from the palm). Tuning half, volsmpl (`volsmpl hoi tune --grid
#: w_pen=1e5,3e5 --cases all`, score of tune.py): handheld objects 22.3 at 1e5, 21.1 at 3e5 (phones up to 5.3 % inside
#: at 1e5, 2.0 % at 3e5; 1e6 leaves them 1.5 % inside but pushes bottles 2-5 cm off the hand), the others 19.2 at 1e5,
#: 25.5 at 3e5 (beds, sofas and carts pushed off their contacts): hence 3e5 for handheld objects, 1e5 for the others.
PRESETS = {
    "paper": {"w_normal": 1e3, "w_pen": 1e4, "w_pen_mesh": 1e3, "w_pen_handheld": None, "rotation_after": 0.0,
              "depth_steps": 0, "scale_free_std": 0.0, "contact_margin": 0.0},
    "tuned": {"w_normal": 1e2, "w_pen": 1e5, "w_pen_mesh": None, "w_pen_handheld": 3e5, "rotation_after": 0.4,
              "depth_steps": 41, "scale_free_std": 1.0, "contact_margin": 0.01},
}


@dataclass
class FitConfig:
    """Weights and optimiser settings: the preset 'tuned' (PRESETS; `FitConfig.preset('paper')` gives the paper's
    weights), Adam lr 2e-3 and 1,000 steps as the paper. The image-term weights are ours (the paper keeps the first
    stage's image alignment without stating its weight): tuned on the tuning split (apps/hoi/tune.py)."""

    iters: int = 1000
    lr: float = 2e-3
    w_contact: float = 1e5
    w_normal: float = PRESETS["tuned"]["w_normal"]
    w_pen: float = PRESETS["tuned"]["w_pen"]
    w_pen_mesh: float | None = PRESETS["tuned"]["w_pen_mesh"]  # the exact mesh's penetration weight; None: w_pen
    # the penetration weight of the objects a person picks up (case.is_handheld), every kind; None: as the others'
    w_pen_handheld: float | None = PRESETS["tuned"]["w_pen_handheld"]
    w_scale: float = 1e3
    # w_keypoints: a sweep of both image weights at 1e5 / 1e6 / 1e7 on the first 13 tuning cases (volsmpl; the lowest
    # mean contact_cm + obj_trans_err_cm + collision_pct) chose 1e6 (docs/hoi/tune.json as of commit a2a727b).
    # w_silhouette: the silhouette term is relative to the silhouette's spread (losses.silhouette_term); 4e3 is that
    # 1e6 times the database's median spread (4.1e-3 focal lengths squared), so the median object is held as before
    w_keypoints: float = 1e6
    w_silhouette: float = 4e3
    # the share of a contact part's vertices (those facing the region) that the contact term pulls onto it: the part's
    # contact patch (losses.contact_terms); 1: the whole part (the plain one-way Chamfer). Set on the tuning half:
    # 3-9 % of a hand's, pelvis' or thigh's vertices are within 2 cm of the object at the truth, and 0.03 is the
    # largest share whose patch lies within 1 cm of the region at the truth (median over the pairs: 0.8 cm; 1.0: 5 cm)
    contact_fraction: float = 0.03
    # metres: the contact's squared distances become linear beyond this (pseudo-Huber, losses.contact_terms); 0: the
    # plain squared distance (its first steps, tens of cm off, stall Adam for the rest of the run)
    contact_huber: float = 0.02
    # metres: a contact patch vertex this near its region counts as touching it (losses.contact_terms), so the contact
    # stops pulling there and the penetration term alone sets how near a thin object comes (the database's phones lie
    # about 1 cm from the palm at the truth); 0: the contact pulls the patch onto the region's surface. Tuning half,
    # volsmpl (`volsmpl hoi tune --grid contact_margin=0 ...` and `=0.01`, docs/hoi/tune.json), 0 -> 1 cm: handheld
    # score (tune.py) 21.06 -> 21.11, the worst cup, phone or bottle 1.99 -> 1.33 % inside; the others' score 20.10 ->
    # 18.18 (median object error 7.0 -> 4.7 cm, contact 5.3 -> 4.2 cm)
    contact_margin: float = PRESETS["tuned"]["contact_margin"]
    region_points: int = 256  # points sampled on each object contact region
    part_points: int = 1024  # body part vertices per contact pair (an even stride through the part's vertices)
    silhouette_points: int = 500  # silhouette pixels used (an even stride through the case's sample)
    silhouette_vertices: int = 1000  # object vertices projected for the silhouette term (an even stride)
    # the object's triangles are split until no edge is longer than this fraction of its largest extent, so its
    # vertices (penetration term, metrics) cover the surface evenly; 0 keeps the mesh as it is
    max_edge_frac: float = 0.08  # 600-6,000 vertices for the templates
    # coarse to fine: the object's rotation is held for this share of the steps while its translation and scale bring
    # it to the body. A first stage 20-90 cm off (the depth-scale ambiguity of one view) is pulled in by the contact term,
    # whose pull on the nearest region points turns the object on its way (handheld objects of the tuning half:
    # median rotation error 61 deg after the fit when it turns from the first step, 32 deg when held for 400)
    rotation_after: float = PRESETS["tuned"]["rotation_after"]
    # before the fit, the object is moved along its camera ray (its projection kept) to the depth of the lowest loss
    # among `depth_steps` depths within a factor exp(+-depth_range) of the first stage's (0 steps: no search); the
    # database's first stages are 20-90 cm off in depth, the depth-scale ambiguity of one view (factor 0.7-1.3)
    depth_steps: int = PRESETS["tuned"]["depth_steps"]
    depth_range: float = 0.5
    # the scale prior of an object that is not handheld pulls only beyond this many of its category's standard
    # deviations of real size from the mean (SIZE_PRIOR; a user's stated size: none): within them its silhouette and
    # its contacts decide the scale. Tuning half, volsmpl, w_pen 1e5: the 22 such cases' median scale error 6.0 ->
    # 2.6 % (sofas 9.1 -> 3.7 %), score (tune.py) 19.2 -> 20.1, score with the scale error added 25.2 -> 22.7. Handheld
    # objects keep the plain prior: with the band the contact pulls a phone deeper into the hand as it grows (the
    # worst of the tuning half's phones 2.0 -> 3.5 % inside at w_pen_handheld 3e5, 2.5 % at 1e6)
    scale_free_std: float = PRESETS["tuned"]["scale_free_std"]
    device: str = "cpu"

    @classmethod
    def preset(cls, name: str, **overrides) -> "FitConfig":
        """The weights of PRESETS[name] with `overrides` on top."""
        if name not in PRESETS:
            raise ValueError(f"unknown preset {name!r}; choose one of {', '.join(PRESETS)}")
        return cls(**{**PRESETS[name], **overrides})

    def __post_init__(self):
        if not isinstance(self.iters, int) or self.iters < 0:
            raise ValueError(f"iters must be an integer >= 0, got {self.iters!r}")
        if not self.lr > 0:
            raise ValueError(f"lr must be > 0, got {self.lr}")
        if not 0.0 < self.contact_fraction <= 1.0:
            raise ValueError(f"contact_fraction must be in (0, 1], got {self.contact_fraction}")
        if not isinstance(self.depth_steps, int) or self.depth_steps < 0:
            raise ValueError(f"depth_steps must be an integer >= 0, got {self.depth_steps!r}")
        if not (np.isfinite(self.depth_range) and self.depth_range > 0):
            raise ValueError(f"depth_range must be a finite log-factor > 0, got {self.depth_range}")
        if not 0.0 <= self.rotation_after < 1.0:
            raise ValueError(f"rotation_after must be a share of the steps in [0, 1), got {self.rotation_after}")
        if not (np.isfinite(self.scale_free_std) and self.scale_free_std >= 0):
            raise ValueError(f"scale_free_std must be a finite number of standard deviations >= 0, got {self.scale_free_std}")
        if not (np.isfinite(self.contact_huber) and self.contact_huber >= 0):
            raise ValueError(f"contact_huber must be a finite length >= 0 (metres), got {self.contact_huber}")
        if not (np.isfinite(self.contact_margin) and self.contact_margin >= 0):
            raise ValueError(f"contact_margin must be a finite length >= 0 (metres), got {self.contact_margin}")
        for k, v in asdict(self).items():
            if k.startswith("w_") and not (v is None and k in ("w_pen_mesh", "w_pen_handheld")) and not (np.isfinite(v) and v >= 0):
                raise ValueError(f"{k} must be a finite weight >= 0, got {v}")


@dataclass
class FitResult:
    name: str
    model: str
    status: str  # plausibility.judge_fit: 'converged', 'diverged', 'object_lost' or 'worse_than_start'
    iterations: int
    ms_per_iter: float
    total_s: float
    peak_mem_mb: float
    human: dict  # fitted similarity of the body into the camera frame (Similarity.to_dict)
    object: dict  # object_record: the fitted similarity, the category and the first stage's similarity
    before: dict = field(default_factory=dict)  # case_metrics of the first-stage estimates
    after: dict = field(default_factory=dict)  # case_metrics of the fit
    loss: list = field(default_factory=list)  # total loss every 50 steps
    batch: int = 1  # cases optimised together (ms_per_iter and total_s are the batch's divided by it)
    status_why: str = ""  # the reason of a status other than 'converged'
    stop: str = ""  # the optimiser's stop rule (volsmpl.optim: 'max_iters', 'converged', ...)
    body: dict = field(default_factory=dict)  # body_placed_record: params, joints and placement (camera frame)


def penetration_weights(problem: Problem, kind: str, cfg: FitConfig) -> torch.Tensor:
    """(B,) each case's penetration weight: w_pen_handheld for a handheld object (case.is_handheld) when set, else
    w_pen_mesh with the exact mesh when set, else w_pen."""
    base = cfg.w_pen_mesh if kind == "mesh" and cfg.w_pen_mesh is not None else cfg.w_pen
    hand = base if cfg.w_pen_handheld is None else cfg.w_pen_handheld
    return torch.where(problem.handheld, hand, base).to(problem.prior_object.dtype)


def _terms(problem: Problem, volume, cfg: FitConfig) -> dict:
    w = penetration_weights(problem, volume.kind, cfg)
    w_pen = float(w.max())  # the term's weight; each case's own is w_pen * w / w_pen
    rel = w / w_pen if w_pen > 0 else w

    terms = {
        "contact": Term(lambda s: s.placed["contact"], cfg.w_contact),
        "normal": Term(lambda s: s.placed["normal"], cfg.w_normal),
        "penetration": Term(lambda s: penetration(problem.query, s.placed["pen_body"], problem.pen_mask) * rel, w_pen),
        "scale": Term(lambda s: scale_prior(s.placed["object"][0], problem.prior_object, problem.prior_object_free)
                      + scale_prior(s.placed["human"][0], 1.0), cfg.w_scale),
        "keypoints": Term(lambda s: keypoint_term(s.placed["joints_cam"], problem.kp, problem.K), cfg.w_keypoints),
        "silhouette": Term(lambda s: silhouette_term(s.placed["sil_cam"], problem.sil_v_mask, problem.sil,
                                                     problem.sil_mask, problem.K), cfg.w_silhouette),
    }
    return {k: t for k, t in terms.items() if t.weight > 0}  # a term weighted 0 is not evaluated


@torch.no_grad()
def along_ray(problem: Problem, variables: dict, terms: dict, cfg: FitConfig) -> tuple:
    """The object of each case moved along its camera ray to the depth of the lowest loss (every term, weighted)
    among cfg.depth_steps depths spaced evenly in log-depth within exp(+-cfg.depth_range) of its current one. The
    depth is the object's log-scale relative to the human's (Problem.similarity): a change of it scales the object
    about the camera centre, so its projection, and with it the image terms, stay as they are while contact,
    penetration and the scale prior choose the depth. Returns (variables with the chosen depths, (B,) the chosen
    log-factors: 0 where the first stage's depth was best)."""
    from dataclasses import replace

    key = "object_rel_log_scale"
    start = variables[key].value
    if cfg.depth_steps == 0:
        return variables, torch.zeros(len(start), device=start.device)
    offsets = torch.linspace(-cfg.depth_range, cfg.depth_range, cfg.depth_steps, device=start.device)
    offsets = torch.cat([offsets.new_zeros(1), offsets])  # the first stage's own depth first: it wins a tie
    state = {n: v.value for n, v in variables.items()}
    losses = []
    for o in offsets:
        s = State({**state, key: start + o})
        s["placed"] = problem.placed(s)
        losses.append(sum(t.weight * t.fn(s) for t in terms.values()))
    losses = torch.stack(losses)  # (D + 1, B)
    losses = torch.where(torch.isfinite(losses), losses, torch.inf)
    best = offsets[losses.argmin(dim=0)]
    return {**variables, key: replace(variables[key], value=start + best[:, None])}, best


def body_placed_record(output, i: int, human: Similarity, first_stage: Similarity | None = None) -> dict:
    """The i-th body of a `BodyOutput` (the body model's frame) placed in the camera frame by `human`, as a JSON
    record: volsmpl.apps.outputs.body_record (params in the body model's frame; joints in the camera frame,
    metres, units 'm', up 'y': the camera frame's axes kept as they are), plus `frame`, `placement` (the
    similarity: camera = scale * rotation @ body(params) + translation) and `first_stage` (the case's)."""
    from types import SimpleNamespace

    from volsmpl.apps.outputs import body_record

    joints = human.apply(output.joints[i].detach().double().cpu().numpy())
    placed = SimpleNamespace(joints=joints[None], **{k: getattr(output, k)[i:i + 1]
                                                     for k in ("betas", "global_orient", "body_pose", "transl")})
    rec = body_record(placed, 0, units="m", up="y")
    rec.update(frame=CAMERA_FRAME, placement=human.to_dict())
    if first_stage is not None:
        rec["first_stage"] = first_stage.to_dict()
    return rec


def object_record(case: HoiCase, fitted: Similarity) -> dict:
    """The fitted object as a JSON record: its similarity into the camera frame (scale, rotation, translation:
    camera = scale * rotation @ x + translation, x in the object's own frame, metres), its `category`, `frame`,
    and `first_stage`, the case's first-stage similarity."""
    return {**fitted.to_dict(), "category": case.category, "frame": CAMERA_FRAME,
            "first_stage": case.init["object"].to_dict()}


def placed_meshes(case: HoiCase, record: dict, body) -> dict:
    """{'body': (vertices, faces), 'object': (vertices, faces)} of a fit record (FitResult as a dict) in the
    camera frame, metres: the body rebuilt from the record's params and placement, the case's object mesh (its
    own file or template, case.object_mesh) moved by the record's object similarity."""
    from .case import object_mesh, object_template

    b = record["body"]
    with torch.no_grad():
        out = body(**{k: torch.tensor([v], dtype=torch.float32, device=body.v_template.device)
                      for k, v in b["params"].items()})
    v = Similarity.from_dict(b["placement"], "body.placement").apply(out.vertices[0].double().cpu().numpy())
    mesh, _ = object_mesh(case, object_template(case))
    o = Similarity.from_dict(record["object"], "object").apply(np.asarray(mesh.vertices, dtype=np.float64))
    return {"body": (v, np.asarray(body.faces)), "object": (o, np.asarray(mesh.faces))}


def fit_cases(cases: list, body, volume, cfg: FitConfig = FitConfig(), problem: Problem | None = None,
              progress: bool | None = None) -> list:
    """Optimise the human and object similarities of B cases together against `volume` (any model kind): one Adam
    over their stacked variables, each case as if alone (their losses are summed); metrics before/after per case.
    `ms_per_iter` of each result is the batch's time per iteration divided by B (the cost of one case's step),
    `peak_mem_mb` the batch's peak. progress: the harness's per-step bar (volsmpl.optim.optimize: None shows it on
    a terminal, False never; volsmpl.apps.progress.steps_bar). Returns one FitResult per case, in order."""
    problem = (problem or Problem(cases, body, volume, cfg)).prepare(volume)
    if [c.name for c in problem.cases] != [c.name for c in cases]:
        raise ValueError("the problem was built for other cases")
    terms = _terms(problem, volume, cfg)
    variables, _ = along_ray(problem, problem.variables([c.init for c in cases]), terms, cfg)
    run = optimize(variables, terms,
                   prepare=lambda s: {"placed": problem.placed(s)}, optimizer="adam", lr=cfg.lr,
                   max_iters=cfg.iters, frozen=[volume], device=cfg.device, progress=progress, usable=problem.usable,
                   desc=f"{cases[0].name if len(cases) == 1 else f'{len(cases)} cases'} {volume.kind}")
    sims = {who: problem.similarity(run.variables, who) for who in ("human", "object")}
    steps, B = run.step_ms(), len(cases)
    results = []
    for i, case in enumerate(cases):
        raw = {who: (float(sc[i]), R[i].double().cpu().numpy(), t[i].double().cpu().numpy())
               for who, (sc, R, t) in sims.items()}
        numbers = [x for s_, R_, t_ in raw.values() for x in (s_, *R_.ravel(), *t_)]
        ends = [run.records[0].total[i], run.records[-1].total[i]] if run.records else []
        if all(np.isfinite(numbers)):
            fitted = {who: Similarity(*v) for who, v in raw.items()}
            before, after = case_metrics(problem, case.init, i), case_metrics(problem, fitted, i)
        else:  # a diverged fit: no placement to measure
            fitted, before, after = None, case_metrics(problem, case.init, i), {}
        status, why = judge_fit(ends, numbers, before, after, run.status[i])
        placed = fitted or case.init
        results.append(FitResult(
            name=case.name, model=volume.kind, status=status, iterations=run.iterations[i],
            ms_per_iter=float(np.mean(steps)) / B if steps else float("nan"), total_s=run.seconds / B,
            peak_mem_mb=run.peak_bytes / 2 ** 20,
            human=placed["human"].to_dict(), object=object_record(case, placed["object"]),
            before=before, after=after, loss=[r.total[i] for r in run.records[::50]], batch=B, status_why=why,
            stop=run.status[i], body=body_placed_record(problem.out, i, placed["human"], case.init["human"])))
    return results


def fit_case(case: HoiCase, body, volume, cfg: FitConfig = FitConfig(), problem: Problem | None = None,
             progress: bool | None = None) -> FitResult:
    """`fit_cases` of one case."""
    return fit_cases([case], body, volume, cfg, problem, progress=progress)[0]


def _within(a: torch.Tensor, b: torch.Tensor, radius: float):
    """(A,) and (B,) bool: the points of a (A, 3) within `radius` of some point of b (B, 3), and the converse
    (k-d trees: the (A, B) distance matrix of a body and an object's samples is ~50 M entries)."""
    from scipy.spatial import cKDTree

    x, y = (t.detach().cpu().double().numpy() for t in (a, b))
    da = cKDTree(y).query(x, distance_upper_bound=radius)[0]
    db = cKDTree(x).query(y, distance_upper_bound=radius)[0]
    return (torch.as_tensor(da < radius, device=a.device), torch.as_tensor(db < radius, device=a.device))


@torch.no_grad()
def case_metrics(problem: Problem, sim: dict, i: int = 0) -> dict:
    """Exact metrics of case i's placement {'human': Similarity, 'object': Similarity}: object vertices inside the
    body (%, exact mesh test), the gap between the object and the body (cm, 0 when they touch), and with ground truth: contact (cm: symmetric Chamfer, mean nearest distance, between
    the ground-truth contact regions as placed: the body's vertices and the object's surface samples within 2 cm of
    the other surface in the ground truth), object translation (cm, centroid) and rotation (deg) errors, object
    and human scale errors (%)."""
    dev = problem.K.device
    h, o = sim["human"], sim["object"]
    args = lambda s: (torch.tensor([s.scale], device=dev), torch.as_tensor(s.rotation, dtype=torch.float32, device=dev)[None],  # noqa: E731
                      torch.as_tensor(s.translation, dtype=torch.float32, device=dev)[None])
    obj_v = problem.obj_v[i:i + 1, problem.obj_mask[i]]
    body_v, samples = problem.body_v[i:i + 1], problem.obj_samples[i:i + 1]
    x = to_body_frame(to_camera(obj_v, *args(o)), *args(h))
    d = mesh_signed_distance(body_v[0], problem.faces, x[0], closed=True)
    # gap_cm: the object's nearest vertex from the body's surface (0 when it touches or enters it)
    m = {"collision_pct": float((d < 0).float().mean() * 100), "gap_cm": float(d.min().clamp(min=0) * 100)}
    case = problem.cases[i]
    truth = case.truth
    if truth is None:
        return m
    body_t = to_camera(body_v, *args(truth["human"]))[0]
    obj_t = to_camera(samples, *args(truth["object"]))[0]
    near_b, near_o = _within(body_t, obj_t, CONTACT_RADIUS)
    if near_b.any() and near_o.any():
        b = to_camera(body_v, *args(h))[0][near_b]
        ob = to_camera(samples, *args(o))[0][near_o]
        dd = torch.cdist(b, ob)
        m["contact_cm"] = float((dd.min(dim=1).values.mean() + dd.min(dim=0).values.mean()) / 2 * 100)
    c = obj_v[0].mean(dim=0, keepdim=True)
    ct = to_camera(c[None], *args(truth["object"]))[0, 0]
    cf = to_camera(c[None], *args(o))[0, 0]
    m["obj_trans_err_cm"] = float((cf - ct).norm() * 100)
    # modulo the category's symmetry (a bottle turned about its axis is not wrong; a ball has no rotation error)
    m["obj_rot_err_deg"] = rotation_error_deg(o.rotation, truth["object"].rotation, SYMMETRY.get(case.category))
    m["scale_err_pct"] = float(abs(o.scale / truth["object"].scale - 1) * 100)
    m["human_scale_err_pct"] = float(abs(h.scale / truth["human"].scale - 1) * 100)
    return m
