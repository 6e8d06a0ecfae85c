"""Registration handoff method: the navcam cloud registered onto the hazcam cloud (pure numerics).

``method(case, nav_uv, params, *, near_hint=None) -> MethodResult`` (``near_hint`` unused); ``nav_uv`` (2,)
is the navcam-left pixel, the answer the hazcam-left pixel (2,).
"""

from __future__ import annotations

from typing import Optional

import numpy as np

from ..registration import select_rows, squared_distances
from ..registration_check import (CheckedRegistration, RegistrationEvidence, range_residual, registration_evidence,
                                  registration_verdict, stereo_range_sigma_m)
from .case import HandoffCase
from .params import HandoffParams
from .result import MethodResult, NoAnswer, answer, f, reg_diag
from .steps import nav_point, project_haz


def mesh_registration(case: HandoffCase, nav_uv, params: HandoffParams, *,
                      near_hint: Optional[MethodResult] = None) -> MethodResult:
    """ICP between the navcam and hazcam clouds (the case's :meth:`~HandoffCase.whole_registration`: several
    seeds — the mast kinematics for near, the pose estimate for far, each perturbed by its error model, and a
    global registration — the best-supported answer kept), then kinematic handoff of the navcam point stereo
    through the recovered transform.

    ``ok`` is the registration's verdict at the target (:func:`~scipctl.core.registration_check.registration_verdict`);
    the evidence is in ``diagnostics["registration_check"]`` (a :class:`RegistrationEvidence` as a dict)."""
    ps = nav_point(case, nav_uv)
    reg = case.whole_registration()
    if isinstance(reg, Exception):
        raise NoAnswer(f"registration failed: {reg}")
    X_nav = np.asarray(ps.xyz, float).reshape(1, 3)
    X = reg.T_target_source.apply(X_nav)
    uv = project_haz(case, X[0])
    diag = reg_diag(reg.chosen)
    diag["registration_seconds"] = f(case.registration_seconds)  # shared by the targets; maybe run meanwhile
    if not np.all(np.isfinite(uv)):
        return answer(uv, diag, ok=False)
    ev = target_evidence(case, reg, X_nav[0], uv)
    # the navcam point the answer carries, against the navcam's dense stereo at the same pixel
    Xd = case.nav.xyz_at(np.asarray(nav_uv, float)[None])[0]
    if np.all(np.isfinite(Xd)):
        Cn = case.nav.left_model.C
        r_ps, r_d = float(np.linalg.norm(X_nav[0] - Cn)), float(np.linalg.norm(Xd - Cn))
        ev.nav_range_residual_m = r_ps - r_d
        ev.nav_range_residual_sigmas = abs(r_ps - r_d) / float(stereo_range_sigma_m(
            r_d, case.nav.dense.focal_baseline_px_m, case.params.registration_check.dense_disparity_sigma_px))
    diag["registration_check"] = ev.to_dict()
    ok, reason = registration_verdict(ev, case.params.registration_check)
    res = answer(uv, diag, ok=ok)
    res.reason = reason
    return res


def target_evidence(case: HandoffCase, reg: CheckedRegistration, X_nav: np.ndarray, uv: np.ndarray
                    ) -> RegistrationEvidence:
    """:class:`RegistrationEvidence` for the navcam point ``X_nav`` (3,) (navcam rover frame) answered at the
    hazcam pixel ``uv`` (2,) by ``reg``: the registration's own evidence, then the hazcam stereo's at the
    answer."""
    ev = registration_evidence(reg, X_nav, case.haz.left_model.project, case.params.registration_check)
    _surface_residuals(case, reg, reg.T_target_source.apply(X_nav[None])[0], uv, ev)
    return ev


def _surface_residuals(case: HandoffCase, reg: CheckedRegistration, X: np.ndarray, uv: np.ndarray,
                       ev: RegistrationEvidence) -> None:
    """Fill ``ev``'s range and local-window residuals of the registered point ``X`` (3,) (hazcam rover frame)
    against the hazcam stereo."""
    p = case.params.registration_check
    haz = case.haz
    C = haz.left_model.C
    ev.answer_in_image = bool(-0.5 <= uv[0] <= haz.width - 0.5 and -0.5 <= uv[1] <= haz.height - 0.5)
    if ev.answer_in_image:
        # two measures of the hazcam surface at the answer: hazcam point stereo there, searched within
        # haz_point_stereo_range_frac of X's range (does the hazcam see a surface near X? its small affine window
        # keeps the foreground at an occluding edge, where dense stereo leaves a hole or the background), and the
        # dense stereo point whose range is nearest X's within residual_window_px, where every pixel there has one
        Cn = reg.T_target_source.apply(case.nav.left_model.C[None])[0]
        fb_h, fb_n = haz.dense.focal_baseline_px_m, case.nav.dense.focal_baseline_px_m
        Xp = _haz_point_near(case, uv, float(np.linalg.norm(X - C)))
        if Xp is not None:
            ev.range_residual_m, ev.range_residual_sigmas = range_residual(
                X, Xp, C, Cn, fb_h, fb_n, p.point_disparity_sigma_px, p.point_disparity_sigma_px)
        Xw, ev.dense_coverage = _haz_dense_window(case, uv, p.residual_window_px)
        if ev.dense_coverage == 1.0:
            Xd = Xw[int(np.argmin(np.abs(np.linalg.norm(Xw - C, axis=1) - np.linalg.norm(X - C))))]
            ev.dense_residual_m, ev.dense_residual_sigmas = range_residual(
                X, Xd, C, Cn, fb_h, fb_n, p.dense_disparity_sigma_px, p.point_disparity_sigma_px)
    nav_pts, _ = case.nav.cloud()
    M = reg.T_target_source
    Xn = M.inverse().apply(X[None])[0]
    near = select_rows(nav_pts, squared_distances(nav_pts, Xn) < p.local_radius_m ** 2)
    ev.local_points = int(len(near))
    surface = _haz_surface(case, X, 2.0 * p.local_radius_m)
    if len(near) >= p.min_local_points and surface is not None:
        tree, haz_pts, normals = surface
        q = M.apply(near)
        dist, j = tree.query(q, k=1)
        ok = dist < p.local_radius_m
        if ok.sum() >= p.min_local_points:
            signed = ((q[ok] - haz_pts[j[ok]]) * normals[j[ok]]).sum(axis=1)
            ev.local_residual_m = float(np.median(np.abs(signed)))
            ev.local_bias_m = float(np.median(signed))


def _haz_point_near(case: HandoffCase, uv: np.ndarray, range_m: float):
    """Hazcam point stereo at the hazcam-left pixel ``uv`` (2,), searched within
    ``haz_point_stereo_range_frac`` of ``range_m`` (as :meth:`HandoffCase.haz_point` does with a range hint, but
    cached under its own key, so that it never shares a cached result with the other methods): the point ``(3,)``
    (hazcam rover frame) or None."""
    from ..point_stereo import point_stereo

    p = case.params
    key = ("registration_check_haz_point", tuple(np.round(uv, 4)), round(range_m, 6))

    def compute():
        f = p.haz_point_stereo_range_frac
        lo, hi = max(case.haz.min_range_m, (1 - f) * range_m), min(case.haz.max_range_m, (1 + f) * range_m)
        if not lo < hi:  # the point is beyond the hazcam's stereo range: nothing to search
            return None
        ps = point_stereo(case.haz.left_img, case.haz.right_img, case.haz.left_model, case.haz.right_model, uv,
                          band_px=p.point_stereo_band_px, window_px=p.haz_point_stereo_window_px,
                          min_range_m=lo, max_range_m=hi)
        return ps.xyz.copy() if ps.ok else None

    return case.memo(key, compute)


def _haz_dense_window(case: HandoffCase, uv: np.ndarray, radius_px: float) -> tuple[np.ndarray, float]:
    """The hazcam dense-stereo points ``(N, 3)`` at the whole pixels within ``radius_px`` of the hazcam-left pixel
    ``uv`` (2,) that have one, and the fraction of those pixels that do (stereo leaves holes at occluding edges
    and in shadow)."""
    k = int(np.floor(radius_px))
    offs = np.array([(du, dv) for dv in range(-k, k + 1) for du in range(-k, k + 1) if du * du + dv * dv <= radius_px ** 2],
                    float)
    X = case.haz.xyz_at(np.round(uv)[None] + offs)
    ok = np.isfinite(X).all(axis=1)
    return X[ok], float(ok.mean())


def _haz_surface(case: HandoffCase, X: np.ndarray, radius_m: float):
    """The hazcam dense points within ``radius_m`` of ``X`` (3,) (hazcam rover frame) on a 5 mm grid: a k-d tree
    of them, the points ``(N, 3)`` and unit normals ``(N, 3)`` towards the hazcam (positive distances: in front
    of the surface); None with fewer than 20 points."""
    from ..open3d_import import open3d

    o3d = open3d()
    from scipy.spatial import cKDTree

    C = case.haz.left_model.C
    pts = case.haz_cloud()
    pts = select_rows(pts, squared_distances(pts, X) < radius_m ** 2)
    if len(pts) < 20:
        return None
    pc = o3d.geometry.PointCloud()
    pc.points = o3d.utility.Vector3dVector(np.ascontiguousarray(pts, dtype=np.float64))
    pc = pc.voxel_down_sample(0.005)
    pc.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=0.03, max_nn=30))
    pc.orient_normals_towards_camera_location(np.asarray(C, dtype=np.float64))
    P = np.asarray(pc.points).copy()
    return cKDTree(P), P, np.asarray(pc.normals).copy()
