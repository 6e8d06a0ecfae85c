"""The images of a run before rendering: poses, pointing, calibrated and true camera models, times (pure numerics).

:func:`plan_products` places every stop on the terrain (:mod:`.placement`), draws the odometry
estimate, points the mast at the target rock, and lists a :class:`ProductPlan` per image;
:func:`estimated_pose` is the pose a product carries (the estimate with the rover's own sigmas).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Optional

import numpy as np

from ..core.camera import CameraModel
from ..core.kinematics import RoverConfig, RoverPose
from ..core.transforms import RigidTransform
from .errors import DEG, ErrorSettings, estimate_poses, true_rover_config, vibration
from .placement import place_on_terrain
from .scenarios import RunPlan, _rng, _wrap
from .scene import Scene

DRIVE_SPEED_M_S = 0.05
TURN_RATE_RAD_S = 0.05
SETTLE_S = 20.0
STEREO_GAP_S = 1.5
PAIR_GAP_S = 10.0


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
    T_site_rover_true: RigidTransform
    T_site_rover_est: RigidTransform  # the odometry estimate
    width: int
    height: int
    vibration_rotvec: Optional[list] = None
    cumulative_path_m: float = 0.0  # driven since the first stop

    @property
    def model_true_site(self) -> CameraModel:
        return self.model_true.transformed(self.T_site_rover_true)


def _pose_dict(T_site_rover: RigidTransform) -> dict:
    return {"position_m": T_site_rover.t.tolist(), "orientation_wxyz": T_site_rover.quat_wxyz.tolist()}


def plan_products(plan: RunPlan, scene: Scene, calibrated: RoverConfig, errors: ErrorSettings, error_draw: int = 0):
    """Geometry of every image of a run: poses, pointing, calibrated and true models. Returns (products, record).

    ``error_draw``: 0 draws the random errors from the run's own streams; ``N > 0`` draws those of every stop after
    the first (the drive's odometry, the mast's pointing noise and vibration) from other streams, keyed by ``N``,
    so the first stop (today's images) is the same and tomorrow's errors are a new draw (:func:`error_stream`)."""
    true_cfg = true_rover_config(calibrated, errors)
    aim_site = scene.target_rock.aim_point_site()
    wheels = None if plan.rover is None else plan.rover.wheels_xy_m
    T_site_rover_true_by_stop = [place_on_terrain(scene, s, calibrated, true_cfg, aim_site, wheels_xy_m=wheels)
                                 for s in plan.stops]
    for k in range(1, len(plan.stops)):  # the drive between the placed stops
        s1 = plan.stops[k]
        s1.path_length_m = float(np.linalg.norm(T_site_rover_true_by_stop[k].t[:2] - T_site_rover_true_by_stop[k - 1].t[:2])) \
            * (1.05 if s1.arc_leg else 1.0)
    r_odo = error_stream(plan, "odometry", True, error_draw)  # the first pose is exact: the stream serves the drive only
    T_site_rover_est_by_stop, odo_rec = estimate_poses(T_site_rover_true_by_stop, [s.path_length_m for s in plan.stops],
                                                       [s.turn_rad for s in plan.stops], errors, r_odo)
    # stop after stop from one stream each; with a new draw, the stops after the first from another
    r_point_today = error_stream(plan, "pointing", False)
    r_vib_today = error_stream(plan, "vibration", False)
    r_point_later = r_point_today if error_draw == 0 else error_stream(plan, "pointing", True, error_draw)
    r_vib_later = r_vib_today if error_draw == 0 else error_stream(plan, "vibration", True, error_draw)
    head = np.asarray(calibrated.mast.tilt.origin_m)
    products, stops_rec = [], []
    t = 1000.0
    cum = 0.0
    stops_and_poses = zip(plan.stops, T_site_rover_true_by_stop, T_site_rover_est_by_stop)
    for k, (s, T_site_rover_true, T_site_rover_est) in enumerate(stops_and_poses):
        t += s.path_length_m / DRIVE_SPEED_M_S + abs(s.turn_rad) / TURN_RATE_RAD_S + (SETTLE_S if k else 0.0)
        cum += s.path_length_m
        aim_rover = T_site_rover_true.inverse().apply(aim_site)
        r_point, r_vib = (r_point_today, r_vib_today) if k == 0 else (r_point_later, r_vib_later)
        srec = {"label": s.label, "drive": k,
                "true_pose": _pose_dict(T_site_rover_true), "estimated_pose": _pose_dict(T_site_rover_est),
                "position_error_m": float(np.linalg.norm(T_site_rover_est.t - T_site_rover_true.t)),
                "yaw_error_rad": float(_wrap(np.arctan2(T_site_rover_est.R[1, 0], T_site_rover_est.R[0, 0])
                                             - np.arctan2(T_site_rover_true.R[1, 0], T_site_rover_true.R[0, 0]))),
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
            pivot = head if stereo.mount == "mast" else calibrated.cameras[cam].left.model.C
            T_vibrated_nominal, rv = vibration(r_vib, vib_max, pivot)
            prec = {"camera": cam, "pan_rad": pan, "tilt_rad": tilt, "vibration_rotvec_rad": rv.tolist()}
            for eye in ("left", "right"):
                spec = calibrated.spec(cam, eye)
                m_cal = calibrated.camera_model(cam, eye, pan or 0.0, tilt or 0.0)
                m_true = true_cfg.camera_model(cam, eye, pan or 0.0, tilt or 0.0)
                if eye == "right":
                    m_true = m_true.transformed(T_vibrated_nominal)
                pid = f"{plan.run}-{s.label}-{cam}-{eye[0].upper()}"
                products.append(ProductPlan(pid, s.label, k, cam, eye, round(t, 3), pan, tilt, m_cal, m_true,
                                            T_site_rover_true, T_site_rover_est,
                                            spec.width, spec.height, rv.tolist() if eye == "right" else None, cum))
                t += STEREO_GAP_S if eye == "left" else 0.0
            t += PAIR_GAP_S
            srec["pairs"].append(prec)
        stops_rec.append(srec)
    rec = {"odometry": odo_rec, "stops": stops_rec,
           "mast_true": {"tilt_axis": true_cfg.mast.tilt.axis.tolist(), "tilt_origin_m": true_cfg.mast.tilt.origin_m.tolist()}}
    return products, rec


def check_error_draw(error_draw) -> int:
    """``error_draw`` as an int; ``ValueError`` unless it is a whole number >= 0 (not a bool)."""
    if isinstance(error_draw, bool) or not isinstance(error_draw, (int, np.integer)) or error_draw < 0:
        raise ValueError(f"error_draw: want an integer >= 0, got {error_draw!r}")
    return int(error_draw)


def error_stream(plan: RunPlan, name: str, later: bool, error_draw: int = 0, *extra) -> np.random.Generator:
    """A new generator of the random error ``name`` (``"odometry"``, ``"pointing"``, ``"vibration"``; ``"sensor"``
    with the product id in ``extra``) of ``plan``'s run: the run's own stream, or for a stop after the first
    (``later``) of draw ``error_draw > 0`` a stream keyed by the draw as well."""
    error_draw = check_error_draw(error_draw)
    key = (plan.seed, plan.scenario, plan.run, name) + tuple(extra)
    if later and error_draw > 0:
        key = key + ("draw", error_draw)
    return _rng(*key)


def estimated_pose(T_site_rover_est: RigidTransform, cumulative_path_m: float, n_legs: int,
                   errors: ErrorSettings) -> RoverPose:
    """The product pose: the odometry estimate with the rover's own 1-sigma claims (None when exact).

    ``sigma_position_m = 5 mm + sqrt(scale^2 + leg^2) L + drift L^2 / 2`` (distance error, and the lateral
    error a heading drift builds up), ``sigma_yaw_rad = 0.1 deg + drift L + noise sqrt(legs)``, L = path driven.
    """
    if errors.odometry_is_exact:
        return RoverPose(T_site_rover_est, "truth")
    L = float(cumulative_path_m)
    sp = 0.005 + np.hypot(errors.odometry_scale_sigma, errors.odometry_scale_leg_sigma) * L \
        + 0.5 * errors.heading_drift_sigma_rad_per_m * L * L
    sy = 0.1 * DEG + errors.heading_drift_sigma_rad_per_m * L + errors.heading_noise_sigma_rad * np.sqrt(n_legs)
    return RoverPose(T_site_rover_est, "wheel_odometry", float(sp), float(sy))
