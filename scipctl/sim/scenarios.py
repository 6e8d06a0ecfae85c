"""Scenarios: rover approaches to a target rock, as downlinks with exact truth (pure numerics; no files).

``paper`` -- the experiment of the SCIP handoff paper: 3 scenes x {straight,
arc} approaches = 6 runs (``s1-straight``, ``s1-arc``, ... ``s3-arc``). Stops
(distances are ground distances from the named cameras to the centre of the
big rock):

=========  ========================  =====================================
stop       cameras                   place
=========  ========================  =====================================
``pan10``  pancam                    mast 10 m from the rock
``mid``    pancam + navcam           mast 4.5 m
``far``    navcam                    navcams 3 m
``near``   navcam + hazcam           hazcams 1 m, rover facing the rock
=========  ========================  =====================================

``pan10``/``mid``/``far`` lie on the approach bearing; in the ``arc`` run that
bearing is rotated by 30 deg about the rock, so the far navcams see the rock
from 30 deg away from the near stop's line of sight. The near stop is the same
in both runs of a scene (up to 2 cm / 1.5 deg). Mast cameras are pointed at the
rock with ``RoverConfig.point_at`` of the calibrated config (the rover's belief),
for the rock's place relative to the rover as SCIP's tracking measures it.

``traverse`` -- one approach from 10 m with stops every 10-20 % of the
remaining distance (pancam down to ~4.5 m, navcam from ~5 m, hazcams from 2 m
hazcam distance to 1 m), runs ``s1-straight`` and ``s1-curved``.

Each run has 3 marked targets of different kinds (``flat``, ``point``,
``edge``, ``sand``, ``contrast``); the 6 paper runs make the paper's 18 handoff
cases. Marks are the exact projection of the target's true 3-D point through
the true model of every image that sees it (in the image, and not occluded:
checked by a ray cast from the model's ray origin -- the CAHVORE entrance
pupil -- to the point).
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass, field
from typing import Callable, Optional

import numpy as np

from ..core.camera import CameraModel
from ..core.kinematics import RoverConfig, RoverPose
from ..core.transforms import RigidTransform
from ..model import Downlink, ImageProduct, ImageTruth, MastAngles, Mark, TargetMarks, TargetTruth
from . import rover as rover_mod
from .errors import DEG, ErrorSettings, estimate_poses, rover_rotation, true_rover_config, vibration
from .scene import GEOM_ROCKS, GEOM_TERRAIN, MAT_ROCK, MAT_TERRAIN, Scene, make_scene

SCENARIOS = ("paper", "traverse")
KINDS = ("flat", "point", "edge", "sand", "contrast")
MISSION = "scip-sim"
# the default rover's placement constants (a SimRover carries each rover's own: scipctl/sim/rover.py)
MAST_REF_X_M = rover_mod.DEFAULT_MAST_REF_X_M  # between the pancam and navcam centres
NAVCAM_REF_X_M = rover_mod.DEFAULT_NAVCAM_REF_X_M
HAZCAM_REF_X_M = rover_mod.DEFAULT_HAZCAM_REF_X_M
WHEELS_XY_M = rover_mod.DEFAULT_WHEELS_XY_M
DEFAULT_BITS = {"pancam": 8, "navcam": 8, "hazcam": 8}
EXPOSURE_MS_PER_UNIT = {"pancam": 40.0, "navcam": 25.0, "hazcam": 15.0}
DRIVE_SPEED_M_S = 0.05
TURN_RATE_RAD_S = 0.05
SETTLE_S = 20.0
STEREO_GAP_S = 1.5
PAIR_GAP_S = 10.0
OCCLUSION_TOL_M = 1e-3


def _rng(*keys) -> np.random.Generator:
    """A generator seeded from ints and strings (stable across runs and platforms)."""
    ints = []
    for k in keys:
        if isinstance(k, str):
            ints.append(int.from_bytes(hashlib.sha256(k.encode()).digest()[:4], "little"))
        else:
            ints.append(int(k) & 0xFFFFFFFF)
    return np.random.default_rng(np.random.SeedSequence(ints))


def _wrap(a: float) -> float:
    return float((a + np.pi) % (2 * np.pi) - np.pi)


# ----------------------------------------------------------------------------- plans
@dataclass
class StopPlan:
    label: str
    xy_m: np.ndarray  # (2,) true rover origin, site frame
    yaw_rad: float  # true heading
    cameras: tuple  # camera pairs imaged at this stop, in order
    ref_camera: str = "navcam"  # the pair whose ground distance to the rock is ``ref_dist_m``
    ref_dist_m: float = 0.0
    bearing_rad: float = 0.0  # from the rock towards the reference cameras
    path_length_m: float = 0.0  # drive from the previous stop
    turn_rad: float = 0.0
    arc_leg: bool = False  # the drive from the previous stop is an arc (5 % longer than the chord)


@dataclass
class RunPlan:
    scenario: str
    run: str
    seed: int
    scene_index: int
    scene_seed: int
    bearing_rad: float  # from the rock towards the final approach
    sun_azimuth_rad: float
    keep_clear: list
    stops: list  # list[StopPlan]
    kinds: tuple  # target kinds wanted, in order of preference
    key_images: list  # [(stop label, camera)] whose pairs must see every target
    sol: int = 1
    rover: Optional[rover_mod.SimRover] = field(default=None, repr=False)  # None: the default rover

    @property
    def name(self) -> str:
        return f"{self.scenario}-{self.run}"


def _place(ref_x_m: float, dist_m: float, bearing_rad: float, jitter=(0.0, 0.0, 0.0)):
    """Rover origin ``(2,)`` and heading for a camera reference point at ``ref_x_m`` (rover x) that stands
    ``dist_m`` from the rock (at the origin) along ``bearing_rad``, the rover facing the rock."""
    c = dist_m * np.array([np.cos(bearing_rad), np.sin(bearing_rad)])
    yaw = bearing_rad + np.pi + jitter[2]
    xy = c - ref_x_m * np.array([np.cos(yaw), np.sin(yaw)]) + np.array(jitter[:2])
    return xy, _wrap(yaw)


def _finish_legs(stops: list, arc_legs: set = frozenset()) -> list:
    for i in range(1, len(stops)):
        d = float(np.linalg.norm(stops[i].xy_m - stops[i - 1].xy_m))
        stops[i].arc_leg = i in arc_legs
        stops[i].path_length_m = d * (1.05 if stops[i].arc_leg else 1.0)
        stops[i].turn_rad = _wrap(stops[i].yaw_rad - stops[i - 1].yaw_rad)
    return stops


def _corridors(bearings, r0=0.75, r1=13.0, half_width=1.0):
    out = []
    for b in bearings:
        u = np.array([np.cos(b), np.sin(b)])
        out.append((r0 * u, r1 * u, half_width))
    return out


def list_runs(scenario: str) -> list[str]:
    if scenario == "paper":
        return [f"s{i}-{a}" for i in (1, 2, 3) for a in ("straight", "arc")]
    if scenario == "traverse":
        return ["s1-straight", "s1-curved"]
    raise ValueError(f"scenario: unknown {scenario!r} (want one of {', '.join(SCENARIOS)})")


def _scene_params(scenario: str, seed: int, scene_index: int):
    r = _rng(seed, scenario, "scene", scene_index)
    bearing = r.uniform(0, 2 * np.pi)
    turn_sign = float(r.choice([-1.0, 1.0]))
    sun_off = float(r.choice([-1.0, 1.0])) * r.uniform(35, 100) * DEG
    scene_seed = int(r.integers(0, 2 ** 31 - 1))
    return bearing, turn_sign, bearing + sun_off, scene_seed


def plan_run(scenario: str, run: str, seed: int, rover: Optional[rover_mod.SimRover] = None) -> RunPlan:
    """The geometry of one run (no rendering). ``rover``: whose placement constants and corridor width to use
    (None: the default rover)."""
    rv = rover_mod.default_sim_rover() if rover is None else rover
    MAST_REF_X_M, NAVCAM_REF_X_M, HAZCAM_REF_X_M = rv.mast_ref_x_m, rv.navcam_ref_x_m, rv.hazcam_ref_x_m
    extra = rv.corridor_extra_m
    runs = list_runs(scenario)
    if run not in runs:
        raise ValueError(f"run: unknown {run!r} for scenario {scenario} (want one of {', '.join(runs)})")
    scene_index = int(run.split("-")[0][1:])
    approach = run.split("-", 1)[1]
    beta, sgn, sun_az, scene_seed = _scene_params(scenario, seed, scene_index)
    rr = _rng(seed, scenario, run)
    run_index = runs.index(run)
    if scenario == "paper":
        alpha = 0.0 if approach == "straight" else sgn * 30.0 * DEG
        b_far = beta + alpha
        # the near stop of the two runs of a scene: the same place up to ~1 cm and ~1 deg
        near_d, near_b, near_yaw = 1.0 + rr.normal(0, 0.01), beta + rr.normal(0, 0.5 * DEG), rr.normal(0, 0.75 * DEG)
        stops = []
        xy, yaw = _place(MAST_REF_X_M, 10.0, b_far)
        stops.append(StopPlan("pan10", xy, yaw, ("pancam",), "pancam", 10.0, b_far))
        xy, yaw = _place(MAST_REF_X_M, 4.5, b_far)
        stops.append(StopPlan("mid", xy, yaw, ("pancam", "navcam"), "navcam", 4.5, b_far))
        xy, yaw = _place(NAVCAM_REF_X_M, 3.0, b_far)
        stops.append(StopPlan("far", xy, yaw, ("navcam",), "navcam", 3.0, b_far))
        xy, yaw = _place(HAZCAM_REF_X_M, near_d, near_b, (0.0, 0.0, near_yaw))
        stops.append(StopPlan("near", xy, yaw, ("navcam", "hazcam"), "hazcam", near_d, near_b))
        _finish_legs(stops, arc_legs={3} if alpha else set())
        keep = _corridors([beta, beta + sgn * 30.0 * DEG], half_width=1.0 + extra)
        # the arc between the far arc stop and the near stop
        arc = [_place(NAVCAM_REF_X_M, r, beta + sgn * f * 30.0 * DEG)[0] for r, f in ((3.2, 1.0), (2.4, 0.6), (1.8, 0.3), (1.6, 0.0))]
        keep += [(arc[i], arc[i + 1], 1.0 + extra) for i in range(len(arc) - 1)]
        kinds = tuple(KINDS[(3 * run_index + j) % len(KINDS)] for j in range(3))
        key = [("near", "hazcam"), ("near", "navcam"), ("far", "navcam")]
        return RunPlan(scenario, run, seed, scene_index, scene_seed, beta, sun_az, keep, stops, kinds, key, sol=run_index + 1,
                       rover=rover)
    # traverse
    curve = 0.0 if approach == "straight" else sgn * 35.0 * DEG
    haz_off = HAZCAM_REF_X_M - MAST_REF_X_M
    d_end = 1.0 + haz_off  # mast distance when the hazcams are 1 m from the rock
    ds = [10.0]
    while ds[-1] > d_end + 1e-9:
        d = ds[-1] * (1.0 - rr.uniform(0.10, 0.20))
        for must in (4.6, 2.0 + haz_off):  # a stop at the pancam->navcam handoff and at 2 m hazcam distance
            if ds[-1] > must + 1e-9 and d < must:
                d = must
        ds.append(max(d, d_end))
    stops = []
    for k, d in enumerate(ds):
        b = beta + curve * (10.0 - d) / (10.0 - d_end)
        cams = []
        if d > 4.3:
            cams.append("pancam")
        if d < 5.3:
            cams.append("navcam")
        if d - haz_off <= 2.0 + 1e-9:
            cams.append("hazcam")
        xy, yaw = _place(MAST_REF_X_M, d, b)
        ref = "hazcam" if "hazcam" in cams else ("navcam" if "navcam" in cams else "pancam")
        ref_d = d - haz_off if ref == "hazcam" else d
        stops.append(StopPlan(f"d{k:02d}", xy, yaw, tuple(cams), ref, ref_d, b))
    _finish_legs(stops, arc_legs=set(range(1, len(stops))) if curve else set())
    bs = np.linspace(0, 1, 8)
    keep = []
    pts = [_place(MAST_REF_X_M, d_end + (10.5 - d_end) * f, beta + curve * (1 - f))[0] for f in bs]
    keep += [(pts[i], pts[i + 1], 1.1 + extra) for i in range(len(pts) - 1)]
    kinds = tuple(KINDS[(3 * run_index + j) % len(KINDS)] for j in range(3))
    first_nav = next(s.label for s in stops if "navcam" in s.cameras)
    key = [(stops[-1].label, "hazcam"), (stops[-1].label, "navcam"), (first_nav, "navcam"), (stops[0].label, "pancam")]
    return RunPlan(scenario, run, seed, scene_index, scene_seed, beta, sun_az, keep, stops, kinds, key, sol=run_index + 1,
                   rover=rover)


def default_errors(scenario: str) -> ErrorSettings:
    """The errors a scenario injects by default: :class:`ErrorSettings` defaults, and for ``paper`` a washed-out
    far navcam pair in run ``s2-arc`` (the paper's run 4)."""
    if scenario == "paper":
        return ErrorSettings(washed_out=(("s2-arc", "far", "navcam"),))
    return ErrorSettings()


# ----------------------------------------------------------------------------- scene cache
_SCENES: dict = {}


def scene_for(plan: RunPlan, texture=None) -> Scene:
    """The plan's scene (cached per scene seed, rover and texture: both runs of a scene share it).

    ``texture``: a :class:`~scipctl.sim.texture.TextureSources` to drape on the terrain (None: procedural albedo);
    its atlas is built from the scene seed, so the texture is a property of the scene.
    """
    rover_key = None if plan.rover is None or plan.rover.is_default else (plan.rover.key, plan.rover.corridor_extra_m,
                                                                          plan.rover.mast_ref_x_m, plan.rover.navcam_ref_x_m,
                                                                          plan.rover.hazcam_ref_x_m)
    key = (plan.scenario, plan.scene_seed)
    if rover_key is not None or texture is not None:
        key = key + (rover_key, None if texture is None else texture.digest)
    if key not in _SCENES:
        if len(_SCENES) >= 4:  # ~170 MB each
            _SCENES.pop(next(iter(_SCENES)))
        # corridors of both runs of the scene (they share the scene)
        keep = []
        for r in list_runs(plan.scenario):
            if r.split("-")[0] == f"s{plan.scene_index}":
                keep += plan_run(plan.scenario, r, plan.seed, plan.rover).keep_clear
        surface_texture = None
        if texture is not None:
            from .texture import build_surface_texture

            surface_texture = build_surface_texture(texture, plan.scene_seed)
        _SCENES[key] = make_scene(plan.scene_seed, keep_clear=keep, sun_azimuth_rad=plan.sun_azimuth_rad,
                                  texture=surface_texture)
    return _SCENES[key]


# ----------------------------------------------------------------------------- geometry
def true_rover_pose(scene: Scene, xy_m, yaw_rad: float, wheels_xy_m=None) -> RigidTransform:
    """``T_site_rover`` of a rover standing on the terrain at ``xy_m`` (2,) with heading ``yaw_rad``.

    The ground heights under the wheels (``wheels_xy_m`` ``(K, 2)`` rover frame; default the default rover's) are
    fitted by a plane; the rover frame's z axis is its downward normal and the origin lies on it under the
    reference point.
    """
    wheels = WHEELS_XY_M if wheels_xy_m is None else np.asarray(wheels_xy_m, float)
    c, s = np.cos(yaw_rad), np.sin(yaw_rad)
    Rz = np.array([[c, -s], [s, c]])
    wxy = np.asarray(xy_m, float)[None, :] + wheels @ Rz.T
    h = scene.ground_height_m(wxy)
    A = np.concatenate([np.ones((len(wxy), 1)), wxy - np.asarray(xy_m)[None, :]], axis=1)
    a0, hx, hy = np.linalg.lstsq(A, h, rcond=None)[0]
    n_up = np.array([-hx, -hy, -1.0])  # site z down: the upward normal of z = -h(x, y)
    n_up /= np.linalg.norm(n_up)
    R = rover_rotation(yaw_rad, n_up)
    return RigidTransform(R, np.array([xy_m[0], xy_m[1], -a0]))


def _ref_point_xy(stop: StopPlan, T: RigidTransform, calibrated: RoverConfig, true_cfg: RoverConfig, aim_site) -> np.ndarray:
    """Site (x, y) of the middle of the stop's reference camera pair (true models; mast pointed at the aim)."""
    cam = stop.ref_camera
    pan = tilt = 0.0
    if calibrated.cameras[cam].mount == "mast":
        pan, tilt = calibrated.point_at(cam, T.inverse().apply(aim_site))
    c = [true_cfg.camera_model(cam, eye, pan, tilt).transformed(T).C for eye in ("left", "right")]
    return 0.5 * (c[0][:2] + c[1][:2])


def place_on_terrain(scene: Scene, stop: StopPlan, calibrated: RoverConfig, true_cfg: RoverConfig, aim_site,
                     iterations: int = 4, wheels_xy_m=None) -> RigidTransform:
    """The true ``T_site_rover`` of a stop, moved so that its reference cameras really stand ``ref_dist_m`` from
    the rock along ``bearing_rad`` (the rover's roll and pitch on the terrain move the mast head sideways).
    Updates ``stop.xy_m``."""
    want = stop.ref_dist_m * np.array([np.cos(stop.bearing_rad), np.sin(stop.bearing_rad)]) + scene.target_rock.centre_xy_m
    xy = np.array(stop.xy_m, float)
    for _ in range(iterations):
        T = true_rover_pose(scene, xy, stop.yaw_rad, wheels_xy_m)
        xy = xy + (want - _ref_point_xy(stop, T, calibrated, true_cfg, aim_site))
    stop.xy_m = xy
    return true_rover_pose(scene, xy, stop.yaw_rad, wheels_xy_m)


@dataclass
class ProductPlan:
    """One image to make: everything but the pixels."""

    product_id: str
    stop: str
    stop_index: int
    camera: str
    eye: str
    time_s: float
    pan_rad: Optional[float]
    tilt_rad: Optional[float]
    model_cal: CameraModel  # product camera model (calibrated, rover frame, commanded angles)
    model_true: CameraModel  # true model in the true rover frame
    T_true: RigidTransform  # true T_site_rover
    T_est: RigidTransform  # estimated T_site_rover
    width: int
    height: int
    vibration_rotvec: Optional[list] = None
    cumulative_path_m: float = 0.0  # driven since the first stop

    @property
    def model_true_site(self) -> CameraModel:
        return self.model_true.transformed(self.T_true)


def project_visible(scene: Scene, model_site: CameraModel, width: int, height: int, X_site, tol_m: float = OCCLUSION_TOL_M):
    """Project points ``X_site`` ``(K, 3)``; ``(uv (K, 2), visible (K,) bool)``.

    Visible = finite projection inside ``[-0.5, W - 0.5] x [-0.5, H - 0.5]``, and the ray from the model's
    origin for that pixel (the CAHVORE entrance pupil moves with the ray) towards the point first hits the
    surface at the point (within ``tol_m``): nothing in front of it, and the ray does not slip past it
    (a point exactly on a silhouette).
    """
    X = np.asarray(X_site, float).reshape(-1, 3)
    uv = model_site.project(X)
    ok = np.all(np.isfinite(uv), axis=1)
    ok &= (uv[:, 0] >= -0.5) & (uv[:, 0] <= width - 0.5) & (uv[:, 1] >= -0.5) & (uv[:, 1] <= height - 0.5)
    vis = np.zeros(len(X), bool)
    idx = np.flatnonzero(ok)
    if len(idx):
        o, _ = model_site.unproject(uv[idx])
        v = X[idx] - o
        dist = np.linalg.norm(v, axis=1)
        hits = scene.cast(o, v / dist[:, None])
        vis[idx] = np.abs(hits.t_m - dist) <= tol_m  # the first hit is the point itself
    return uv, vis


# ----------------------------------------------------------------------------- targets
@dataclass
class Target:
    id: str
    kind: str
    description: str
    xyz_site_m: np.ndarray


_DESCRIPTIONS = {
    "flat": "flat, pebble-free ground near the big rock",
    "point": "sharp corner of the big rock",
    "edge": "point on the big rock's occluding edge as the hazcams see it",
    "sand": "inside a drift-sand patch (low texture)",
    "contrast": "high-contrast spot",
}


def _tangent_rings(P, n, radius_m, k=8):
    """Points on circles of ``radius_m`` around ``P`` ``(K, 3)`` in the planes normal to ``n`` ``(K, 3)`` -> ``(K * k, 3)``."""
    P = np.asarray(P, float).reshape(-1, 3)
    n = np.broadcast_to(np.asarray(n, float), P.shape)
    a = np.where((np.abs(n[:, 0]) < 0.9)[:, None], [1.0, 0, 0], [0, 1.0, 0])
    t1 = np.cross(n, a)
    t1 /= np.linalg.norm(t1, axis=1, keepdims=True)
    t2 = np.cross(n, t1)
    ang = np.arange(k) * 2 * np.pi / k
    ring = P[:, None, :] + radius_m * (np.cos(ang)[None, :, None] * t1[:, None, :] + np.sin(ang)[None, :, None] * t2[:, None, :])
    return ring.reshape(-1, 3)


def choose_targets(scene: Scene, plan: RunPlan, products: list, rng: np.random.Generator):
    """Pick ``len(plan.kinds)`` targets visible in both eyes of every ``plan.key_images`` pair.

    Returns ``(targets, record)``; a kind with no valid candidate is replaced by the next kind that has one.
    """
    by = {(p.stop, p.camera, p.eye): p for p in products}
    keys = [(s, c, e) for s, c in plan.key_images for e in ("left", "right")]
    keys = [k for k in keys if k in by]
    haz = by.get((plan.key_images[0][0], "hazcam", "left"))
    ref = haz if haz is not None else by[keys[0]]
    m_ref = ref.model_true_site
    W, H = ref.width, ref.height
    n = 90
    us = np.linspace(0.06 * W, 0.94 * W, n)
    vs = np.linspace(0.06 * H, 0.94 * H, n)
    U, V = np.meshgrid(us, vs)
    uv = np.stack([U.ravel(), V.ravel()], 1)
    o, d = m_ref.unproject(uv)
    hits = scene.cast(o, d)
    rock = scene.target_rock
    n_rock_tris = len(rock.triangles)
    r_xy = np.hypot(hits.points[:, 0], hits.points[:, 1])
    cand = hits.hit & (r_xy < 1.3)
    on_rock = cand & (hits.geometry_id == GEOM_ROCKS) & (hits.primitive_id < n_rock_tris)
    on_ter = cand & (hits.geometry_id == GEOM_TERRAIN) & (r_xy > rock.radius_m + 0.12)

    def visible_everywhere(X):
        X = np.asarray(X, float).reshape(-1, 3)
        ok = np.ones(len(X), bool)
        for k in keys:
            p = by[k]
            w, h = p.width, p.height
            uvk, vis = project_visible(scene, p.model_true_site, w, h, X)
            inner = (uvk[:, 0] > 0.04 * w) & (uvk[:, 0] < 0.96 * w) & (uvk[:, 1] > 0.04 * h) & (uvk[:, 1] < 0.96 * h)
            ok &= vis & inner
        return ok

    # per-kind candidate pools: (points (K, 3), scores (K,)) -- higher score is better
    pools = {}
    P = hits.points
    nrm = hits.normal
    # flat / sand: terrain; check the ground around with vertical rays
    ter_idx = np.flatnonzero(on_ter)
    if len(ter_idx):
        ws = scene.appearance.sand_weight(P[ter_idx, :2])
        slope = np.arccos(np.clip(-nrm[ter_idx, 2], -1, 1))
        k_ring = 8
        rings = _tangent_rings(P[ter_idx], np.array([0, 0, -1.0]), 0.04, k_ring)
        hr = scene.cast(rings - np.array([0, 0, 1.0]), np.tile([0, 0, 1.0], (len(rings), 1)))
        clean = (np.all((hr.geometry_id == GEOM_TERRAIN).reshape(-1, k_ring), axis=1)
                 & (np.ptp(np.nan_to_num(hr.points[:, 2], nan=1e9).reshape(-1, k_ring), axis=1) < 0.008)
                 & (slope <= 10 * DEG))
        wr = scene.appearance.sand_weight(rings[:, :2]).reshape(-1, k_ring)
        flat_ok = clean & (ws == 0) & np.all(wr == 0, axis=1)
        sand_ok = clean & (ws >= 1) & np.all(wr >= 1, axis=1)
        pools["flat"] = (P[ter_idx[flat_ok]], -slope[flat_ok])
        pools["sand"] = (P[ter_idx[sand_ok]], np.zeros(int(sand_ok.sum())))
    # edge: the big rock seen at grazing incidence by the reference camera, next to its silhouette
    rk_idx = np.flatnonzero(on_rock)
    if len(rk_idx):
        cosi = np.abs(np.einsum("ij,ij->i", nrm[rk_idx], d[rk_idx]))
        sel = rk_idx[(cosi > 0.12) & (cosi < 0.45)]
        edge_pts, edge_scores = [], []
        step = 0.012 * W
        for i in sel:
            nb = uv[i][None, :] + step * np.array([[1, 0], [-1, 0], [0, 1], [0, -1], [1, 1], [-1, -1], [1, -1], [-1, 1]])
            on, dn = m_ref.unproject(nb)
            hn = scene.cast(on, dn)
            if np.any(hn.t_m > hits.t_m[i] + 0.08):
                edge_pts.append(P[i])
                edge_scores.append(-abs(np.einsum("j,j->", nrm[i], d[i])))
        pools["edge"] = (np.array(edge_pts).reshape(-1, 3), np.array(edge_scores))
    # point: next to the hull corners of the big rock (3 mm in, on an adjacent facet), sharpest first
    from .scene import vertex_normals

    cv = rock.vertices[rock.corner_idx]
    g = scene.ground_height_m(cv[:, :2])
    above = (-cv[:, 2]) - g > 0.03
    vn = vertex_normals(rock.vertices, rock.triangles)[rock.corner_idx]
    inward = np.array([rock.centre_xy_m[0], rock.centre_xy_m[1], rock.aim_point_site()[2]])[None, :] - cv
    inward -= np.einsum("ij,ij->i", inward, vn)[:, None] * vn
    inward /= np.linalg.norm(inward, axis=1, keepdims=True)
    hc = scene.cast(cv + 0.05 * vn + 0.003 * inward, -vn)
    ok = above & hc.hit & (hc.geometry_id == GEOM_ROCKS) & (hc.primitive_id < n_rock_tris)
    ok &= np.linalg.norm(np.nan_to_num(hc.points - cv, nan=1.0), axis=1) < 0.008
    pools["point"] = (hc.points[ok], rock.corner_sharpness_rad[ok])
    # contrast: local albedo range within 4 mm, over rock and ground candidates
    cc = np.flatnonzero(cand & ((hits.material == MAT_TERRAIN) | (hits.material == MAT_ROCK)))
    if len(cc):
        pick = cc if len(cc) <= 1500 else rng.choice(cc, 1500, replace=False)
        pick = np.sort(pick)
        rings = _tangent_rings(P[pick], nrm[pick], 0.004)
        mats = np.repeat(hits.material[pick], 8)
        sc = np.repeat(hits.obj_scale[pick], 8)
        alb = scene.appearance.albedo(rings, mats, sc, None).reshape(len(pick), 8)
        pools["contrast"] = (P[pick], np.ptp(alb, axis=1))

    chosen: list[Target] = []
    rec = {"wanted": list(plan.kinds), "pool_sizes": {k: int(len(v[0])) for k, v in sorted(pools.items())}, "substituted": []}

    def try_kind(kind):
        pts, scores = pools.get(kind, (np.zeros((0, 3)), np.zeros(0)))
        if len(pts) == 0:
            return None
        # best-scoring quarter first (in random order), then the rest by score
        order_i = np.argsort(-scores, kind="stable")
        q = max(8, len(order_i) // 4)
        top = order_i[:q][rng.permutation(min(q, len(order_i)))]
        for i in list(top) + list(order_i[q:q + 200]):
            X = pts[i]
            if any(np.linalg.norm(X - t.xyz_site_m) < 0.05 for t in chosen):
                continue
            if visible_everywhere(X)[0]:
                return Target(f"t{len(chosen) + 1}", kind, _DESCRIPTIONS[kind], np.array(X, float))
        return None

    for kind in plan.kinds:
        t = try_kind(kind)
        if t is not None:
            chosen.append(t)
    for kind in [k for k in KINDS if k not in plan.kinds] + list(KINDS):
        if len(chosen) >= len(plan.kinds):
            break
        t = try_kind(kind)
        if t is not None:
            chosen.append(t)
            rec["substituted"].append(kind)
    return chosen, rec


# ----------------------------------------------------------------------------- build
@dataclass
class SimRun:
    """A simulated run: the downlink, the full simulation record (JSON-able), the scene and the plan."""

    plan: RunPlan
    downlink: Downlink
    record: dict
    scene: Scene = field(repr=False)
    products: list = field(repr=False, default_factory=list)  # list[ProductPlan]
    targets: list = field(repr=False, default_factory=list)  # list[Target]


def _pose_dict(T: RigidTransform) -> dict:
    return {"position_m": T.t.tolist(), "orientation_wxyz": T.quat_wxyz.tolist()}


def plan_products(plan: RunPlan, scene: Scene, calibrated: RoverConfig, errors: ErrorSettings):
    """Geometry of every image of a run: poses, pointing, calibrated and true models. Returns (products, record)."""
    true_cfg = true_rover_config(calibrated, errors)
    aim_site = scene.target_rock.aim_point_site()
    wheels = None if plan.rover is None else plan.rover.wheels_xy_m
    T_true = [place_on_terrain(scene, s, calibrated, true_cfg, aim_site, wheels_xy_m=wheels) for s in plan.stops]
    for k in range(1, len(plan.stops)):  # the drive between the placed stops
        s1 = plan.stops[k]
        s1.path_length_m = float(np.linalg.norm(T_true[k].t[:2] - T_true[k - 1].t[:2])) * (1.05 if s1.arc_leg else 1.0)
    r_odo = _rng(plan.seed, plan.scenario, plan.run, "odometry")
    T_est, odo_rec = estimate_poses(T_true, [s.path_length_m for s in plan.stops], [s.turn_rad for s in plan.stops], errors, r_odo)
    r_point = _rng(plan.seed, plan.scenario, plan.run, "pointing")
    r_vib = _rng(plan.seed, plan.scenario, plan.run, "vibration")
    head = np.asarray(calibrated.mast.tilt.origin_m)
    products, stops_rec = [], []
    t = 1000.0
    cum = 0.0
    for k, (s, Tt, Te) in enumerate(zip(plan.stops, T_true, T_est)):
        t += s.path_length_m / DRIVE_SPEED_M_S + abs(s.turn_rad) / TURN_RATE_RAD_S + (SETTLE_S if k else 0.0)
        cum += s.path_length_m
        aim_rover = Tt.inverse().apply(aim_site)
        srec = {"label": s.label, "drive": k, "true_pose": _pose_dict(Tt), "estimated_pose": _pose_dict(Te),
                "position_error_m": float(np.linalg.norm(Te.t - Tt.t)),
                "yaw_error_rad": float(_wrap(np.arctan2(Te.R[1, 0], Te.R[0, 0]) - np.arctan2(Tt.R[1, 0], Tt.R[0, 0]))),
                "path_length_m": s.path_length_m, "cumulative_path_m": cum, "pairs": []}
        for cam in s.cameras:
            stereo = calibrated.cameras[cam]
            pan = tilt = None
            if stereo.mount == "mast":
                rng_err = np.linalg.norm(aim_rover - head) * errors.pointing_noise_frac
                goal = aim_rover + (r_point.normal(0, rng_err, size=3) if rng_err > 0 else 0.0)
                pan, tilt = calibrated.point_at(cam, goal)
                vib_max = errors.vibration_max_rad
            else:
                vib_max = errors.vibration_body_max_rad
            T_vib, rv = vibration(r_vib, vib_max, head if stereo.mount == "mast" else calibrated.cameras[cam].left.model.C)
            prec = {"camera": cam, "pan_rad": pan, "tilt_rad": tilt, "vibration_rotvec_rad": rv.tolist()}
            for eye in ("left", "right"):
                spec = calibrated.spec(cam, eye)
                m_cal = calibrated.camera_model(cam, eye, pan or 0.0, tilt or 0.0)
                m_true = true_cfg.camera_model(cam, eye, pan or 0.0, tilt or 0.0)
                if eye == "right":
                    m_true = m_true.transformed(T_vib)
                pid = f"{plan.run}-{s.label}-{cam}-{eye[0].upper()}"
                products.append(ProductPlan(pid, s.label, k, cam, eye, round(t, 3), pan, tilt, m_cal, m_true, Tt, Te,
                                            spec.width, spec.height, rv.tolist() if eye == "right" else None, cum))
                t += STEREO_GAP_S if eye == "left" else 0.0
            t += PAIR_GAP_S
            srec["pairs"].append(prec)
        stops_rec.append(srec)
    rec = {"odometry": odo_rec, "stops": stops_rec,
           "mast_true": {"tilt_axis": true_cfg.mast.tilt.axis.tolist(), "tilt_origin_m": true_cfg.mast.tilt.origin_m.tolist()}}
    return products, rec


def compute_marks(scene: Scene, products: list, targets: list) -> list[TargetMarks]:
    """Exact marks of every target in every product that sees it (``sigma_px`` 0)."""
    out = []
    X = np.array([t.xyz_site_m for t in targets]).reshape(-1, 3)
    vis_all = []
    for p in products:
        T_rover_site = p.T_true.inverse()
        uv = p.model_true.project(T_rover_site.apply(X))  # true model, true rover frame: the definition of a mark
        _, vis = project_visible(scene, p.model_true_site, p.width, p.height, X)
        vis_all.append((p.product_id, uv, vis))
    for j, t in enumerate(targets):
        marks = [Mark(pid, float(uv[j, 0]), float(uv[j, 1]), 0.0) for pid, uv, vis in vis_all if vis[j]]
        out.append(TargetMarks(t.id, t.kind, t.description, marks))
    return out


def estimated_pose(T_est: RigidTransform, cumulative_path_m: float, n_legs: int, errors: ErrorSettings) -> RoverPose:
    """The product pose: the odometry estimate with the rover's own 1-sigma claims (None when exact).

    ``sigma_position_m = 5 mm + sqrt(scale^2 + leg^2) L + drift L^2 / 2`` (distance error, and the lateral
    error a heading drift builds up), ``sigma_yaw_rad = 0.1 deg + drift L + noise sqrt(legs)``, L = path driven.
    """
    if errors.odometry_is_exact:
        return RoverPose(T_est, "truth")
    L = float(cumulative_path_m)
    sp = 0.005 + np.hypot(errors.odometry_scale_sigma, errors.odometry_scale_leg_sigma) * L \
        + 0.5 * errors.heading_drift_sigma_rad_per_m * L * L
    sy = 0.1 * DEG + errors.heading_drift_sigma_rad_per_m * L + errors.heading_noise_sigma_rad * np.sqrt(n_legs)
    return RoverPose(T_est, "wheel_odometry", float(sp), float(sy))


def build_run(scenario: str, run: str, seed: int, errors: Optional[ErrorSettings] = None, image_scale: float = 1.0,
              supersample: int = 2, render: bool = True, bits: Optional[dict] = None,
              progress: Optional[Callable[[int, int, str], None]] = None,
              rover: Optional[rover_mod.SimRover] = None, texture=None) -> SimRun:
    """Simulate one run into an in-memory :class:`~scipctl.model.Downlink` with truth.

    ``errors`` defaults to :func:`default_errors` (all errors on); ``image_scale`` resamples every camera
    (e.g. 0.125: 1024 -> 128 px for the default rover; it must give whole sizes for every camera of the rover);
    ``render=False`` skips the pixels (black images, still exact marks and truth); ``bits`` maps camera -> 8 or 12;
    ``progress(done, total, product_id)`` is called per image. ``rover``: a :class:`~scipctl.sim.rover.SimRover`
    (None: the default ``rocky8-sim``; e.g. ``commands.synth.m2020_sim_rover(folder)``); ``texture``: a
    :class:`~scipctl.sim.texture.TextureSources` draped on the terrain (None: procedural albedo). The record gains
    ``rover`` / ``texture`` entries only when they are not the defaults.
    """
    from ..io.images import encode_png
    from .render import Sensor, auto_exposure, expose, render_radiance

    errors = default_errors(scenario) if errors is None else errors
    plan = plan_run(scenario, run, seed, rover)
    scene = scene_for(plan, texture)
    calibrated = rover_mod.default_rover_config() if rover is None else rover.config
    if image_scale != 1.0:
        calibrated = rover_mod.scale_rover_config(calibrated, image_scale)
    products, geo_rec = plan_products(plan, scene, calibrated, errors)
    targets, tgt_rec = choose_targets(scene, plan, products, _rng(seed, scenario, run, "targets"))
    marks = compute_marks(scene, products, targets)
    bits = dict(DEFAULT_BITS, **(bits or {}))

    images, truths, img_rec = [], [], []
    exposure_of = {}
    total = len(products)
    for i, p in enumerate(products):
        sensor = Sensor(bits=bits.get(p.camera, 8))
        washed = errors.is_washed_out(run, p.stop, p.camera)
        resp = errors.responsivity_of(p.camera, p.eye)
        if render:
            rad = render_radiance(scene, p.model_true_site, p.width, p.height, supersample)
            key = (p.stop, p.camera)
            if p.eye == "left" or key not in exposure_of:
                exposure_of[key] = auto_exposure(rad, sensor) * (errors.washed_out_factor if washed else 1.0)
            exposure = exposure_of[key]
            rng = _rng(seed, scenario, run, "sensor", p.product_id) if errors.sensor_noise else None
            px = expose(rad, exposure, resp, sensor, rng)
        else:
            exposure = 1.0
            px = np.zeros((p.height, p.width), np.uint8 if sensor.bits == 8 else np.uint16)
        png = encode_png(px)
        exposure_ms = round(exposure * EXPOSURE_MS_PER_UNIT.get(p.camera, 25.0), 3)
        mast = MastAngles(p.pan_rad, p.tilt_rad) if p.pan_rad is not None else None
        est = estimated_pose(p.T_est, p.cumulative_path_m, p.stop_index, errors)
        images.append(ImageProduct(p.product_id, p.camera, p.eye, float(p.time_s), 1, p.stop_index, est, p.model_cal,
                                   p.width, p.height, png, mast=mast, exposure_ms=exposure_ms, gain=1.0))
        truths.append(ImageTruth(p.product_id, RoverPose(p.T_true, "truth"), p.model_true))
        img_rec.append({"product_id": p.product_id, "exposure_ms": exposure_ms, "responsivity": resp, "washed_out": washed,
                        "bits": sensor.bits, "vibration_rotvec_rad": p.vibration_rotvec})
        if progress is not None:
            progress(i + 1, total, p.product_id)

    dl = Downlink(MISSION, plan.sol, calibrated, images, marks, truths,
                  [TargetTruth(t.id, np.array(t.xyz_site_m, float)) for t in targets])
    record = {
        "scenario": scenario, "run": run, "seed": int(seed), "scene_index": plan.scene_index, "scene_seed": plan.scene_seed,
        "image_scale": image_scale, "supersample": supersample, "rendered": render,
        "errors": errors.to_dict(), "bearing_rad": plan.bearing_rad, "sun_dir_site": scene.sun_dir_site.tolist(),
        "target_rock": {"size_m": scene.target_rock.size_m.tolist(), "aim_point_site_m": scene.target_rock.aim_point_site().tolist()},
        "targets": [{"id": t.id, "kind": t.kind, "xyz_site_m": t.xyz_site_m.tolist(),
                     "n_marks": len(m.marks)} for t, m in zip(targets, marks)],
        "target_selection": tgt_rec, "images": img_rec, **geo_rec,
    }
    if rover is not None and not rover.is_default:
        record["rover"] = rover.to_record()
    if texture is not None:
        record["texture"] = dict(texture.to_record(), **scene.appearance.texture.to_record())
    return SimRun(plan, dl, record, scene, products, targets)
