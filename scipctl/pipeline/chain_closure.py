"""The chain's closure check: the target re-found in the final hazcam image straight from the chain's last trusted
pancam track, skipping the navcam steps in between (docs/stereo-and-tracking.md, "Closure").

The chain hands the target from stop to stop; an error at one stop is carried, not corrected, and ``scip`` hands
the chain's navcam pixel off faithfully, drift included. The closure is a second, shorter path to the same
hazcam pixel: the pancam image of the approach's imaging stop (~4.5 m; at 0.28 mrad/px its footprint on the
target, ~1.3 mm, is finer than the hazcam's at ~1 m, ~2 mm) is rendered through the target's local plane into
the final hazcam view and found there by the chain's own feature-guided step
(:func:`~scipctl.pipeline.feature_track.feature_track`: features remove the pose error of the drive between the
two stops, NCC refines). Where the two paths agree, the navcam steps did not drift; where they disagree, one of
them is wrong. The pancam track itself is shared by both paths, so an error there is in both (measured: the
closure is therefore not a GO). Measured again as the answer, a confirmed closure is more often right than the
handoff path, so it is the chain's default answer (``ChainParams.answer``; docs/stereo-and-tracking.md, "Closure as
the answer"); ``ChainParams.closure`` records the check on a chain that answers by handoff.

When the pancam track at that stop was flagged, the closure starts from the navcam handoff there instead (found
from the designation image across the drive, not from the pancam track): coarser (~3.7 mm at 4.5 m), still
independent of the navcam tracks that follow it.

The check records, on the final hazcam step's ``extra["closure"]``, a :class:`Closure`'s dict: the status of
the feature step (``confirmed`` / ``unconfirmed`` / ``failed``, or why there was nothing to check), the
reference product, the closure pixel and its distance ``closure_px`` to the chain's answer, and the feature
step's diagnostics.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Optional

import numpy as np

from ..jsonutil import finite_or_none


@dataclass
class Closure:
    """The closure check of one chain. ``status``: ``confirmed`` | ``unconfirmed`` | ``failed`` (the feature step's)
    or ``no final answer`` | ``no reference`` | ``no stereo`` (nothing to check). ``uv``: the closure's pixel in the
    final hazcam image (None unless found); ``closure_px``: its distance to the chain's final answer (hazcam px)."""

    status: str
    reference: Optional[str] = None  # product id of the image the closure started from (a pancam or navcam)
    reference_step: Optional[int] = None  # its index in the chain
    uv: Optional[list] = None
    closure_px: Optional[float] = None
    scale: Optional[float] = None  # hazcam pixels per reference pixel at the target
    ncc_peak: Optional[float] = None
    feature_local_inliers: int = 0
    feature_confirmed: int = 0
    feature_shift_px: Optional[float] = None
    # with ChainParams.closure_vo: whether the visual-odometry candidate won, and its RANSAC inliers (None: not run
    # or not solved)
    feature_vo: Optional[bool] = None
    vo_inliers: Optional[int] = None
    # confirmed: how many candidates' NCC positions agreed (pooled), and how far NCC moved the winner's feature
    # position (hazcam px)
    feature_pooled: Optional[int] = None
    feature_refine_px: Optional[float] = None
    # "navcam": the closure started from the pancam image of the reference's stop, at the navcam handoff's point
    # projected into it (ChainParams.closure_pancam_from_navcam); None: from the reference step's own image
    via: Optional[str] = None

    def to_dict(self) -> dict:
        d = asdict(self)
        for k in ("closure_px", "scale", "ncc_peak", "feature_shift_px", "feature_refine_px"):
            d[k] = finite_or_none(d[k])
        return d


# (camera, step kind) of the steps the closure may start from, in order of preference (closure_reference)
CLOSURE_REFERENCES = (("pancam", "track"), ("navcam", "handoff"))


def closure_reference(steps: list, final: int, order: tuple = CLOSURE_REFERENCES) -> Optional[int]:
    """Index of the step the closure starts from, or None: the chain's last trusted pancam track before step
    ``final``; when there is none, its last trusted navcam handoff (at the approach's imaging stop, found from the
    designation image across the drive when the pancam track there was flagged). Trusted: ok, not unverified, with
    a pixel and a stereo point, at an earlier stop than ``final``. Navcam tracks are never the reference: they are
    what the closure checks. The designation is not one either: measured as one (session 28,
    docs/stereo-and-tracking.md, "The closure's reference"), it was confirmed for 33 of 87 chains, and preferring it
    lost chains. ``order``: the (camera, step kind) pairs tried, first found wins (a measurement may ask for one
    kind alone, e.g. ``(("pancam", "designate"),)``)."""
    def trusted(s):
        return (s.ok and not s.extra.get("unverified") and s.tracked_uv is not None and s.xyz_site_m is not None
                and s.position != steps[final].position)

    for camera, kind in order:
        for i in range(final - 1, -1, -1):
            if steps[i].camera == camera and steps[i].kind == kind and trusted(steps[i]):
                return i
    return None


def track_from_step(dl, R, prod, params, feats: Optional[dict] = None):
    """The target found in ``prod`` (an image product) straight from the chain step ``R`` (its image and pixel,
    its stereo point on that pixel's ray, the local plane there) by the chain's feature-guided step:
    ``(TrackResult or None, info dict, scale, predicted pixel)``; ``(None, {}, nan, None)`` when the target projects
    behind ``prod``'s camera. ``feats``: the feature step's keypoint cache (:func:`feature_track`; None: its own)."""
    from ..core.point_stereo import on_left_ray
    from ..core.windows import window_scale_for_handoff
    from .feature_track import feature_track, vo_correction
    from .plane_warp import local_normals_site, near_dense_stereo, render_planes

    prev = dl.product(R.product_id)
    # the reference's estimate on its tracked pixel's ray, as the chain keeps it (on_left_ray)
    X_prev = on_left_ray(prev.camera_model, R.tracked_uv, prev.pose.T_site_rover.inverse().apply(np.asarray(R.xyz_site_m)))
    X_site = prev.pose.T_site_rover.apply(X_prev)
    rng_prev = float(np.linalg.norm(X_prev - prev.camera_model.C))
    prev_stereo = near_dense_stereo(dl, prev, rng_prev)  # the plane's normals and the odometry's 3-D points
    planes, n_view = render_planes(prev, *local_normals_site(prev, X_prev, rng_prev, prev_stereo))
    X_new = prod.pose.T_site_rover.inverse().apply(X_site)
    pred = prod.camera_model.project(X_new[None])[0]
    if not np.all(np.isfinite(pred)):
        return None, {}, float("nan"), None
    rng_new = float(np.linalg.norm(X_new - prod.camera_model.C))
    scale = window_scale_for_handoff(1.0 / prev.camera_model.hs, rng_prev, 1.0 / prod.camera_model.hs, rng_new)
    feats = {} if feats is None else feats
    vo = vo_correction(dl, prev, prod, rng_prev, feats, params, prev_stereo) if params.closure_vo else None
    tr, info = feature_track(prev, prod, X_site, planes, n_view, pred, scale, params.template_half(prod.camera),
                             feats, params, vo=vo)
    return tr, info, float(scale), pred


def pancam_from_navcam(dl, N):
    """The navcam handoff step ``N`` re-expressed in the pancam image of its stop (the chain's last left pancam
    there): a copy of ``N`` whose image is that pancam and whose pixel is ``N``'s point (its stereo point moved onto
    its pixel's ray, site frame) projected into it; its ``xyz_site_m`` is that point. Both cameras are on the mast at
    one stop, so no drive lies between them: the projection carries the navcam pixel's error and the two cameras'
    relative calibration, not a pose error. None when the stop has no left pancam or the point does not project
    into it."""
    import dataclasses

    from ..core.point_stereo import on_left_ray

    pans = dl.images_at(N.position, "pancam", "left")
    if not pans or N.tracked_uv is None or N.xyz_site_m is None:
        return None
    pan = max(pans, key=lambda im: im.time_s)  # the one run_chain tracks at that stop
    nav = dl.product(N.product_id)
    X_nav = on_left_ray(nav.camera_model, np.asarray(N.tracked_uv, float),
                        nav.pose.T_site_rover.inverse().apply(np.asarray(N.xyz_site_m, float)))
    X_site = nav.pose.T_site_rover.apply(X_nav)
    uv = pan.camera_model.project(pan.pose.T_site_rover.inverse().apply(X_site)[None])[0]
    # inside the outermost pixel centres (stricter than the image's extent [-0.5, W - 0.5]): a reference needs
    # pixels on every side to cut its template from
    if not (np.all(np.isfinite(uv)) and 0 <= uv[0] <= pan.width - 1 and 0 <= uv[1] <= pan.height - 1):
        return None
    return dataclasses.replace(N, camera="pancam", product_id=pan.product_id, tracked_uv=[float(x) for x in uv],
                               xyz_site_m=[float(x) for x in X_site])


def closure_check(dl, steps: list, params, feats: Optional[dict] = None) -> Closure:
    """The :class:`Closure` of a chain whose final hazcam handoff is the step with ``extra["final"]``.

    ``dl``: the downlink; ``steps``: the chain's :class:`~scipctl.pipeline.chain.ChainStep` list; ``params``: its
    :class:`~scipctl.pipeline.chain.ChainParams` (the feature step's settings, the hazcam template size); ``feats``:
    the feature step's keypoint cache (None: its own).
    """
    from .feature_track import confirmed_consistency

    final = next((i for i, s in enumerate(steps) if s.camera == "hazcam" and s.extra.get("final")), None)
    if final is None or steps[final].tracked_uv is None:
        return Closure("no final answer")
    ref = closure_reference(steps, final)
    if ref is None:
        return Closure("no reference")
    R, H = steps[ref], steps[final]
    via = None
    if params.closure_pancam_from_navcam and R.camera == "navcam":
        # the pancam image of the same stop resolves the target 3x finer; a confirmed closure from it is taken
        R_pan = pancam_from_navcam(dl, R)
        if R_pan is not None:
            tr, info, scale, pred = track_from_step(dl, R_pan, dl.product(H.product_id), params, feats)
            if pred is not None and info.get("feature_status") == "confirmed":
                R, via = R_pan, "navcam"
    if via is None:
        tr, info, scale, pred = track_from_step(dl, R, dl.product(H.product_id), params, feats)
    if pred is None:
        return Closure("failed", R.product_id, ref)
    out = Closure(info.get("feature_status", "failed"), R.product_id, ref, scale=float(scale), via=via,
                  ncc_peak=info.get("ncc_score"), feature_local_inliers=int(info.get("feature_local_inliers", 0)),
                  feature_confirmed=int(info.get("feature_confirmed", 0)),
                  feature_shift_px=info.get("feature_shift_px"), feature_vo=info.get("feature_vo"),
                  vo_inliers=info.get("vo_inliers"))
    pooled, out.feature_refine_px = confirmed_consistency(info)
    out.feature_pooled = None if math.isnan(pooled) else int(pooled)
    if tr is not None and np.all(np.isfinite(tr.uv)):
        out.uv = [float(x) for x in tr.uv]
        out.closure_px = float(np.linalg.norm(np.asarray(tr.uv) - np.asarray(H.tracked_uv, float)))
    return out


def reference_lineage(steps: list, index) -> list:
    """The step indices whose pixels carried the target to ``steps[index]``: ``index``, then the step it was
    tracked from (its ``extra["reference"]`` product), and so on back to the designation (``steps[0]``, not
    listed); ``[]`` when ``index`` is not a step index or is the designation. A reference that names no step of
    the chain ends the lineage there."""
    if not isinstance(index, int) or not 0 < index < len(steps):
        return []
    by_product = {s.product_id: i for i, s in enumerate(steps)}
    lineage, i = [], index
    while i is not None and 0 < i and i not in lineage:
        lineage.append(i)
        i = by_product.get(steps[i].extra.get("reference"))
    return lineage


def closure_evidence(steps: list, closure: dict):
    """The :class:`~scipctl.core.closure_trust.ClosureEvidence` of a chain's closure (``closure``: a
    :class:`Closure`'s dict, as recorded on the final step); ``steps``: the chain's
    :class:`~scipctl.pipeline.chain.ChainStep` list (its reference step's own ``p_success``)."""
    from ..core.closure_trust import ClosureEvidence

    def num(v):
        return float("nan") if v is None else float(v)

    ref = closure.get("reference_step")
    R = steps[ref] if isinstance(ref, int) and 0 <= ref < len(steps) else None
    # every step that carried the target's pixel from the designation to the reference, scored: the product of
    # their p (a reference far down a drifting chain is only as good as the tracks before it)
    path = [steps[i].p_success for i in reference_lineage(steps, ref)]
    path_p = math.prod(path) if path and all(p is not None for p in path) else None
    # the image the closure started from: the reference's own, or the pancam at a navcam reference's point
    from_pancam = R is not None and (R.camera == "pancam" or closure.get("via") == "navcam")
    return ClosureEvidence(
        ncc_peak=num(closure.get("ncc_peak")), local_inliers=num(closure.get("feature_local_inliers")),
        confirmed=num(closure.get("feature_confirmed")), shift_px=num(closure.get("feature_shift_px")),
        scale=num(closure.get("scale")), from_pancam=float(from_pancam),
        ref_p_success=num(None if R is None else R.p_success), handoff_px=num(closure.get("closure_px")),
        refine_px=num(closure.get("feature_refine_px")), pooled=num(closure.get("feature_pooled")),
        path_p=num(path_p))
