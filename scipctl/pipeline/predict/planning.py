"""Approach planning: the stop schedule (:func:`stop_distances`), the path and its detours around rocks
(:func:`plan_approach`), each stop's pose on the terrain and the planned camera shots (site frame)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Optional

import numpy as np

from ...core.camera import CameraModel
from ...core.kinematics import RoverConfig, RoverPose
from ...core.transforms import RigidTransform
# the planned shots carry the on-board chain's window sizes
from ..chain import ChainParams
from .geometry import _wrap, pose_on_plane, tilt_of, yaw_of
from .approach_search import ApproachSearch
from .arm_margin import ArmMargin, arm_margin
from .params import ApproachParams, RoverBody, UncertaintyParams
from .terrain import Terrain


@dataclass
class CameraShot:
    """One camera's acquisition at a stop, as planned (nominal: no pose error)."""

    camera: str
    pan_rad: Optional[float]
    tilt_rad: Optional[float]
    uv: Optional[list]  # predicted left-image pixel of the target
    range_m: Optional[float]
    in_fov: bool
    incidence_rad: Optional[float] = None
    occluded: Optional[bool] = None
    texture_std: Optional[float] = None
    coverage: Optional[float] = None
    template_half_px: int = ChainParams.other_template_half_px
    search_radius_px: float = float(ChainParams.other_search_radius_px)
    note: str = ""

    def to_dict(self) -> dict:
        return dict(self.__dict__)


@dataclass
class PlannedStop:
    index: int
    kind: str  # start | pancam | pancam-navcam-handoff | navcam | navcam-hazcam-handoff | hazcam | final
    distance_m: float  # horizontal, rover origin -> target
    T_site_rover: RigidTransform
    heading_rad: float
    leg_m: float  # path length driven from the previous stop
    turn_rad: float  # turn in place before imaging (the turn to face the target, or at a waypoint)
    cameras: list = field(default_factory=list)  # CameraShot
    tilt_rad: float = 0.0
    terrain_known: bool = True
    path_from_previous: list = field(default_factory=list)  # [(x, y), ...] site frame, incl. both ends

    @property
    def position_m(self) -> np.ndarray:
        return self.T_site_rover.t

    def to_dict(self) -> dict:
        return {
            "index": self.index, "kind": self.kind, "distance_m": self.distance_m,
            "position_site_m": self.T_site_rover.t.tolist(), "orientation_wxyz": self.T_site_rover.quat_wxyz.tolist(),
            "heading_rad": self.heading_rad, "leg_m": self.leg_m, "turn_rad": self.turn_rad,
            "tilt_rad": self.tilt_rad, "terrain_known": self.terrain_known,
            "cameras": [c.to_dict() for c in self.cameras],
        }


@dataclass
class ApproachPlan:
    target_site_m: np.ndarray  # (3,)
    start: RoverPose
    bearing_rad: float  # final approach heading
    detour_rad: float  # bearing minus the direct bearing
    stops: list  # PlannedStop, stops[0] is today's position
    path_xy: np.ndarray  # (N, 2) the whole path, site frame
    path_length_m: float
    clearance: dict  # min distances: rocks, target; blocked flag
    params: ApproachParams  # the plan's own: standoff_m is the standoff it was planned to
    designation_camera: str = "pancam"
    search: Optional[ApproachSearch] = None  # what plan_approach tried before keeping this plan
    arm_margin: Optional[ArmMargin] = None  # the final drive's error margin the search asked of this plan
    # the final stop is an arm-placement pose (the Monte Carlo checks the arm workspace there); False for a route
    # that ends at an imaging stop (:func:`~.route.route_from_downlink`)
    placement: bool = True

    @property
    def final(self) -> PlannedStop:
        return self.stops[-1]

    def to_dict(self) -> dict:
        return {
            "target_site_m": self.target_site_m.tolist(), "bearing_rad": self.bearing_rad, "detour_rad": self.detour_rad,
            "path_length_m": self.path_length_m, "clearance": self.clearance,
            "standoff_m": self.params.final_distance_m,
            "search": None if self.search is None else self.search.to_dict(),
            "arm_margin": None if self.arm_margin is None else self.arm_margin.to_dict(),
            "placement": self.placement, "stops": [s.to_dict() for s in self.stops],
        }


def stop_distances(start_m: float, p: ApproachParams, designation_camera: str = "pancam") -> list:
    """Planned stop distances (m, decreasing, last = the final standoff) and their kinds.

    Special stops at ``pancam_handoff_m`` (when starting beyond it with
    pancams), ``hazcam_handoff_m``, ``hazcam_stops_m`` and the final standoff;
    above the navcam->hazcam handoff, regular stops every ``stop_fraction`` of
    the remaining distance (at least ``min_leg_m``) from the previous stop; a
    regular stop that would fall within ``merge_m`` of the next special stop
    is replaced by it.
    """
    d_final = p.final_distance_m
    if not start_m > d_final:
        return []
    specials = {}
    if designation_camera == "pancam" and start_m > p.pancam_handoff_m + p.merge_m:
        specials[p.pancam_handoff_m] = "pancam-navcam-handoff"
    if start_m > p.hazcam_handoff_m + p.merge_m:
        specials[p.hazcam_handoff_m] = "navcam-hazcam-handoff"
    for d in p.hazcam_stops_m:
        if d_final + p.merge_m < d < min(start_m, p.hazcam_handoff_m) - p.merge_m:
            specials[float(d)] = "hazcam"
    specials[d_final] = "final"
    out = []
    d = start_m
    while d > d_final:
        below = [x for x in specials if x < d - 1e-9]
        s_next = max(below)
        cand = d - max(p.stop_fraction * d, p.min_leg_m)
        if d <= p.hazcam_handoff_m + 1e-9 or cand <= s_next + p.merge_m:
            d = s_next
            out.append((float(d), specials[d]))
        else:
            d = cand
            kind = "pancam" if (designation_camera == "pancam" and d > p.pancam_handoff_m) else "navcam"
            out.append((float(d), kind))
    # a start already inside the pancam->navcam handoff distance hands off at the first stop
    if designation_camera == "pancam" and start_m <= p.pancam_handoff_m + p.merge_m and out:
        if out[0][1] == "navcam":
            out[0] = (out[0][0], "pancam-navcam-handoff")
    return out


def _cameras_for(kind: str) -> list:
    return {
        "pancam": ["pancam"], "pancam-navcam-handoff": ["pancam", "navcam"], "navcam": ["navcam"],
        "navcam-hazcam-handoff": ["navcam", "hazcam"], "hazcam": ["hazcam"], "final": ["hazcam"],
    }[kind]


def _point_on_polyline_at_distance(poly: np.ndarray, target_xy_site: np.ndarray, dist: float, s_from: float = 0.0):
    """First point (arc length s >= s_from) of the polyline ``poly`` (N, 2) at horizontal ``dist`` from
    ``target_xy_site``.

    Returns ``(point (2,), s, segment index)`` or None.
    """
    s0 = 0.0
    for i in range(len(poly) - 1):
        a, b = poly[i], poly[i + 1]
        L = float(np.linalg.norm(b - a))
        if L < 1e-12:
            continue
        u = (b - a) / L
        # |a + t u - target_xy_site|^2 = dist^2
        w = a - target_xy_site
        bq = 2 * np.dot(u, w)
        cq = np.dot(w, w) - dist * dist
        disc = bq * bq - 4 * cq
        if disc >= 0:
            for t in sorted(((-bq - math.sqrt(disc)) / 2, (-bq + math.sqrt(disc)) / 2)):
                if -1e-9 <= t <= L + 1e-9 and s0 + t >= s_from - 1e-9:
                    return a + t * u, s0 + t, i
        s0 += L
    return None


def _sample_path_poses(poly: np.ndarray, step_m: float) -> tuple:
    """Points (N, 2) and headings (N,) every ``step_m`` along a polyline (segments' own headings)."""
    pts, yaws = [], []
    for i in range(len(poly) - 1):
        a, b = poly[i], poly[i + 1]
        L = float(np.linalg.norm(b - a))
        if L < 1e-9:
            continue
        yaw = math.atan2(b[1] - a[1], b[0] - a[0])
        n = max(1, int(math.ceil(L / step_m)))
        for t in np.linspace(0.0, 1.0, n + 1):
            pts.append(a + t * (b - a))
            yaws.append(yaw)
    return np.array(pts).reshape(-1, 2), np.array(yaws)


def _turn_samples(xy, yaw_from, yaw_to, step_rad):
    d = float(_wrap(yaw_to - yaw_from))
    n = max(1, int(math.ceil(abs(d) / step_rad)))
    return [(np.asarray(xy, float), yaw_from + d * k / n) for k in range(n + 1)]


def clearance_of(poses_xy_yaw: list, rocks_xy: np.ndarray, target_xy: np.ndarray, body: RoverBody) -> dict:
    """Minimum footprint distances (m) to the rock cells and to the target over ``[(xy (2,), yaw), ...]``.

    Returns ``{min_rock_m, min_target_m, worst_rock_xy}`` (inf when there are no rocks).
    """
    min_rock, worst = np.inf, None
    min_tgt = np.inf
    R = np.asarray(rocks_xy, float).reshape(-1, 2)
    target_xy_site = np.asarray(target_xy, float).reshape(2)
    for xy, yaw in poses_xy_yaw:
        c, s = math.cos(yaw), math.sin(yaw)
        rot = np.array([[c, s], [-s, c]])  # site -> rover (2-D)
        if len(R):
            # only cells that can matter (within 2 m)
            near = np.abs(R - xy).max(axis=1) < 2.0
            if np.any(near):
                loc = (R[near] - xy) @ rot.T
                d = body.distance(loc)
                k = int(np.argmin(d))
                if d[k] < min_rock:
                    min_rock, worst = float(d[k]), R[near][k].tolist()
        dt = float(body.distance(((target_xy_site - xy) @ rot.T)[None])[0])
        min_tgt = min(min_tgt, dt)
    return {"min_rock_m": float(min_rock), "min_target_m": float(min_tgt), "worst_rock_xy": worst}


def standoff_candidates(p: ApproachParams) -> list:
    """Final standoffs (m) the planner may use, in order of preference.

    A standoff pinned by the operator (``standoff_m``) is the only one. Otherwise
    the arm workspace's centre first, then every ``standoff_step_m`` inside
    ``[r_min_m, r_max_m]`` by distance from the centre (the farther first on a
    tie: more room between the footprint and the target's rock).
    """
    if p.standoff_m is not None:
        return [float(p.standoff_m)]
    a, c = p.arm, p.arm.centre_m
    n = int(math.floor((a.r_max_m - a.r_min_m) / (2 * p.standoff_step_m) + 1e-9))
    out = [c]
    for k in range(1, n + 1):
        out += [c + k * p.standoff_step_m, c - k * p.standoff_step_m]
    return [round(float(x), 9) for x in out if a.r_min_m - 1e-9 <= x <= a.r_max_m + 1e-9]


def arm_room_m(arm, xy_rover) -> float:
    """How far (m) the horizontal rover-frame point ``xy_rover`` (2,) lies inside the arm workspace's radial limits
    (negative: outside)."""
    r = float(np.hypot(xy_rover[0], xy_rover[1]))
    return min(r - arm.r_min_m, arm.r_max_m - r)


def plan_approach(start: RoverPose, target_site_m, terrain: Optional[Terrain], rover_config: RoverConfig,
                  params: Optional[ApproachParams] = None, designation_camera: str = "pancam",
                  chain_params: Optional[ChainParams] = None,
                  uncertainty: Optional[UncertaintyParams] = None) -> ApproachPlan:
    """Plan the stops from ``start`` to the final pose in front of ``target_site_m`` (3,) (site frame).

    Searches (approach bearing, final standoff): the bearings in the order of
    ``detour_bearings_rad`` (the direct one first) and, for each, the standoffs
    of :func:`standoff_candidates` (inside the arm workspace, so that the
    target stays reachable), and keeps the first plan whose swept footprint
    clears the rocks (``rock_keep_out_m``) and the target
    (``target_keep_out_m``) and whose final pose sees the target in the
    hazcams. With ``uncertainty`` (the Monte Carlo's error model) and a
    searched standoff, the plan kept must also leave the designated point
    ``params.arm_margin_sigmas`` sigmas of the final drive's error inside the
    arm workspace's radial limits (:func:`~.arm_margin.arm_margin`); every
    bearing is searched for one before the first plan that clears only the
    constraints above (the workspace's edge) is kept, and ``plan.search``
    names what the candidates with the margin broke. If none clears, the plan closest to clearing them (largest worst
    margin) is returned with its failing clearance figures. ``clearance["search"]``
    ``plan.search`` records what was tried and, for a blocked plan, which constraint bound
    (:class:`~.approach_search.ApproachSearch`). Without a ``terrain`` the ground is taken as the
    start pose's plane and no rocks are known. ``params`` is checked; each
    planned shot carries the window size and search radius of
    ``chain_params`` (the on-board chain's, default
    :class:`~scipctl.pipeline.chain.ChainParams`).
    """
    p = (params or ApproachParams()).check()
    chain_params = chain_params or ChainParams()
    X_target_site = np.asarray(target_site_m, float).reshape(3)
    S = start.T_site_rover.t[:2]
    d_start = float(np.linalg.norm(X_target_site[:2] - S))
    direct = math.atan2(X_target_site[1] - S[1], X_target_site[0] - S[0])
    rocks = (terrain.rock_cells(p.rock_cell_m, p.ground_window_m, p.rock_height_m)
             if terrain is not None else np.zeros((0, 2)))
    search = ApproachSearch(rock_keep_out_m=p.rock_keep_out_m, target_keep_out_m=p.target_keep_out_m)
    best, best_margin = None, -np.inf
    chosen = first_clear = None
    want_margin = uncertainty is not None and p.standoff_m is None and p.arm_margin_sigmas > 0
    sp, sy = uncertainty.per_stop_sigmas() if want_margin else (0.0, 0.0)
    for db in p.detour_bearings_rad:
        if d_start <= p.pancam_handoff_m and abs(db) > 1e-9:
            continue  # too close for a detour leg
        for sd in standoff_candidates(p):
            pp = p if p.standoff_m is not None else replace(p, standoff_m=sd)
            plan = _plan_bearing(start, X_target_site, terrain, rover_config, pp, direct + db, db, rocks,
                                 designation_camera)
            fov_px = _final_hazcam_margin_px(rover_config, plan)
            X_rover = plan.final.T_site_rover.inverse().apply(X_target_site)
            if want_margin:
                plan.arm_margin = arm_margin([st.leg_m for st in plan.stops[1:]], X_rover, rover_config,
                                             uncertainty, p.arm_margin_sigmas, sp, sy)
            search.add(math.degrees(db), sd, plan.clearance, fov_px, p.fov_margin("hazcam"),
                       arm_room_m(p.arm, X_rover[:2]), None if plan.arm_margin is None else plan.arm_margin.margin_m)
            margin = min(plan.clearance["min_rock_m"] - p.rock_keep_out_m,
                         plan.clearance["min_target_m"] - p.target_keep_out_m,
                         (fov_px - p.fov_margin("hazcam")) / 1000.0)  # px -> a small margin: geometry first
            i = len(search.tried) - 1
            if best is None or margin > best_margin:
                best, best_margin = (plan, i), margin
            if not search.tried[-1]["bound_by"]:
                first_clear = first_clear or (plan, i)
                if not search.tried[-1]["short_of_margin"]:
                    chosen = (plan, i)
                    break
        if chosen is not None:
            break
    plan, search.kept = chosen or first_clear or best
    plan.search = search
    for st in plan.stops[1:]:
        st.cameras = [_shot(rover_config, st, c, X_target_site, plan.params, chain_params) for c in _cameras_for(st.kind)]
    return plan


def _final_hazcam_margin_px(rover_config: RoverConfig, plan: "ApproachPlan") -> float:
    """Smallest distance (px) of the target from the edges of the two hazcam images at the final pose
    (-inf when it is behind a camera or there is no hazcam)."""
    from ...core.image_margin import pair_margin_px

    X_rover = plan.final.T_site_rover.inverse().apply(np.asarray(plan.target_site_m, float))
    return float(pair_margin_px(rover_config, "hazcam", X_rover[None])[0])


def _plan_bearing(start, X_target_site, terrain, rover_config, p, bearing, detour, rocks,
                  designation_camera) -> ApproachPlan:
    """The plan along one approach bearing to the final standoff of ``p``: stops, path and clearance (no camera
    shots yet: :func:`plan_approach` adds them to the plan it keeps)."""
    S = start.T_site_rover.t[:2].copy()
    u = np.array([math.cos(bearing), math.sin(bearing)])
    d_start = float(np.linalg.norm(X_target_site[:2] - S))
    d_final = p.final_distance_m
    F = X_target_site[:2] - d_final * u
    if abs(detour) < 1e-9:
        poly = np.array([S, F])
    else:
        d_w = min(p.pancam_handoff_m, 0.8 * d_start)
        W = X_target_site[:2] - d_w * u
        poly = np.array([S, W, F])
    dists = stop_distances(d_start, p, designation_camera)
    start_plane = _plane_of(start.T_site_rover)
    stops = [PlannedStop(0, "start", d_start, start.T_site_rover, yaw_of(start.T_site_rover), 0.0, 0.0,
                         tilt_rad=tilt_of(start.T_site_rover))]
    s_prev = 0.0
    prev_xy, prev_yaw = S, yaw_of(start.T_site_rover)
    turn_poses = []
    path_pts = [S]
    for k, (dist, kind) in enumerate(dists, start=1):
        if kind == "final":
            pt, s, seg = F, _polyline_length(poly), len(poly) - 2
        else:
            r = _point_on_polyline_at_distance(poly, X_target_site[:2], dist, s_prev)
            if r is None:
                continue
            pt, s, seg = r
        seg_yaw = math.atan2(poly[seg + 1][1] - poly[seg][1], poly[seg + 1][0] - poly[seg][0])
        facing = math.atan2(X_target_site[1] - pt[1], X_target_site[0] - pt[0])
        heading = facing if kind in ("navcam-hazcam-handoff", "hazcam", "final") else seg_yaw
        # path from the previous stop: vertices of the polyline between s_prev and s
        seg_path = [prev_xy] + [poly[i] for i in range(1, len(poly) - 1) if s_prev < _arc(poly, i) < s] + [pt]
        for a, b in zip(seg_path[:-1], seg_path[1:]):
            turn_poses.extend(_turn_samples(a, prev_yaw, math.atan2(b[1] - a[1], b[0] - a[0]), p.turn_step_rad))
            prev_yaw = math.atan2(b[1] - a[1], b[0] - a[0])
        turn = float(_wrap(heading - prev_yaw))
        if abs(turn) > 1e-9:
            turn_poses.extend(_turn_samples(pt, prev_yaw, heading, p.turn_step_rad))
        guess = pose_on_plane(pt, heading, start_plane)
        plane, known = start_plane, False
        if terrain is not None:
            pl, _, _ = terrain.ground_plane(guess, p.body, p.rock_cell_m)
            if pl is not None:
                plane, known = pl, True
        T_site_rover = pose_on_plane(pt, heading, plane)
        stops.append(PlannedStop(k, kind, float(np.linalg.norm(X_target_site[:2] - pt)), T_site_rover, heading,
                                 float(s - s_prev), turn, tilt_rad=tilt_of(T_site_rover), terrain_known=known,
                                 path_from_previous=[np.asarray(q, float).tolist() for q in seg_path]))
        path_pts.extend(seg_path[1:])
        s_prev, prev_xy, prev_yaw = s, pt, heading
    for i, st in enumerate(stops):
        st.index = i
    path_xy = np.array(path_pts).reshape(-1, 2)
    pts, yaws = _sample_path_poses(path_xy, p.path_step_m)
    swept = [(pts[i], yaws[i]) for i in range(len(pts))] + turn_poses + [(stops[-1].T_site_rover.t[:2], stops[-1].heading_rad)]
    cl = clearance_of(swept, rocks, X_target_site[:2], p.body)
    cl["blocked"] = bool(cl["min_rock_m"] < p.rock_keep_out_m or cl["min_target_m"] < p.target_keep_out_m)
    cl["terrain_known_fraction"] = terrain.known_fraction_along(pts) if terrain is not None else 0.0
    cl["rock_cells"] = int(len(rocks))
    return ApproachPlan(X_target_site, start, float(bearing), float(detour), stops, path_xy, _polyline_length(path_xy), cl, p,
                        designation_camera)


def _arc(poly, i):
    return float(sum(np.linalg.norm(poly[j + 1] - poly[j]) for j in range(i)))


def _polyline_length(poly) -> float:
    poly = np.asarray(poly, float)
    return float(np.sum(np.linalg.norm(np.diff(poly, axis=0), axis=1))) if len(poly) > 1 else 0.0


def _plane_of(T_site_rover: RigidTransform):
    """The plane (a, b, c) through the rover origin perpendicular to its z axis."""
    n = T_site_rover.R[:, 2]
    p0 = T_site_rover.t
    # n . (X - p0) = 0 -> z = p0z - (nx (x - p0x) + ny (y - p0y)) / nz
    a, b = -n[0] / n[2], -n[1] / n[2]
    return a, b, p0[2] - a * p0[0] - b * p0[1]


def camera_model_at(rover_config: RoverConfig, camera: str, eye: str, pan_rad, tilt_rad,
                    T_site_rover: RigidTransform) -> CameraModel:
    """A camera's model in the SITE frame for a rover pose and joint angles (body cameras ignore the angles)."""
    return rover_config.camera_model(camera, eye, pan_rad or 0.0, tilt_rad or 0.0).transformed(T_site_rover)


def _shot(rover_config: RoverConfig, stop: PlannedStop, camera: str, target_site, params: ApproachParams,
          chain_params: ChainParams) -> CameraShot:
    Xr = stop.T_site_rover.inverse().apply(np.asarray(target_site, float))
    cam = rover_config.cameras.get(camera)
    if cam is None:
        return CameraShot(camera, None, None, None, None, False, note=f"no {camera} in the rover configuration")
    spec = cam.left
    pan = tilt = None
    note = ""
    if cam.mount == "mast":
        try:
            pan, tilt = rover_config.point_at(camera, Xr)
        except ValueError as e:
            return CameraShot(camera, None, None, None, None, False, note=f"cannot point: {e}")
    m = rover_config.camera_model(camera, "left", pan or 0.0, tilt or 0.0)
    uv = m.project(Xr[None])[0]
    rng = float(np.linalg.norm(Xr - m.C))
    margin = params.fov_margin(camera)
    ok = bool(np.all(np.isfinite(uv)) and margin <= uv[0] <= spec.width - 1 - margin
              and margin <= uv[1] <= spec.height - 1 - margin)
    return CameraShot(camera, pan, tilt, uv.tolist() if np.all(np.isfinite(uv)) else None, rng, ok,
                      template_half_px=chain_params.template_half(camera),
                      search_radius_px=float(chain_params.search_radius(camera)), note=note)
