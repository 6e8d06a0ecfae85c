"""The tracking and handoff chain run on rendered expected views (nominal and Monte Carlo samples),
scored against the projection of the target's surface point."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Optional

import numpy as np

from ...core.camera import CameraModel
from ...core.kinematics import RoverConfig
from .geometry import perturb_pose
from .montecarlo import McResult
from .params import PredictParams
from .planning import ApproachPlan
from .terrain import Terrain


@dataclass
class ChainSample:
    sample: int  # -1: nominal (no pose error)
    steps: list  # dicts: stop, camera, kind, ok (accurate), kept (not lost), error_px, error_m, ncc, reason
    ok: bool  # the target was kept to the final stop
    final_error_m: Optional[float] = None

    def to_dict(self) -> dict:
        return {"sample": self.sample, "ok": self.ok, "final_error_m": self.final_error_m, "steps": self.steps}


@dataclass
class ChainResult:
    samples: list  # ChainSample
    per_view: list  # dicts: stop, camera, kind, p_success, mean_error_px, n

    def to_dict(self) -> dict:
        return {"samples": [s.to_dict() for s in self.samples], "per_view": self.per_view}


def _crop_render(terrain: Terrain, m_site: CameraModel, centre_uv, half: int):
    c = np.round(np.asarray(centre_uv, float)).astype(int)
    return terrain.render(m_site, 0, 0, roi=(int(c[0] - half), int(c[1] - half), 2 * half + 1, 2 * half + 1))


def _fill(img: np.ndarray) -> np.ndarray:
    out = np.array(img, np.float32, copy=True)
    bad = ~np.isfinite(out)
    if bad.all():
        return np.zeros_like(out)
    out[bad] = float(np.nanmean(out))
    return out


def simulate_chain(plan: ApproachPlan, terrain: Terrain, rover_config: RoverConfig, designation_img: np.ndarray,
                   designation_model_site: CameraModel, designation_uv, surface_point_site, mc: Optional[McResult],
                   params: PredictParams, n_samples: Optional[int] = None, target_normal_site=None) -> ChainResult:
    """Run the tracking chain and the handoffs on rendered views, nominal and for ``n_samples`` MC samples.

    The first window comes from today's real image (``designation_img``, its
    model in the site frame, the designated pixel). At each stop and camera the
    view is rendered at the sample's true pose with the pointing computed
    from the rover's estimate (exact ``point_at``), the previous window is
    scaled by the range / IFOV ratio and NCC-tracked around the predicted
    pixel; the search region rendered is the part that holds the true target
    plus ``search_margin_px`` (clipped to the chain's search radius). With
    ``params.tracker_reach == "image"`` (the plane chain, whose feature step
    removes the pose error over the whole image) the track is searched within
    ``chain.feature_fine_radius_px`` of the true pixel instead. The
    navcam->hazcam handoff takes the tracked navcam pixel to 3-D on the
    terrain, projects it into the hazcam, and refines it by tracking an
    expected window draped from the navcam view. A step succeeds when the
    tracked pixel lies within :func:`success_px` of the projection of the target's
    surface point; a failed step loses the target for the rest of the chain.
    """
    from ...core.tracking import track

    Xs = np.asarray(surface_point_site, float).reshape(3)
    n_mc = 0 if mc is None else min(int(n_samples if n_samples is not None else params.uncertainty.n_track_samples),
                                    mc.n_samples)
    sample_ids = [-1] + list(range(n_mc))
    samples = []
    for sid in sample_ids:
        prev = {"img": np.asarray(designation_img, np.float32), "origin": (0, 0), "uv": np.asarray(designation_uv, float),
                "model": designation_model_site, "range": float(np.linalg.norm(Xs - designation_model_site.C)), "X": Xs}
        X_est = Xs.copy()
        steps, lost = [], False
        nav_view = None
        for st in plan.stops[1:]:
            if sid < 0:
                T_site_rover_true = st.T_site_rover
            else:
                dxy, dyaw = mc.errors[st.index]
                T_site_rover_true = perturb_pose(st.T_site_rover, dxy[sid:sid + 1], dyaw[sid:sid + 1])[0]
            for sh in st.cameras:
                kind = "track"
                if st.kind == "pancam-navcam-handoff" and sh.camera == "navcam":
                    kind = "handoff pancam->navcam"
                if st.kind == "navcam-hazcam-handoff" and sh.camera == "hazcam":
                    kind = "handoff navcam->hazcam"
                rec = {"stop": st.index, "camera": sh.camera, "kind": kind, "ok": False, "kept": False, "error_px": None,
                       "error_m": None, "ncc": None, "reason": ""}
                steps.append(rec)
                if lost:
                    rec["reason"] = "target lost earlier"
                    continue
                if sh.uv is None:
                    rec["reason"] = sh.note or "target not in view"
                    lost = True
                    continue
                spec = rover_config.spec(sh.camera, "left")
                Xr_est = st.T_site_rover.inverse().apply(X_est)
                pan = tilt = None
                if rover_config.cameras[sh.camera].mount == "mast":
                    try:
                        pan, tilt = rover_config.point_at(sh.camera, Xr_est)
                    except ValueError:
                        rec["reason"] = "cannot point"
                        lost = True
                        continue
                m_bel = rover_config.camera_model(sh.camera, "left", pan or 0.0, tilt or 0.0)
                uv_pred = m_bel.project(Xr_est[None])[0]
                m_true = m_bel.transformed(T_site_rover_true)  # site frame, true pose
                uv_true = m_true.project(Xs[None])[0]
                if not (np.all(np.isfinite(uv_true)) and np.all(np.isfinite(uv_pred))):
                    rec["reason"] = "target behind the camera"
                    lost = True
                    continue
                margin = plan.params.fov_margin(sh.camera)
                if not (margin <= uv_true[0] <= spec.width - 1 - margin and margin <= uv_true[1] <= spec.height - 1 - margin):
                    rec["reason"] = "out of the field of view"
                    lost = True
                    continue
                if terrain.occluded(m_true.C[None], Xs[None], params.occlusion_tol_m, target_normal_site)[0]:
                    rec["reason"] = "occluded"
                    lost = True
                    continue
                if kind == "handoff navcam->hazcam" and nav_view is not None:
                    res = _hazcam_handoff(terrain, nav_view, m_true, uv_true, params)
                else:
                    if params.tracker_reach == "image":
                        # the feature-guided step finds the pose error over the whole image; its coarse answer is
                        # taken as exact and NCC decides within the fine radius around it (what is left to fail
                        # is the appearance: a draped window that matches elsewhere, or nothing)
                        search_uv, radius = uv_true, float(params.chain.feature_fine_radius_px)
                    else:
                        search_uv, radius = uv_pred, float(params.chain.search_radius(sh.camera))
                    res = _track_step(terrain, prev, m_true, search_uv, uv_true, radius,
                                      params.chain.template_half(sh.camera), params, track)
                uv_tr, ncc, reason, view = res
                rec["ncc"] = None if ncc is None or not np.isfinite(ncc) else float(ncc)
                if uv_tr is None and reason in NO_DATA:
                    # today's terrain holds too little around the target to render this view: no evidence either
                    # way, so the step is not simulated (neither lost nor accurate); the next view is tracked from
                    # the last rendered one, re-aimed at the target
                    rec.update(reason=f"{NOT_SIMULATED}: {reason}", kept=True, ok=True, simulated=False)
                    X_est = st.T_site_rover.apply(T_site_rover_true.inverse().apply(Xs))
                    prev = dict(prev, X=Xs)
                    continue
                if uv_tr is None:
                    rec["reason"] = reason
                    lost = True
                    continue
                err = float(np.hypot(*(uv_tr - uv_true)))
                rng_t = float(np.linalg.norm(Xs - m_true.C))
                tol = success_px(m_true, rng_t, sh.camera, params)
                rec["error_px"] = err
                rec["error_m"] = err * rng_t / m_true.hs
                rec["tolerance_px"] = tol
                rec["ok"] = err <= tol
                rec["kept"] = rec["error_m"] <= params.lost_m
                if not rec["ok"]:
                    rec["reason"] = f"drift: tracked {100 * rec['error_m']:.1f} cm from the target ({err:.1f} px, tolerance {tol:.1f} px)"
                if not rec["kept"]:
                    rec["reason"] += ": lost"
                    lost = True
                    continue
                # stereo re-estimate: the terrain point at the tracked pixel, in the believed frame
                o, d = m_true.unproject(uv_tr[None])
                hit = terrain.cast(o, d)
                X_hit = hit.points[0] if hit.hit[0] else Xs
                X_est = st.T_site_rover.apply(T_site_rover_true.inverse().apply(X_hit))
                prev = {"img": view.image, "origin": view.origin_uv, "uv": uv_tr, "model": m_true,
                        "range": float(np.linalg.norm(X_hit - m_true.C)), "X": X_hit}
                if sh.camera == "navcam":
                    nav_view = {"view": view, "uv": uv_tr, "model": m_true}
        kept = bool(steps) and not lost and steps[-1]["kept"]
        samples.append(ChainSample(sid, steps, kept, steps[-1]["error_m"] if kept else None))
    per_view = []
    if samples:
        for i, s0 in enumerate(samples[0].steps):
            vals = [s.steps[i] for s in samples if s.sample >= 0]
            errs = [v["error_m"] for v in vals if v["error_m"] is not None and v["kept"]]
            sim = [v for v in vals if v.get("simulated", True)]
            per_view.append({"stop": s0["stop"], "camera": s0["camera"], "kind": s0["kind"],
                             "nominal_ok": s0["ok"], "nominal_kept": s0["kept"], "nominal_error_px": s0["error_px"],
                             "nominal_error_m": s0["error_m"], "nominal_reason": s0["reason"],
                             "p_kept": (float(np.mean([v["kept"] for v in sim])) if sim else None),
                             "n_simulated": len(sim),
                             "p_kept_given_visible": _p_given_visible(vals, "kept"),
                             "p_accurate_given_visible": _p_given_visible(vals, "ok"),
                             "mean_error_m": float(np.mean(errs)) if errs else None, "n": len(vals),
                             "reasons": sorted({v["reason"] for v in vals if v["reason"] and not v["ok"]})})
    return ChainResult(samples, per_view)


# a step whose view cannot be rendered from today's terrain (too little stereo around the target) is not simulated
NOT_SIMULATED = "not simulated"
NO_DATA = ("expected window mostly empty", "expected hazcam window mostly empty", "no terrain data in the search region",
           "no terrain at the navcam pixel")


def success_px(model: CameraModel, range_m: float, camera: str, params: PredictParams) -> float:
    """Tracking tolerance (px) at ``range_m``: ``params.success_of(camera)`` on the surface (at least
    ``params.min_success_px``)."""
    return float(max(params.min_success_px, params.success_of(camera) * model.hs / max(range_m, 1e-6)))


def _p_given_visible(vals, key):
    geo = ("out of the field of view", "occluded", "target behind the camera", "target lost earlier", "cannot point")
    vis = [v for v in vals if not (v["reason"] in geo) and v.get("simulated", True)]
    return float(np.mean([v[key] for v in vis])) if vis else None


def _draped_template(terrain, prev, m_new, X_prev, half: int):
    """The previous view as the new camera sees it around the previously tracked 3-D point: the new camera's
    rays ``(2 half + 1)^2`` around the projection of ``X_prev`` (3,) (site) cast onto the terrain and the
    hits' intensities sampled in the previous view (``prev``: img, origin, model). This is the chain's own
    template (``pipeline/chain.py`` renders the previous image into the new view through the target's plane),
    with the terrain in place of the plane. Returns ``(template (h, w) float32, tracked point in template px)``
    or ``(None, reason)``."""
    from ...core.expected import bilinear_sample

    uv_c = m_new.project(np.asarray(X_prev, float)[None])[0]
    if not np.all(np.isfinite(uv_c)):
        return None, "the tracked point does not project into the new view"
    c = np.round(uv_c)
    us, vs = np.meshgrid(np.arange(c[0] - half, c[0] + half + 1), np.arange(c[1] - half, c[1] + half + 1))
    uv = np.stack([us, vs], -1).reshape(-1, 2)
    oo, dd = m_new.unproject(uv)
    hh = terrain.cast(oo, dd)
    vals = np.full(len(uv), np.nan, np.float32)
    if np.any(hh.hit):
        puv = prev["model"].project(hh.points[hh.hit]) - np.asarray(prev["origin"], float)
        vals[hh.hit] = bilinear_sample(prev["img"], puv)
    tpl = vals.reshape(2 * half + 1, 2 * half + 1)
    if np.isfinite(tpl).mean() < 0.5:
        return None, "expected window mostly empty"
    return _fill(tpl), uv_c - (c - half)


def _track_step(terrain, prev, m_true, uv_pred, uv_true, radius, half, params, track):
    """Track the previous view, draped into the new view (:func:`_draped_template`), in a rendered crop around the
    prediction ``uv_pred``. Returns (uv or None, ncc, reason, RenderedView)."""
    tpl, tc = _draped_template(terrain, prev, m_true, prev["X"], half)
    if tpl is None:
        return None, None, tc, None
    off = float(np.abs(uv_true - uv_pred).max())
    r_eff = min(radius, off + params.search_margin_px)
    if off > radius:
        return None, None, "outside the search region", None
    # crop: the search region around the prediction plus the template, plus the window the next stop needs
    crop_half = int(math.ceil(r_eff + tpl.shape[0] // 2 + 2))
    need_next = int(math.ceil(3 * half + 4))  # a later camera change (scale ~1/3) needs ~3x the window
    crop_half = max(crop_half, int(math.ceil(off + need_next)))
    view = _crop_render(terrain, m_true, uv_pred, crop_half)
    img = _fill(view.image)
    if view.coverage < params.min_coverage * 0.5:
        return None, None, "no terrain data in the search region", view
    loc_pred = uv_pred - np.asarray(view.origin_uv, float)
    tr = track(tpl, img, loc_pred, r_eff, template_center_uv=tc, min_score=0.3)
    if not tr.ok or not np.all(np.isfinite(tr.uv)):
        return None, tr.score, f"track: {tr.reason}", view
    return tr.uv + np.asarray(view.origin_uv, float), tr.score, "", view


def _hazcam_handoff(terrain, nav, m_haz_true, uv_true, params):
    """Navcam->hazcam handoff on rendered views: kinematic point (terrain 3-D at the navcam pixel), refined by
    an expected hazcam window draped from the navcam view, NCC-tracked."""
    from ...core.expected import bilinear_sample
    from ...core.tracking import track

    o, d = nav["model"].unproject(np.asarray(nav["uv"], float)[None])
    hit = terrain.cast(o, d)
    if not hit.hit[0]:
        return None, None, "no terrain at the navcam pixel", None
    uv_k = m_haz_true.project(hit.points[0][None])[0]
    if not np.all(np.isfinite(uv_k)):
        return None, None, "target does not project into the hazcam", None
    k = params.handoff.template_half_px
    c = np.round(uv_k)
    # expected window: hazcam rays -> terrain -> navcam view intensities
    us, vs = np.meshgrid(np.arange(c[0] - k, c[0] + k + 1), np.arange(c[1] - k, c[1] + k + 1))
    uv = np.stack([us, vs], -1).reshape(-1, 2)
    oo, dd = m_haz_true.unproject(uv)
    hh = terrain.cast(oo, dd)
    nv = nav["view"]
    vals = np.full(len(uv), np.nan, np.float32)
    if np.any(hh.hit):
        puv = nav["model"].project(hh.points[hh.hit]) - np.asarray(nv.origin_uv, float)
        vals[hh.hit] = bilinear_sample(nv.image, puv)
    tpl = vals.reshape(2 * k + 1, 2 * k + 1)
    if np.isfinite(tpl).mean() < 0.5:
        return None, None, "expected hazcam window mostly empty", None
    tpl = _fill(tpl)
    off = float(np.abs(uv_true - uv_k).max())
    radius = params.handoff.search_radius_px
    if off > radius:
        return None, None, "outside the search region", None
    r_eff = min(radius, off + params.search_margin_px)
    half = int(math.ceil(r_eff + k + 2))
    half = max(half, int(math.ceil(off + 3 * params.chain.template_half("hazcam") + 4)))
    view = _crop_render(terrain, m_haz_true, uv_k, half)
    img = _fill(view.image)
    tc = uv_k - (c - k)
    tr = track(tpl, img, uv_k - np.asarray(view.origin_uv, float), r_eff, template_center_uv=tc, min_score=0.3)
    if not tr.ok or not np.all(np.isfinite(tr.uv)):
        return None, tr.score, f"track: {tr.reason}", view
    return tr.uv + np.asarray(view.origin_uv, float), tr.score, "", view
