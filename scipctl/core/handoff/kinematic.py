"""Kinematic handoff methods: the navcam target's 3-D point moved into the hazcam (pure numerics).

Each is ``method(case, nav_uv, params, *, near_hint=None) -> MethodResult``; ``nav_uv`` (2,) is the
navcam-left pixel, the answer the hazcam-left pixel (2,). They raise
:class:`~scipctl.core.handoff.result.NoAnswer` when they have none.
"""

from __future__ import annotations

from typing import Optional

import numpy as np

from ..expected import splat_points
from ..registration import squared_distances
from .case import HandoffCase
from .params import HandoffParams
from .result import MethodResult, NoAnswer, answer, f, track_diag
from .steps import dense_point, local_ifov_rad, nav_point, project_haz, search_reaches_image, track
from .windows import fill_nan, nav_plane_normal, plane_window


def pure_kinematic(case: HandoffCase, nav_uv, params: HandoffParams, *,
                   near_hint: Optional[MethodResult] = None) -> MethodResult:
    """Point stereo on the navcams -> 3-D (navcam rover frame) -> ``T_haz_nav`` -> hazcam model."""
    ps = nav_point(case, nav_uv)
    X = case.T_haz_nav.apply(ps.xyz)
    uv = project_haz(case, X)
    if not np.all(np.isfinite(uv)):
        raise NoAnswer("target does not project into the hazcam")
    return answer(uv, {
        "stereo_score": f(ps.score), "range_m": f(ps.range_m), "epipolar_offset_px": f(ps.epipolar_offset_px),
        "xyz_haz_rover_m": X.tolist(),
    })


def alt_pure_kinematic(case: HandoffCase, nav_uv, params: HandoffParams, *,
                       near_hint: Optional[MethodResult] = None) -> MethodResult:
    """:func:`pure_kinematic` with the dense ("JPL", rectified) stereo range."""
    X = case.T_haz_nav.apply(dense_point(case, nav_uv))
    uv = project_haz(case, X)
    if not np.all(np.isfinite(uv)):
        raise NoAnswer("target does not project into the hazcam")
    return answer(uv, {"xyz_haz_rover_m": X.tolist()})


def refined_kinematic(case: HandoffCase, nav_uv, params: HandoffParams, *,
                      near_hint: Optional[MethodResult] = None) -> MethodResult:
    """An expected hazcam window from the navcams, NCC-tracked in the hazcam.

    Near: the window splatted from the navcam dense cloud, centred on the
    alt-pure-kinematic point. Far: the far navcam window brought into the
    hazcam view, tracked around ``near_hint`` (the near navcams'
    pure-kinematic result for the same target, as in the paper; the far
    kinematic point when it is None or failed). Beyond the paper, the far
    window is warped through the local plane (fitted to the far navcam's
    dense points around the target); ``far_window_warp="scale"`` (or no
    plane) gives the paper's uniformly scaled window.
    """
    p = params
    k = p.template_half_px
    if case.label == "near":
        X = case.T_haz_nav.apply(dense_point(case, nav_uv))
        centre = project_haz(case, X)
        if not np.all(np.isfinite(centre)):
            raise NoAnswer("target does not project into the hazcam")
        pts, vals = case.nav_cloud_in_haz()
        near = squared_distances(pts, X) < p.nav_cloud_radius_m**2
        c = np.round(centre).astype(int)
        roi = (int(c[0] - k), int(c[1] - k), 2 * k + 1, 2 * k + 1)
        sp = splat_points(pts[near], vals[near], case.haz.left_model, case.haz.width, case.haz.height, roi=roi)
        tpl = fill_nan(sp.image)
        if tpl is None:
            raise NoAnswer("expected hazcam window is empty (no navcam stereo around the target)")
        tc = centre - np.array([roi[0], roi[1]], float)
        tr = track(case, tpl, centre, p.search_radius_px, p.refined_min_score, template_center_uv=tc)
        diag = {"expected_filled": sp.filled_fraction, "start_uv": centre.tolist()}
    else:
        ps = nav_point(case, nav_uv)
        X_far = case.T_haz_nav.apply(ps.xyz)
        if near_hint is None or not near_hint.ok:
            # fall back to the far kinematic point when the near one is not available
            start = project_haz(case, X_far)
            X_haz = X_far
        else:
            start = near_hint.uv
            X_haz = np.asarray(near_hint.diagnostics["xyz_haz_rover_m"])
        if not search_reaches_image(start, p.search_radius_px, case.haz.width, case.haz.height):
            # no hazcam pixel within the search radius: nothing to track (and a fish-eye model's pixel angle,
            # needed to scale the window, is 0 that far outside the image)
            raise NoAnswer(f"the kinematic start ({start[0]:.0f}, {start[1]:.0f}) is more than the search radius "
                           f"{p.search_radius_px:g} px outside the hazcam image", {"start_uv": np.asarray(start).tolist()})
        tpl = None
        if p.far_window_warp == "plane":
            n_nav = nav_plane_normal(case, p, nav_uv, ps.xyz)
            if n_nav is not None:
                tpl, tc, A = plane_window(case, X_far, case.T_haz_nav.rotate(n_nav), k)
                if tpl is not None:
                    tr = track(case, tpl, start, p.search_radius_px, p.refined_min_score, template_center_uv=tc)
                    diag = {"warp": "local plane", "nav_px_per_haz_px": A.tolist(),
                            "start_uv": np.asarray(start).tolist()}
        if tpl is None:  # the paper's uniformly scaled window
            from ..windows import extract_window, scale_window, window_scale_for_handoff

            ifov_nav = local_ifov_rad(case.nav.left_model, nav_uv)
            ifov_haz = local_ifov_rad(case.haz.left_model, start)
            range_haz = float(np.linalg.norm(X_haz - case.haz.left_model.C))
            try:
                scale = window_scale_for_handoff(ifov_nav, ps.range_m, ifov_haz, range_haz)
            except ValueError as e:  # a pixel angle or a range at the target is not positive
                raise NoAnswer(f"no window scale: {e}", {"start_uv": np.asarray(start).tolist()}) from None
            src_half = int(np.ceil(k / scale))
            win = extract_window(case.nav.left_img, nav_uv, src_half)
            tpl = scale_window(win, scale)
            tr = track(case, tpl, start, p.search_radius_px, p.refined_min_score)
            diag = {"warp": "uniform scale", "scale": scale, "start_uv": np.asarray(start).tolist()}
    if not np.all(np.isfinite(tr.uv)):
        raise NoAnswer(f"NCC track failed: {tr.reason}", diag)
    diag.update(track_diag(tr))
    return answer(tr.uv, diag)
