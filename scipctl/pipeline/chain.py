"""Track a designated target through the stops of an approach (SCIP steps 3 and 5) and hand it
from pancam to navcam, then to the hazcams.

At each rover position (time order) the target's 3-D estimate (site frame,
through the rover's pose estimates) predicts where it appears in the new left
image; the previous stop's window around the target, scaled by the change of
range (and of IFOV at a camera change), is NCC-tracked there; stereo at the
tracked pixel updates the 3-D estimate.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Optional

import numpy as np

from ..model import Downlink, ImageProduct, InputError

TEMPLATE_HALF_PX = {"pancam": 20, "navcam": 15, "hazcam": 15}
SEARCH_RADIUS_PX = {"pancam": 120.0, "navcam": 60.0, "hazcam": 60.0}
BAND_PX = {"pancam": 6.0, "navcam": 3.0, "hazcam": 3.0}
STEREO_WINDOW_PX = {"pancam": 21, "navcam": 21, "hazcam": 21}


@dataclass
class ChainStep:
    position: tuple
    camera: str
    product_id: str
    kind: str  # "designate" | "track" | "handoff"
    predicted_uv: Optional[list]
    tracked_uv: Optional[list]
    mark_uv: Optional[list]
    error_px: Optional[float]
    ncc_peak: Optional[float]
    range_m: Optional[float]
    xyz_site_m: Optional[list]
    truth_xyz_site_m: Optional[list]
    error_3d_m: Optional[float]
    ok: bool
    reason: str = ""
    extra: dict = field(default_factory=dict)

    def to_dict(self):
        d = dict(self.__dict__)
        d["position"] = list(self.position)
        return d


def _f(x):
    try:
        x = float(x)
    except (TypeError, ValueError):
        return None
    return x if np.isfinite(x) else None


def _stereo(dl: Downlink, left: ImageProduct, uv):
    from ..core.stereo import point_stereo

    right = dl.stereo_pair(left)
    if right is None:
        return None
    return point_stereo(left.pixels_float(), right.pixels_float(), left.camera_model, right.camera_model,
                        np.asarray(uv, float), band_px=BAND_PX.get(left.camera, 4.0),
                        window_px=STEREO_WINDOW_PX.get(left.camera, 11))


def run_chain(dl: Downlink, start: ImageProduct, start_uv, target_id: Optional[str] = None,
              handoff_method: str = "pure-geometric") -> list:
    """Follow the target from ``start`` (a left pancam or navcam image) to the last hazcam image.

    Returns the list of :class:`ChainStep`; the last step is the navcam->hazcam
    handoff by ``handoff_method`` (near navcams) when a hazcam pair exists.
    """
    from ..core.tracking import extract_window, scale_window, track, window_scale_for_handoff

    tgt = None
    truth_xyz = None
    if target_id is not None:
        try:
            tgt = dl.target(target_id)
        except InputError:
            tgt = None
        tt = dl.truth_target(target_id)
        truth_xyz = None if tt is None else np.asarray(tt.xyz_site_m, float)

    def mark(prod):
        if tgt is None:
            return None
        m = tgt.mark_in(prod.product_id)
        return None if m is None else [m.u, m.v]

    def step(prod, kind, pred, uv, ps, ncc=None, ok=True, reason="", extra=None):
        mk = mark(prod)
        err = None if (mk is None or uv is None) else float(np.hypot(uv[0] - mk[0], uv[1] - mk[1]))
        xyz_site = None
        e3 = None
        rng = None
        if ps is not None and ps.ok:
            xyz_site = prod.pose.T_site_rover.apply(np.asarray(ps.xyz, float))
            rng = _f(ps.range_m)
            if truth_xyz is not None:
                e3 = float(np.linalg.norm(xyz_site - truth_xyz))
        return ChainStep(prod.position, prod.camera, prod.product_id, kind,
                         None if pred is None else [float(x) for x in pred],
                         None if uv is None else [float(x) for x in uv], mk, err, _f(ncc), rng,
                         None if xyz_site is None else xyz_site.tolist(),
                         None if truth_xyz is None else truth_xyz.tolist(), e3, ok, reason, extra or {})

    steps = []
    uv = np.asarray(start_uv, float)
    ps = _stereo(dl, start, uv)
    if ps is None or not ps.ok:
        reason = "no right eye" if ps is None else ps.reason
        raise InputError(start.product_id, "pixel", f"designation has no stereo: {reason}")
    steps.append(step(start, "designate", None, uv, ps))
    X_site = start.pose.T_site_rover.apply(np.asarray(ps.xyz, float))
    prev, prev_uv, prev_range = start, uv, float(ps.range_m)
    cam = start.camera

    positions = [p for p in dl.positions() if p != start.position]
    positions = [p for p in positions if min(im.time_s for im in dl.images_at(p)) > start.time_s]
    for pos in positions:
        lefts = {im.camera: im for im in sorted(dl.images_at(pos, eye="left"), key=lambda i: i.time_s)}
        order = []
        if cam in lefts:
            order.append(cam)
        if cam == "pancam" and "navcam" in lefts:
            order.append("navcam")
        for c in order:
            prod = lefts[c]
            X_rover = prod.pose.T_site_rover.inverse().apply(X_site)
            pred = prod.camera_model.project(X_rover[None])[0]
            rng_new = float(np.linalg.norm(X_rover - prod.camera_model.C))
            if not np.all(np.isfinite(pred)):
                steps.append(step(prod, "track", None, None, None, ok=False, reason="target behind the camera"))
                continue
            scale = window_scale_for_handoff(1.0 / prev.camera_model.hs, prev_range, 1.0 / prod.camera_model.hs, rng_new)
            half = TEMPLATE_HALF_PX.get(c, 15)
            src_half = max(3, int(np.ceil(half / scale)))
            win = extract_window(prev.pixels_float(), prev_uv, src_half)
            tpl = scale_window(win, scale)
            tr = track(tpl, prod.pixels_float(), pred, SEARCH_RADIUS_PX.get(c, 60.0), min_score=0.3)
            kind = "handoff" if c != prev.camera else "track"
            if not tr.ok or not np.all(np.isfinite(tr.uv)):
                steps.append(step(prod, kind, pred, None, None, tr.score, ok=False, reason=f"track: {tr.reason}"))
                continue
            ps = _stereo(dl, prod, tr.uv)
            ok = ps is not None and ps.ok
            steps.append(step(prod, kind, pred, tr.uv, ps, tr.score, ok=ok,
                              reason="" if ok else ("no right eye" if ps is None else f"stereo: {ps.reason}"),
                              extra={"scale": scale, "ncc_ratio": _f(tr.ratio)}))
            if ok:
                X_site = prod.pose.T_site_rover.apply(np.asarray(ps.xyz, float))
                prev_range = float(ps.range_m)
            else:
                prev_range = rng_new
            prev, prev_uv, cam = prod, tr.uv, c
        if "hazcam" in lefts and cam == "navcam" and prev.position == pos:
            steps.append(_hazcam_handoff(dl, prev, prev_uv, lefts["hazcam"], handoff_method, step))
            break
    return steps


def _hazcam_handoff(dl, nav, nav_uv, haz, method, step):
    from .handoff import build_setup

    setup = build_setup(dl, hazcam=haz.product_id, near=nav.product_id)
    case = setup.cases["near"]
    res = case.run(method, nav_uv)
    uv = res.uv if res.uv is not None and np.all(np.isfinite(res.uv)) else None
    ps = _stereo(dl, haz, uv) if uv is not None else None
    return step(haz, "handoff", None, uv, ps, res.diagnostics.get("ncc_peak"), ok=uv is not None,
                reason=res.reason, extra={"method": method, "navcam": "near"})
