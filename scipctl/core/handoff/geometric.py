"""Geometric handoff methods: the hazcam stereo surface seen from the navcam (pure numerics).

Each is ``method(case, nav_uv, params, *, near_hint=None) -> MethodResult`` (``near_hint`` unused here);
``nav_uv`` (2,) is the navcam-left pixel, the answer the hazcam-left pixel (2,). They raise
:class:`~scipctl.core.handoff.result.NoAnswer` when they have none.
"""

from __future__ import annotations

from typing import Optional

import numpy as np

from ..camera import CameraModel
from ..expected import match_projection, nearest_projection
from .case import HandoffCase
from .params import HandoffParams
from .result import MethodResult, NoAnswer, answer, f, track_diag
from .steps import interp_xyz, project_haz, track
from .windows import draped_window


def pure_geometric(case: HandoffCase, nav_uv, params: HandoffParams, *,
                   near_hint: Optional[MethodResult] = None) -> MethodResult:
    """The paper's pure geometric handoff, then (beyond the paper) a sub-pixel refinement.

    Paper: the hazcam dense point whose navcam projection lands nearest the
    navcam target (here refined to sub-pixel by the local affine fit of the
    projection). Its error is the dense range error at that one pixel times
    the hazcam-navcam parallax (~0.2 hazcam px per mm of range at 1 m from
    near navcams: SGBM's few-mm noise and corner rounding is ~1 px).
    Refinement: Gauss-Newton on the hazcam pixel, with each pixel's 3-D
    point from hazcam point stereo (small window, affine NCC) and the
    Jacobian from the dense surface, until that point projects onto the
    navcam target. The dense answer is kept when point stereo fails.

    Computed once per target and case (the refined, coarse-fine and consensus
    methods start from it); each call returns a copy.
    """
    key = ("pg", tuple(np.round(np.asarray(nav_uv, float), 6)))
    return case.memo(key, lambda: _pure_geometric(case, nav_uv, params)).copy()


def _pure_geometric(case: HandoffCase, nav_uv, params: HandoffParams) -> MethodResult:
    xyz = case.haz.dense.xyz  # rectified-left grid of the hazcam, hazcam rover frame
    nav_in_haz = case.nav_model_in_haz()
    res = nearest_projection(xyz, (0, 0), nav_in_haz, nav_uv, proj=case.haz_in_nav())
    if res is None:
        raise NoAnswer("no hazcam stereo projects into the navcam")
    # sub-pixel point on the rectified grid -> 3-D -> original hazcam pixel
    X = interp_xyz(xyz, res.uv)
    if X is None:
        X = res.xyz
    uv = project_haz(case, X)
    diag = {"nearest_distance_navcam_px": res.distance_px, "dense_uv": uv.tolist()}
    refined = None
    if params.haz_point_stereo_window_px > 0 and np.all(np.isfinite(uv)):
        J = haz_to_nav_jacobian(case, uv, nav_in_haz)
        C = case.haz.left_model.C
        r_hint = float(np.linalg.norm(X - C))
        if J is not None:
            refined = match_projection(lambda p: case.haz_point(p, r_hint), nav_in_haz, nav_uv, uv, J,
                                       max_iterations=params.geometric_iterations)
    if refined is not None and refined.residual_px <= params.geometric_max_residual_px:
        diag.update({"refined_by": "hazcam point stereo", "refinement_px": float(np.hypot(*(refined.uv - uv))),
                     "refinement_residual_navcam_px": refined.residual_px,
                     "refinement_iterations": refined.iterations})
        uv, X = refined.uv, refined.xyz
    else:
        diag["refined_by"] = None
    diag["xyz_haz_rover_m"] = X.tolist()
    return answer(uv, diag)


def haz_to_nav_jacobian(case: HandoffCase, haz_uv, nav_in_haz: CameraModel,
                        step_px: float = 2.0) -> Optional[np.ndarray]:
    """d(navcam pixel)/d(hazcam pixel) ``(2, 2)`` at ``haz_uv`` (2,) by central differences of the hazcam dense
    surface (``nav_in_haz``: the navcam-left model in the hazcam rover frame); None where it is not defined."""
    uv = np.asarray(haz_uv, float).reshape(2)
    offs = np.array([[step_px, 0], [-step_px, 0], [0, step_px], [0, -step_px]])
    X = case.haz.xyz_at(uv + offs)
    if not np.all(np.isfinite(X)):
        return None
    q = nav_in_haz.project(X)
    J = np.stack([(q[0] - q[1]), (q[2] - q[3])], axis=1) / (2 * step_px)
    if not np.all(np.isfinite(J)) or abs(np.linalg.det(J)) < 1e-6:
        return None
    return J


def refined_geometric(case: HandoffCase, nav_uv, params: HandoffParams, *,
                      near_hint: Optional[MethodResult] = None) -> MethodResult:
    """The navcam image draped over the hazcam stereo surface as the expected hazcam window (anti-aliased to
    the hazcam pixel footprint), centred on the pure-geometric point, NCC-tracked."""
    p = params
    pg = pure_geometric(case, nav_uv, p)
    tpl, frac, c = draped_window(case, p, pg.uv, case.T_haz_nav, p.template_half_px)
    if tpl is None:
        raise NoAnswer("expected hazcam window is empty (no hazcam stereo around the target)")
    tc = np.asarray(pg.uv) - (c - p.template_half_px)
    tr = track(case, tpl, pg.uv, p.search_radius_px, p.refined_min_score, template_center_uv=tc)
    if not np.all(np.isfinite(tr.uv)):
        raise NoAnswer(f"NCC track failed: {tr.reason}")
    diag = {"draped_fraction": frac, "start_uv": pg.uv.tolist()}
    diag.update(track_diag(tr))
    return answer(tr.uv, diag)


def coarse_fine_geometric(case: HandoffCase, nav_uv, params: HandoffParams, *,
                          near_hint: Optional[MethodResult] = None) -> MethodResult:
    """Beyond the paper (its suggestion for refinement failures): track a large draped window (more context)
    first, then the small one within ``fine_search_px`` of that answer (the coarse answer if the fine track
    fails)."""
    p = params
    pg = pure_geometric(case, nav_uv, p)
    big, frac_big, cb = draped_window(case, p, pg.uv, case.T_haz_nav, p.coarse_template_half_px)
    small, frac, cs = draped_window(case, p, pg.uv, case.T_haz_nav, p.template_half_px)
    if big is None or small is None:
        raise NoAnswer("expected hazcam window is empty (no hazcam stereo around the target)")
    tr1 = track(case, big, pg.uv, p.search_radius_px, p.refined_min_score,
                template_center_uv=np.asarray(pg.uv) - (cb - p.coarse_template_half_px))
    if not np.all(np.isfinite(tr1.uv)):
        raise NoAnswer(f"coarse NCC track failed: {tr1.reason}")
    tr2 = track(case, small, tr1.uv, p.fine_search_px, p.refined_min_score,
                template_center_uv=np.asarray(pg.uv) - (cs - p.template_half_px))
    diag = {"draped_fraction": frac_big, "start_uv": pg.uv.tolist(), "coarse_uv": tr1.uv.tolist(),
            "coarse_ncc_peak": f(tr1.score), "coarse_ncc_ratio": f(tr1.ratio)}
    if not np.all(np.isfinite(tr2.uv)):
        diag["fallback"] = f"fine track failed: {tr2.reason}"
        return answer(tr1.uv, diag)
    diag.update(track_diag(tr2))
    return answer(tr2.uv, diag)
