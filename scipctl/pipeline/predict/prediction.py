"""The whole prediction (orchestration): views, Monte Carlo, chain on rendered views, risks and the
confidence for a planned approach (:func:`run_prediction`), and from a downlink (:func:`predict_target`)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Optional

import numpy as np

from ...core.camera import CameraModel
from ...core.kinematics import RoverConfig
from ...core.prediction_calibration import PredictionCalibration
from ..designate import Designation
from .chain_sim import ChainResult, simulate_chain
from .from_downlink import sigmas_for, target_context, terrain_sources
from .montecarlo import McResult, monte_carlo
from .params import PredictParams
from .planning import ApproachPlan, plan_approach
from .risks import Risk, assess_risks, foreshortening_changes
from .terrain import Terrain
from .views import check_views


@dataclass
class Prediction:
    target_id: str
    plan: ApproachPlan
    mc: Optional[McResult]
    chain: Optional[ChainResult]
    risks: list
    views: dict  # (stop, camera) -> RenderedView (reduced size)
    surface_point_site: np.ndarray
    confidence: float  # P(success): p_simulated calibrated against the chain (== p_simulated when not calibrated)
    sigma_source: str
    notes: list = field(default_factory=list)
    seconds: dict = field(default_factory=dict)
    accuracy: dict = field(default_factory=dict)  # predicted final placement error (m): nominal, mean, max over kept samples
    terrain: Optional[Terrain] = field(default=None, repr=False)  # today's terrain the views were rendered from
    p_simulated: Optional[float] = None  # geometry MC x tracking on expected views (confidence_of); None: = confidence
    calibration: Optional[str] = None  # what calibrated confidence (the model file and its population); None: nothing

    def __post_init__(self):
        if self.p_simulated is None:
            self.p_simulated = self.confidence

    def to_dict(self) -> dict:
        return {
            "target": self.target_id, "plan": self.plan.to_dict(), "accuracy": self.accuracy,
            "monte_carlo": None if self.mc is None else self.mc.to_dict(),
            "chain": None if self.chain is None else self.chain.to_dict(),
            "risks": [r.to_dict() for r in self.risks], "confidence": self.confidence,
            "p_simulated": self.p_simulated, "calibration": self.calibration,
            "surface_point_site_m": self.surface_point_site.tolist(), "sigma_source": self.sigma_source,
            "notes": self.notes, "seconds": self.seconds,
        }


def confidence_of(mc: Optional[McResult], chain: Optional[ChainResult]) -> float:
    """Predicted P(success) = P(geometry ok: every view in field, in search, visible; arm reaches) from the Monte
    Carlo, times the fraction of the rendered chain samples that were geometrically ok and tracked the target
    to the end within tolerance (the nominal chain when no sample was geometrically ok)."""
    p = 1.0 if mc is None else mc.p_success_geometry
    if chain is None:
        return float(p)
    runs = [s for s in chain.samples if s.sample >= 0]
    if mc is not None and mc.samples_ok is not None:
        runs = [s for s in runs if mc.samples_ok[s.sample]]
    if not runs:
        runs = [s for s in chain.samples if s.sample < 0]
    frac = float(np.mean([s.ok for s in runs])) if runs else 1.0
    return float(p * frac)


@dataclass(frozen=True)
class PoseSigmas:
    """The pose-estimate error of the approach's first leg (see :func:`sigmas_for`) and where it came from."""

    position_m: float
    yaw_rad: float
    source: str  # e.g. "position: downlink, yaw: default"


def run_prediction(plan: ApproachPlan, terrain: Terrain, rover_config: RoverConfig, designation: Designation,
                   image: np.ndarray, model_site: CameraModel, sigmas: PoseSigmas,
                   params: Optional[PredictParams] = None, render_views: bool = True,
                   calibration: Optional[PredictionCalibration] = None) -> Prediction:
    """Views, Monte Carlo, chain simulation and risks for a planned approach (pure: arrays in, results out).

    ``designation``: today's designation (its pixel, its 3-D point ``xyz_site_m`` and ``range_sigma_m``, the
    1-sigma error of its range along its line of sight; None counts as 0); ``image`` ``(H, W)`` float32: the
    left image it was designated in; ``model_site``: that image's camera model in the site frame.
    ``params`` (default :class:`PredictParams`) is checked first. ``render_views``: render the reduced-size
    expected views (``Prediction.views``, for the report); no figure of the prediction depends on them.
    ``calibration``: maps the simulated probability (:func:`confidence_of`, kept as ``Prediction.p_simulated``)
    to ``Prediction.confidence`` (None: ``confidence`` is the simulated probability).
    """
    import time

    params = (params or PredictParams()).check()
    notes, secs = [], {}
    uv = np.asarray(designation.pixel_uv, float)
    X_T = np.asarray(designation.xyz_site_m, float)
    range_sigma_m = float(designation.range_sigma_m or 0.0)
    # the target's point on the terrain surface: today's designation ray cast into the mesh
    o, d = model_site.unproject(uv[None])
    hit = terrain.cast(o, d)
    Xs = hit.points[0] if hit.hit[0] else None
    n_target = hit.normals[0] if hit.hit[0] else None  # the target's surface normal (occlusion by itself)
    if Xs is None or np.linalg.norm(Xs - X_T) > max(0.1, 0.05 * np.linalg.norm(X_T - o[0])):
        notes.append("the designation ray misses today's stereo surface near the target; using the designated point")
        Xs, n_target = X_T, None
    t0 = time.perf_counter()
    views = check_views(plan, terrain, rover_config, Xs, params, render=render_views, target_normal_site=n_target)
    secs["views"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    mc = monte_carlo(plan, terrain, rover_config, Xs, params.uncertainty, sigmas.position_m, sigmas.yaw_rad,
                     range_sigma_m, params.occlusion_tol_m, tracker_reach=params.tracker_reach,
                     target_normal_site=n_target)
    secs["monte_carlo"] = time.perf_counter() - t0
    chain = None
    if params.run_chain:
        t0 = time.perf_counter()
        chain = simulate_chain(plan, terrain, rover_config, image, model_site, uv, Xs, mc, params,
                               target_normal_site=n_target)
        secs["chain"] = time.perf_counter() - t0
    risks = assess_risks(plan, mc, chain, params)
    for (si, cam), ratio in sorted(foreshortening_changes(plan).items()):
        if not (1.0 / params.max_foreshortening_change <= ratio <= params.max_foreshortening_change):
            msg = f"too oblique a change of view: the target's foreshortening changes x{ratio:.2f} from the previous image"
            r = next((r for r in risks if r.stop == si and r.camera == cam), None)
            if r is None:
                risks.append(Risk(si, cam, "view", None, [msg]))
            else:
                r.reasons.append(msg)
    risks.sort(key=lambda r: (r.stop, r.camera))
    p_sim = confidence_of(mc, chain)
    conf = p_sim if calibration is None else calibration.p_success(p_sim)
    acc = {}
    if chain is not None:
        nom = [s for s in chain.samples if s.sample < 0]
        kept = [s.final_error_m for s in chain.samples if s.sample >= 0 and s.ok and s.final_error_m is not None]
        acc = {"nominal_final_error_m": nom[0].final_error_m if nom else None,
               "mean_final_error_m": float(np.mean(kept)) if kept else None,
               "max_final_error_m": float(np.max(kept)) if kept else None, "samples_kept": len(kept),
               "goal_m": params.success_of("hazcam")}
    return Prediction(designation.id, plan, mc, chain, risks, views, np.asarray(Xs, float), conf, sigmas.source, notes,
                      secs, acc, terrain, p_sim, None if calibration is None else calibration_label(calibration))


def calibration_label(calibration: PredictionCalibration) -> str:
    """One line naming a calibration: its route, how many approaches and families it was fitted on."""
    pv = calibration.provenance
    fams = pv.get("training_families") or []
    return (f"{pv.get('route', '?')} route: fitted on {pv.get('n_rows', '?')} approaches of {len(fams)} families "
            f"(chain within {calibration.success_px:g} px for {pv.get('n_success', '?')})")


def predict_target(dl, record: Designation, params: Optional[PredictParams] = None, designated_now: bool = False,
                   terrain: Optional[Terrain] = None, render_views: bool = True) -> Prediction:
    """Plan and predict tomorrow's approach to a designated target from today's downlink (the designation's position).
    With ``params.route == "downlink"`` the approach is the downlink's own later stops instead of a planned one
    (:func:`~.route.route_from_downlink`; only today's images are read, the later positions' recorded poses give
    the route).

    ``render_views``: as in :func:`run_prediction` (False: ``Prediction.views`` is empty). With ``params.calibrate``
    the confidence is calibrated by the packaged model of ``params.route``
    (:mod:`scipctl.core.prediction_calibration`; none packaged: not calibrated)."""
    import time

    params = (params or PredictParams()).check()
    ctx = target_context(dl, record, designated_now)
    t0 = time.perf_counter()
    if terrain is None:
        srcs = terrain_sources(dl, ctx.product.position, downsample=params.stereo_downsample,
                               target_range_m=record.range_m)
        terrain = Terrain(srcs, params.max_edge_ratio, params.min_edge_m, params.smooth_sigma_px)
    t_terrain = time.perf_counter() - t0
    t0 = time.perf_counter()
    if params.route == "downlink":
        from .route import route_from_downlink

        plan = route_from_downlink(dl, ctx.start, ctx.product.position, ctx.target_site_m, terrain, params.approach,
                                   params.chain, designation_camera=ctx.product.camera)
    else:
        plan = plan_approach(ctx.start, ctx.target_site_m, terrain, dl.rover_config, params.approach,
                             designation_camera=ctx.product.camera, chain_params=params.chain,
                             uncertainty=params.uncertainty)
    t_plan = time.perf_counter() - t0
    sp, sy, src = sigmas_for(ctx.product, params.uncertainty)
    calibration = None
    if params.calibrate:
        from ...io.prediction_calibration import load_packaged_prediction_calibration

        calibration = load_packaged_prediction_calibration(params.route)
    pred = run_prediction(plan, terrain, dl.rover_config, record, ctx.product.pixels_float(),
                          ctx.product.camera_model.transformed(ctx.start.T_site_rover), PoseSigmas(sp, sy, src), params,
                          render_views=render_views, calibration=calibration)
    pred.seconds.update({"terrain": t_terrain, "plan": t_plan})
    return pred
