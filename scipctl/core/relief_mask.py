"""Which pixels of a template rendered through a plane the plane misplaces, by the stereo of the nearer image.

The chain renders the previous stop's image into the new view through the target's local plane
(pipeline/plane_warp.py). What stands off that plane (a rock beside a target on the ground, the ground beyond the
edge of a rock the target is on) is drawn where the plane would put it, not where the new camera sees it:
parallax, large for small relief at a grazing view (from 10 m, ~9 deg down, to 4.5 m, ~18 deg down, a point 1.4 cm
above the plane moves ~11 pancam pixels against where the plane puts it). Left in the template, such pixels pull
the NCC peak towards where they really are.

The relief is measured by the new image's own dense stereo (the new view is the nearer one: the previous image's
stereo cannot see it; on a synthetic box scene, box pixels the plane misplaced by 3-6 new pixels differed from the
plane by only 0.31-0.46 half-resolution pixels of the previous image's disparity, within SGBM's error). For each
template pixel (a pixel of the new image), the plane's point on its ray is compared with the surface stereo
measures there. The plane is first shifted by the median disagreement at the reference pixels (the template's
centre, the target's own surface: an offset of the whole plane moves the whole window alike). A pixel is kept
when its measured disparity lies within ``disparity_error_px`` (the stereo's error bound) of that shifted plane's,
or when the previous camera would see the measured point (its disparity moved towards the plane's by that bound)
within ``max_parallax_px`` (new pixels, through ``other_px_scale`` new pixels per previous pixel) of the shifted
plane's point, i.e. when the template drew it within that many pixels of where it is. A pixel with no measured
disparity is kept (no evidence either way).
"""

from __future__ import annotations

import numpy as np


def relief_keep(stereo, uv_left, X_plane, T_otherrover_rover, camera_other, reference, disparity_error_px: float,
                max_parallax_px: float, other_px_scale: float = 1.0) -> np.ndarray:
    """``(M,)`` bool: the template pixels that lie where the plane puts them, within ``max_parallax_px``.

    ``stereo``: the :class:`~scipctl.core.dense_stereo.DenseStereo` of the image whose pixels the template's are (its
    models in that image's rover frame); ``uv_left`` ``(M, 2)``: those original left pixels; ``X_plane`` ``(M, 3)``:
    the plane's points on their rays, same frame (NaN rows: not kept); ``T_otherrover_rover``:
    :class:`~scipctl.core.transforms.RigidTransform` from that frame into the rover frame of the image the template
    was rendered from ("other"); ``camera_other``: that image's camera model; ``reference`` ``(M,)`` bool: the pixels
    whose median disagreement is the plane's offset (the template's centre); ``disparity_error_px``: the stereo's
    disparity error bound (its own pixels, >= 0); ``max_parallax_px`` (> 0): in the template's pixels, which are
    ``other_px_scale`` (> 0) per pixel of the other camera.
    """
    uv = np.asarray(uv_left, float)
    X = np.asarray(X_plane, float)
    ref = np.asarray(reference)
    M = len(uv)
    if uv.ndim != 2 or uv.shape[1] != 2 or X.shape != (M, 3) or ref.shape != (M,) or ref.dtype != bool:
        raise ValueError(f"uv_left (M, 2), X_plane (M, 3) and reference (M,) bool expected, got {uv.shape}, "
                         f"{X.shape} and {ref.dtype} {ref.shape}")
    if not (np.isfinite(disparity_error_px) and disparity_error_px >= 0):
        raise ValueError(f"disparity_error_px: must be >= 0, got {disparity_error_px!r}")
    if not (np.isfinite(max_parallax_px) and max_parallax_px > 0):
        raise ValueError(f"max_parallax_px: must be > 0, got {max_parallax_px!r}")
    if not (np.isfinite(other_px_scale) and other_px_scale > 0):
        raise ValueError(f"other_px_scale: must be > 0, got {other_px_scale!r}")
    finite = np.all(np.isfinite(uv), axis=1) & np.all(np.isfinite(X), axis=1)
    keep = np.zeros(M, bool)
    if not finite.any():
        return keep
    rp = stereo.rectified
    A, C = rp.left_model.A, rp.left_model.C
    u, Xf = uv[finite], X[finite]
    d_meas = stereo.disparity_at_rect_uv(rp.left_uv_to_rect(u))
    Z_plane = (Xf - C) @ A
    fb = stereo.focal_baseline_px_m
    with np.errstate(divide="ignore", invalid="ignore"):
        d_plane = fb / Z_plane
        diff = d_meas - d_plane
    r = ref[finite] & np.isfinite(diff)
    offset = float(np.median(diff[r])) if r.any() else 0.0
    rel = diff - offset
    measured = np.isfinite(rel) & (np.abs(rel) > disparity_error_px)
    keep_f = np.ones(len(u), bool)
    if measured.any():
        um, dp = u[measured], d_plane[measured] + offset
        # the disparity within the error bound that is nearest the (shifted) plane's
        d_edge = dp + np.sign(rel[measured]) * (np.abs(rel[measured]) - disparity_error_px)
        o, dirs = rp.orig_left.unproject(um)

        def on_ray(d):  # points on the pixels' rays at disparities d (the stereo's frame)
            with np.errstate(divide="ignore", invalid="ignore"):
                t = (fb / d - (o - C) @ A) / (dirs @ A)
            return o + t[:, None] * dirs

        p_edge = camera_other.project(T_otherrover_rover.apply(on_ray(d_edge)))
        p_surf = camera_other.project(T_otherrover_rover.apply(on_ray(dp)))
        with np.errstate(invalid="ignore"):
            keep_f[measured] = other_px_scale * np.linalg.norm(p_edge - p_surf, axis=1) <= max_parallax_px
    keep[finite] = keep_f & (Z_plane > 0)
    return keep
