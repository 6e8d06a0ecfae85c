"""Designate a 3-D target from a pixel in a left stereo image (SCIP step 1)."""

from __future__ import annotations

from typing import Optional

import numpy as np

from ..core.point_stereo import PointStereoParams
from ..jsonutil import finite_or_none
from ..model import Downlink, ImageProduct, InputError

EDGE_MARGIN_PX = 20  # a designation closer than this to the image edge is warned about


def pick_left_product(dl: Downlink, product_id: Optional[str], camera: Optional[str]) -> ImageProduct:
    if product_id:
        p = dl.product(product_id)
    elif camera:
        cands = [im for im in dl.images if im.camera == camera and im.eye == "left"]
        if not cands:
            raise InputError(dl.source or "downlink", "camera", f"no left {camera} image in the downlink")
        p = max(cands, key=lambda im: im.time_s)
    else:
        raise InputError("designate", "--product", "give --product PRODUCT_ID or --camera NAME")
    if p.eye != "left":
        raise InputError(p.product_id, "eye", "designate from a left-eye image (the right eye is matched by stereo)")
    return p


def parse_pixel(text: str) -> np.ndarray:
    try:
        parts = [float(x) for x in str(text).replace(" ", "").split(",")]
    except ValueError:
        raise InputError("--pixel", "pixel", f"expected U,V numbers, got {text!r}") from None
    if len(parts) != 2 or not all(np.isfinite(parts)):
        raise InputError("--pixel", "pixel", f"expected two finite numbers U,V, got {text!r}")
    return np.array(parts)


def surface_normal(xyz: np.ndarray, centre: np.ndarray, radius_m: float) -> tuple[Optional[np.ndarray], int]:
    """Plane-fit normal ``(3,)`` of points ``(N, 3)`` within ``radius_m`` of ``centre``; oriented up (-z, rover frame)."""
    pts = xyz[np.all(np.isfinite(xyz), axis=1)]
    pts = pts[np.linalg.norm(pts - centre, axis=1) < radius_m]
    if len(pts) < 10:
        return None, len(pts)
    c = pts.mean(axis=0)
    _, _, vt = np.linalg.svd(pts - c, full_matrices=False)
    n = vt[-1]
    if n[2] > 0:
        n = -n
    return n, len(pts)


def designate(dl: Downlink, left: ImageProduct, uv, target_id: str = "t1", with_normal: bool = True,
              params: Optional[PointStereoParams] = None) -> dict:
    """Point stereo at ``uv`` in ``left``; returns the designation record (raises InputError).

    ``params``: the per-camera band and window (default :class:`PointStereoParams`, checked; an operator's
    ``--band-px`` is :meth:`PointStereoParams.with_band`).
    """
    from ..core.point_stereo import point_stereo

    params = (params or PointStereoParams()).check()
    uv = np.asarray(uv, float)
    if not (-0.5 <= uv[0] <= left.width - 0.5 and -0.5 <= uv[1] <= left.height - 0.5):
        raise InputError(left.product_id, "pixel", f"({uv[0]:g}, {uv[1]:g}) is outside the {left.width}x{left.height} image")
    right = dl.stereo_pair(left)
    if right is None:
        raise InputError(left.product_id, "eye", f"no right-eye {left.camera} image taken with it: cannot do stereo")
    band = float(params.band(left.camera))
    win = params.window(left.camera)
    L = left.pixels_float()
    R = right.pixels_float()
    ps = point_stereo(L, R, left.camera_model, right.camera_model, uv, band_px=band, window_px=win)
    warnings = []
    k = win // 2 + 1
    patch = L[max(0, int(uv[1]) - k):int(uv[1]) + k + 1, max(0, int(uv[0]) - k):int(uv[0]) + k + 1]
    if patch.size and float((patch >= 0.999).mean()) > 0.05:
        warnings.append("saturated pixels in the window")
    if patch.size and float(patch.std()) < 0.01:
        warnings.append("low texture")
    if min(uv[0], uv[1], left.width - 1 - uv[0], left.height - 1 - uv[1]) < EDGE_MARGIN_PX:
        warnings.append("near the image edge")
    rec = {
        "id": target_id,
        "product_id": left.product_id,
        "right_product_id": right.product_id,
        "camera": left.camera,
        "position": {"site": left.site, "drive": left.drive},
        "pixel_uv": uv.tolist(),
        "band_px": band,
        "ok": bool(ps.ok),
        "reason": ps.reason,
        "match_score": _f(ps.score),
        "match_ratio": _f(getattr(ps, "ratio", None)),
        "uv_right": None if ps.uv_right is None else [float(x) for x in ps.uv_right],
        "epipolar_offset_px": _f(ps.epipolar_offset_px),
        "warnings": warnings,
    }
    if not ps.ok:
        return rec
    X_rover = np.asarray(ps.xyz, float)
    X_site = left.pose.T_site_rover.apply(X_rover)
    rec.update({
        "xyz_rover_m": X_rover.tolist(),
        "xyz_site_m": X_site.tolist(),
        "range_m": _f(ps.range_m),
        "range_sigma_m": _f(ps.range_sigma_m),
        "ray_miss_m": _f(getattr(ps, "miss_distance_m", None)),
        "pose": {"position_m": left.pose.position_m.tolist(), "orientation_wxyz": left.pose.orientation_wxyz.tolist(),
                 "source": left.pose.source},
    })
    if with_normal:
        from ..core.dense_stereo import dense_stereo

        try:
            ds = dense_stereo(L, R, left.camera_model, right.camera_model,
                              min_range_m=max(0.3, 0.5 * ps.range_m), max_range_m=2.0 * ps.range_m + 1.0)
            xyz = ds.xyz.reshape(-1, 3)
            n, npts = surface_normal(xyz, X_rover, radius_m=max(0.05, 0.02 * ps.range_m))
        except Exception as e:  # dense stereo is a diagnostic here; the designation stands without it
            n, npts = None, 0
            warnings.append(f"no surface normal (dense stereo failed: {e})")
        rec["surface_normal_rover"] = None if n is None else n.tolist()
        rec["normal_points"] = npts
        if n is None and npts < 10:
            warnings.append("no surface normal (too few dense-stereo points around the target)")
        else:
            ray = X_rover - left.camera_model.C
            ray /= np.linalg.norm(ray)
            rec["incidence_deg"] = float(np.degrees(np.arccos(abs(float(np.dot(ray, n))))))
    return rec


_f = finite_or_none
