"""Monte Carlo over the pose-estimate error of a planned approach: P(in field of view), P(inside the
tracker's search region), P(not occluded) per view, P(in the arm workspace) at the final pose."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Optional

import numpy as np

from ...core.kinematics import RoverConfig
from ...core.transforms import RigidTransform
from .arm_margin import stereo_range_sigma_m
from .params import UncertaintyParams
from .planning import ApproachPlan
from .terrain import Terrain


@dataclass
class McView:
    stop: int
    camera: str
    p_in_fov: float
    p_in_search: float
    p_visible: float  # not occluded
    p_ok: float  # all three
    p_chain: float  # this and every earlier view ok
    # 90th percentile of the pointing offset over the samples that see the target (see pointing_offset_p90)
    offset_px_p90: float

    def to_dict(self) -> dict:
        return dict(self.__dict__)


# how far from its pose-estimate prediction the chain's tracker finds the target: anywhere in the image (the
# feature-guided step, pipeline/feature_track.py, matches against the whole new image) or within the
# square search region of ChainParams.search_radius_px (NCC alone: the "scale" chain, or the plane chain's fallback)
TRACKER_REACHES = ("image", "search")


@dataclass
class McResult:
    n_samples: int
    sigma_position_m: float
    sigma_yaw_rad: float
    views: list  # McView
    p_arm_workspace: Optional[float]  # None: the plan ends at no placement pose (``ApproachPlan.placement``)
    p_success_geometry: float  # every view ok and (at a placement pose) the target in the arm workspace
    samples_ok: np.ndarray = field(repr=False, default=None)  # (n,) bool
    errors: dict = field(repr=False, default_factory=dict)  # per stop: (dxy (n, 2), dyaw (n,))
    # (n, 2) the true target's horizontal position (x forward, y right) in the true final rover frame: what the arm
    # workspace is checked on
    final_xy_rover_m: np.ndarray = field(repr=False, default=None)

    def to_dict(self) -> dict:
        return {"n_samples": self.n_samples, "sigma_position_m": self.sigma_position_m,
                "sigma_yaw_rad": self.sigma_yaw_rad, "views": [v.to_dict() for v in self.views],
                "p_arm_workspace": self.p_arm_workspace, "p_success_geometry": self.p_success_geometry}


def sample_pose_errors(plan: ApproachPlan, up: UncertaintyParams, sigma_position_m: float, sigma_yaw_rad: float,
                       rng: np.random.Generator, n: int) -> dict:
    """Per stop index: ``(dxy (n, 2), dyaw (n,))`` rover-frame error of the true pose w.r.t. the believed pose.

    A random walk: each leg adds ``N(0, sigma_leg^2)`` per axis with
    ``sigma_leg^2 = sigma_position_m^2 + (drive_error_frac * leg)^2`` and a yaw
    step with ``sigma^2 = sigma_yaw_rad^2 + (yaw_error_rad_per_m * leg)^2``.
    Stop 0 (today) has no error: the plan is made in today's estimated frame.
    """
    out = {0: (np.zeros((n, 2)), np.zeros(n))}
    dxy = np.zeros((n, 2))
    dyaw = np.zeros(n)
    for st in plan.stops[1:]:
        sp = math.hypot(sigma_position_m, up.drive_error_frac * st.leg_m)
        sy = math.hypot(sigma_yaw_rad, up.yaw_error_rad_per_m * st.leg_m)
        # the increment is expressed in the rover frame of the previous stop: rotate by the accumulated yaw
        inc = rng.standard_normal((n, 2)) * sp
        c, s = np.cos(dyaw), np.sin(dyaw)
        dxy = dxy + np.stack([c * inc[:, 0] - s * inc[:, 1], s * inc[:, 0] + c * inc[:, 1]], axis=1)
        dyaw = dyaw + rng.standard_normal(n) * sy
        out[st.index] = (dxy.copy(), dyaw.copy())
    return out


def pointing_offset_p90(uv_true, uv_pred, in_view) -> float:
    """The pointing offset a view's tracker faces: the 90th percentile (``numpy.percentile``, linear
    interpolation) of ``max(|du|, |dv|)`` between the true pixel ``uv_true`` (n, 2) and the predicted pixel
    ``uv_pred`` (n, 2) -- the same offset the square search region is judged by -- over the samples with
    ``in_view`` (n,) bool: the re-pointed true target inside the image. NaN when no sample sees the target.

    A sample whose target is behind the camera or beside it (near the image plane, where the projection runs to
    hundreds of thousands of pixels) is out of view: it counts in P(in view), not in the offset.
    """
    off = np.abs(np.asarray(uv_true, float) - np.asarray(uv_pred, float)).max(axis=-1)
    sel = np.asarray(in_view, bool) & np.isfinite(off)
    return float(np.percentile(off[sel], 90)) if sel.any() else float("nan")


def _true_pose_arrays(T_site_rover_believed: RigidTransform, dxy, dyaw):
    """R (n, 3, 3), t (n, 3) of ``T_site_rover_believed @ Exp(dxy, dyaw)``."""
    n = len(dyaw)
    c, s = np.cos(dyaw), np.sin(dyaw)
    Rz = np.zeros((n, 3, 3))
    Rz[:, 0, 0], Rz[:, 0, 1], Rz[:, 1, 0], Rz[:, 1, 1], Rz[:, 2, 2] = c, -s, s, c, 1.0
    R = T_site_rover_believed.R[None] @ Rz
    t = T_site_rover_believed.t[None] + np.c_[dxy, np.zeros(n)] @ T_site_rover_believed.R.T
    return R, t


def monte_carlo(plan: ApproachPlan, terrain: Optional[Terrain], rover_config: RoverConfig, target_true_site,
                up: UncertaintyParams, sigma_position_m: float, sigma_yaw_rad: float,
                designation_range_sigma_m: float = 0.0, occlusion_tol_m: float = 0.04,
                tracker_reach: str = "image", target_normal_site=None) -> McResult:
    """Monte Carlo over the pose-estimate error (see :func:`sample_pose_errors`).

    Per sample and stop: the rover believes it is at the planned pose; it
    points each camera at its current target estimate (the previous stop's
    stereo re-estimate, carried through the believed poses); the true target
    ``target_true_site`` (3,) lands at ``uv_true``; the estimate at
    ``uv_pred``. Pointing is the nominal one plus the re-pointing shift
    ``uv_pred - uv_nominal`` (first order in the small pointing change).
    A view is ok when the re-pointed true pixel is inside the image (margin
    ``plan.params.fov_margin``), the line of sight is not occluded by the terrain and, with
    ``tracker_reach="search"``, within the tracker's search radius of ``uv_pred`` (square region).
    ``tracker_reach="image"`` (default, :data:`TRACKER_REACHES`): the chain's feature-guided step matches the
    rendered previous view against the whole new image, so the search radius (its NCC fallback's) does not bound
    it; ``p_in_search`` is still reported. ``target_normal_site`` (3,) or None: the terrain's normal at the
    target, so that the target's own surface met at grazing incidence does not count as an occluder
    (:meth:`~.terrain.Terrain.occluded`).
    Each view reports :func:`pointing_offset_p90` over the samples that see the target.
    At the final pose the rover drives (closed loop on its estimate, the
    sequence's ``DRV_APPROACH_TARGET``) so that its estimate sits where the
    plan put the plan's target ``plan.target_site_m`` (the designated point
    the standoff was planned to); the true target must then be inside the
    arm workspace (its rover-frame position per sample: ``final_xy_rover_m``).
    ``target_true_site`` is the truth of the views, the occlusion and the
    re-estimates (the prediction passes the designation ray's point on
    today's terrain); it is not the reference of the final drive.
    """
    if tracker_reach not in TRACKER_REACHES:
        raise ValueError(f"monte_carlo: tracker_reach must be one of {TRACKER_REACHES}, got {tracker_reach!r}")
    n = int(up.n_samples)
    rng = np.random.default_rng(up.seed)
    X_T = np.asarray(target_true_site, float).reshape(3)
    errors = sample_pose_errors(plan, up, sigma_position_m, sigma_yaw_rad, rng, n)
    # designation error along today's line of sight
    start = plan.start.T_site_rover
    C0 = start.apply(rover_config.camera_model(plan.designation_camera, "left").C) if plan.designation_camera in rover_config.cameras else start.t
    los = (X_T - C0) / np.linalg.norm(X_T - C0)
    X_est = X_T[None] + rng.standard_normal(n)[:, None] * designation_range_sigma_m * los[None]  # believed site frame
    ok_all = np.ones(n, bool)
    views = []
    for st in plan.stops[1:]:
        dxy, dyaw = errors[st.index]
        R_true, t_true = _true_pose_arrays(st.T_site_rover, dxy, dyaw)
        T_rover_site_believed = st.T_site_rover.inverse()
        X_true_rover = np.einsum("nji,nj->ni", R_true, X_T[None] - t_true)  # R^T (X - t)
        last_est = None
        for sh in st.cameras:
            if sh.uv is None:
                views.append(McView(st.index, sh.camera, 0.0, 0.0, 0.0, 0.0, 0.0, float("nan")))
                ok_all[:] = False
                continue
            spec = rover_config.spec(sh.camera, "left")
            m = rover_config.camera_model(sh.camera, "left", sh.pan_rad or 0.0, sh.tilt_rad or 0.0)
            uv_pred = m.project(T_rover_site_believed.apply(X_est))
            uv_true = m.project(X_true_rover)
            uv_nom = np.asarray(sh.uv, float)
            shift = uv_pred - uv_nom
            rep = uv_true - shift
            margin = plan.params.fov_margin(sh.camera)
            fin = np.all(np.isfinite(rep), axis=1) & np.all(np.isfinite(uv_pred), axis=1)
            with np.errstate(invalid="ignore"):
                in_fov = fin & (rep[:, 0] >= margin) & (rep[:, 0] <= spec.width - 1 - margin) & \
                    (rep[:, 1] >= margin) & (rep[:, 1] <= spec.height - 1 - margin)
                off = np.abs(uv_true - uv_pred).max(axis=1)
                in_search = fin & (off <= sh.search_radius_px)
            C_true = np.einsum("nij,j->ni", R_true, m.C) + t_true
            if terrain is not None:
                vis = ~terrain.occluded(C_true, np.broadcast_to(X_T, C_true.shape), occlusion_tol_m, target_normal_site)
            else:
                vis = np.ones(n, bool)
            ok = in_fov & vis & (in_search if tracker_reach == "search" else True)
            ok_all &= ok
            views.append(McView(st.index, sh.camera, float(in_fov.mean()), float(in_search.mean()), float(vis.mean()),
                                float(ok.mean()), float(ok_all.mean()), pointing_offset_p90(uv_true, uv_pred, in_fov)))
            # stereo re-estimate from this camera: truth + range noise along its line of sight, into the believed frame
            sig_r = stereo_range_sigma_m(rover_config, sh.camera, float(sh.range_m or 0.0), up.disparity_sigma_px)
            los_t = X_T[None] - C_true
            los_t /= np.linalg.norm(los_t, axis=1, keepdims=True)
            X_meas_true = X_T[None] + rng.standard_normal(n)[:, None] * sig_r * los_t
            X_meas_rover = np.einsum("nji,nj->ni", R_true, X_meas_true - t_true)
            last_est = st.T_site_rover.apply(X_meas_rover)
        if last_est is not None:
            X_est = last_est
    if not plan.placement:  # the route ends at an imaging stop: no final drive, no arm check
        return McResult(n, float(sigma_position_m), float(sigma_yaw_rad), views, None, float(ok_all.mean()),
                        ok_all, errors, None)
    # final pose: the rover drives its estimate to where the plan put its target; truth relative to the true final pose
    fin_st = plan.stops[-1]
    dxy, dyaw = errors[fin_st.index]
    R_true, t_true = _true_pose_arrays(fin_st.T_site_rover, dxy, dyaw)
    # the believed final pose is shifted so that the estimate lands where the plan's target (the designated point
    # the standoff was planned to, as the flight rules check it) sits in the planned final rover frame -- not the
    # truth X_T: the rover knows only its estimate and the plan (issue #15: X_T 0.12 m beyond the designated point
    # put every sample 0.12 m beyond the planned standoff)
    est_rover = fin_st.T_site_rover.inverse().apply(X_est)
    planned_rover = fin_st.T_site_rover.inverse().apply(np.asarray(plan.target_site_m, float).reshape(3))
    corr = est_rover - planned_rover[None]  # the rover moves by this (its own frame) to put the estimate there
    # the correction is commanded in the rover's body frame, so in truth it moves along its TRUE final heading
    # (R_true, per sample), not the believed one: the planned rotation added ~ dyaw x |corr| of spurious error
    # (issue #15). With the estimate re-measured at this stop, X_final = planned_rover - (its stereo error)
    t_true = t_true + np.einsum("nij,nj->ni", R_true, corr)
    X_final = np.einsum("nji,nj->ni", R_true, X_T[None] - t_true)
    in_arm = plan.params.arm.contains(X_final[:, :2])
    p_arm = float(in_arm.mean())
    ok_all &= in_arm
    return McResult(n, float(sigma_position_m), float(sigma_yaw_rad), views, p_arm, float(ok_all.mean()),
                    ok_all, errors, X_final[:, :2].copy())
