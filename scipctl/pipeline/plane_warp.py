"""Rendering one image into another's view through a local surface plane (the chain's templates), and the
local surface normals it needs (site frame; each image through its own pose estimate)."""

from __future__ import annotations

from typing import Optional

import numpy as np

from ..model import Downlink, ImageProduct


def near_dense_stereo(dl: Downlink, prod: ImageProduct, range_m: float, downsample: int = 2):
    """Dense stereo of ``prod``'s pair around a target ``range_m`` from its camera (ranges ``max(0.3, 0.6 range)``
    to ``1.6 range + 0.5`` m), at half resolution (``downsample``; the chain's, and its default): a
    :class:`~scipctl.core.dense_stereo.DenseStereo`, or None when ``prod`` has no right eye or stereo fails."""
    from ..core.dense_stereo import dense_stereo

    right = dl.stereo_pair(prod)
    if right is None:
        return None
    try:
        return dense_stereo(prod.pixels_float(), right.pixels_float(), prod.camera_model, right.camera_model,
                            min_range_m=max(0.3, 0.6 * range_m), max_range_m=1.6 * range_m + 0.5,
                            downsample=downsample)
    except Exception:
        return None


def local_normals_site(prod: ImageProduct, X_rover: np.ndarray, range_m: float, stereo):
    """Surface normals (site frame) at ``X_rover`` from ``stereo``, :func:`near_dense_stereo` of ``prod`` around
    ``range_m`` (the caller's, which it also hands to the visual odometry; None: no stereo, no normals).

    Returns ``(local, ground)``: the plane fitted within ``max(0.05, 0.025
    range)`` m (the target's own surface, e.g. a rock face) and within
    ``max(0.2, 0.1 range)`` m (mostly the surrounding ground); each ``(3,)`` or None.
    """
    from .designate import surface_normal

    ds = stereo
    if ds is None:
        return None, None
    xyz = ds.xyz.reshape(-1, 3)
    out = []
    for radius_m in (max(0.05, 0.025 * range_m), max(0.2, 0.1 * range_m)):
        n, npts = surface_normal(xyz, X_rover, radius_m=radius_m)
        out.append(None if n is None else prod.pose.T_site_rover.rotate(n))
    return tuple(out)


# the surrounding ground's plane is tried too when it differs from the target's own by more than this (degrees)
GROUND_PLANE_MIN_DEG = 5.0


def render_planes(prod: ImageProduct, normal, ground) -> tuple[list, np.ndarray]:
    """The planes the feature step renders ``prod`` through, from :func:`local_normals_site`'s ``(normal,
    ground)`` (site frame, each ``(3,)`` or None): ``(planes, n_view)``. ``n_view``, the one the NCC template is
    rendered through, is the target's own surface (else the surrounding ground, else the rover's ground plane at
    ``prod``'s pose estimate, site ``-z`` of the rover); ``planes`` is ``[n_view]``, plus the ground's when it
    differs from ``n_view`` by more than ``GROUND_PLANE_MIN_DEG``."""
    up = prod.pose.T_site_rover.rotate([0.0, 0.0, -1.0])
    n_view = normal if normal is not None else (ground if ground is not None else up)
    planes = [n_view]
    if ground is not None and np.degrees(np.arccos(np.clip(ground @ n_view, -1, 1))) > GROUND_PLANE_MIN_DEG:
        planes.append(ground)
    return planes, n_view


def plane_points_site(prod: ImageProduct, X_site, n_site, uv) -> np.ndarray:
    """Where the rays of ``prod``'s pixels ``uv`` (N, 2) (its camera at its pose estimate) meet the plane through
    ``X_site`` (3,) with normal ``n_site`` (3,), site frame: ``(N, 3)``, NaN where a ray does not meet it in front
    of the camera."""
    o, d = prod.camera_model.unproject(np.asarray(uv, float).reshape(-1, 2))
    T_site_rovernew = prod.pose.T_site_rover
    o_s, d_s = T_site_rovernew.apply(o), T_site_rovernew.rotate(d)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = ((np.asarray(X_site) - o_s) @ n_site) / (d_s @ n_site)
    P_s = o_s + t[:, None] * d_s
    P_s[~(t > 0)] = np.nan
    return P_s


def render_through_plane(prev: ImageProduct, prod: ImageProduct, X_site, n_site, uv, antialias: bool = False) -> np.ndarray:
    """``prev``'s image seen at ``prod``'s pixels ``uv`` (..., 2) through the plane (X_site, n_site), site frame.

    Each pixel's ray (``prod``'s camera at its pose estimate) meets the plane
    through ``X_site`` (3,) with normal ``n_site`` (3,) (:func:`plane_points_site`); the point is projected
    into ``prev`` (its pose estimate) and ``prev``'s image is sampled there
    (bilinear). With ``antialias`` and a grid ``uv`` (h, w, 2), h, w >= 3, whose cells are the rendered pixels,
    ``prev`` is first blurred to the cells' footprint in it (the map's median Jacobian,
    :func:`~scipctl.core.expected.antialiased_sample`): where ``prev`` is the finer view (the closure's 4.5 m
    pancam seen from the hazcam) each rendered pixel averages what the new camera's pixel would, instead of
    point-sampling it; where ``prev`` is the coarser nothing changes. Returns float32 (...) with NaN where ``prev``
    did not see it.
    """
    uv = np.asarray(uv, float)
    uv_prev = prev_pixels_through_plane(prev, prod, X_site, n_site, uv.reshape(-1, 2))
    return _sample_prev(prev, uv_prev.reshape(uv.shape), antialias)


def _sample_prev(prev: ImageProduct, q, antialias: bool) -> np.ndarray:
    """``prev``'s image at its pixels ``q`` (..., 2): bilinear, or with ``antialias`` and a grid (h, w, 2), h, w >= 3,
    blurred to the cells' footprint first (:func:`render_through_plane`). float32 (...), NaN outside."""
    from ..core.expected import antialiased_sample, bilinear_sample, map_jacobian

    if antialias and q.ndim == 3 and min(q.shape[:2]) >= 3:
        A = map_jacobian(q)
        if A is not None:
            return antialiased_sample(prev.pixels_float(), q, A)
    return bilinear_sample(prev.pixels_float(), q)


def render_through_surface(prev: ImageProduct, prod: ImageProduct, X_site, n_site, stereo, uv,
                           disparity_error_px: Optional[float] = None, level: bool = False,
                           antialias: bool = False) -> np.ndarray:
    """``prev``'s image seen at ``prod``'s pixels ``uv`` (h, w, 2) through the surface ``prev``'s dense stereo
    measured (the plane (X_site, n_site) where a ray finds no crossing of it; with ``disparity_error_px`` (its own
    pixels) also where the crossing is within that of the plane): :func:`render_through_plane` with each ray's
    point from :func:`~scipctl.core.surface_raycast.surface_points` (rays of ``prod``'s camera at its pose
    estimate, in ``prev``'s rover frame). ``level``: the stereo first shifted to agree with the plane at the grid's
    central box, a quarter of its width (the chain's choices: ``ChainParams.template_surface_gate_px`` and
    ``template_surface_level``).
    ``stereo``: :func:`near_dense_stereo` of ``prev`` (its models in ``prev``'s rover frame). Returns float32
    (h, w) with NaN where ``prev`` did not see it.
    """
    from ..core.surface_raycast import surface_points

    uv = np.asarray(uv, float)
    if uv.ndim != 3 or uv.shape[-1] != 2:
        raise ValueError(f"uv: expected a grid of pixels (h, w, 2), got shape {uv.shape}")
    h, w = uv.shape[:2]
    flat = uv.reshape(-1, 2)
    T_roverprev_rovernew = prev.pose.T_site_rover.inverse() @ prod.pose.T_site_rover
    o, d = prod.camera_model.unproject(flat)
    o_prev, d_prev = T_roverprev_rovernew.apply(o), T_roverprev_rovernew.rotate(d)
    P_plane = prev.pose.T_site_rover.inverse().apply(plane_points_site(prod, X_site, n_site, flat))
    t_plane = np.einsum("ij,ij->i", P_plane - o_prev, d_prev)
    ii, jj = np.meshgrid(np.arange(h) - (h - 1) / 2, np.arange(w) - (w - 1) / 2, indexing="ij")
    reference = (np.maximum(np.abs(ii), np.abs(jj)) <= max(1, min(h, w) // 8)).reshape(-1) & bool(level)
    P = surface_points(o_prev, d_prev, t_plane, stereo, reference, disparity_error_px)
    return _sample_prev(prev, prev.camera_model.project(P).reshape(uv.shape), antialias)


def prev_pixels_through_plane(prev: ImageProduct, prod: ImageProduct, X_site, n_site, uv) -> np.ndarray:
    """Where ``prod``'s pixels ``uv`` (N, 2) fall in ``prev`` through the plane (X_site, n_site), site frame: each
    ray (``prod``'s camera at its pose estimate) meets the plane (:func:`plane_points_site`) and the point is
    projected into ``prev`` (its pose estimate). ``(N, 2)``, NaN where a ray misses the plane."""
    P_roverprev = prev.pose.T_site_rover.inverse().apply(plane_points_site(prod, X_site, n_site, uv))
    return prev.camera_model.project(P_roverprev)


def plane_warped_view(prev: ImageProduct, prod: ImageProduct, X_site, n_site, centre_uv, half: int,
                      step_px: float = 1.0, antialias: bool = False):
    """``prod``'s view of the window around ``centre_uv`` rendered from ``prev``'s image through a plane.

    See :func:`render_through_plane`. View pixel ``(i, j)`` is ``prod`` pixel
    ``c + step_px * ((i, j) - half)`` with ``c`` = ``centre_uv`` rounded
    (``step_px > 1``: a coarser rendering, e.g. at ``prev``'s own
    resolution). Returns ``(view (2h+1, 2h+1) float32 with NaN where ``prev``
    did not see the plane, centre_in_view_uv (2,))``: ``centre_uv`` in the
    view's pixel coordinates.
    """
    c = np.round(np.asarray(centre_uv, float))
    g = np.arange(-half, half + 1) * float(step_px)
    us, vs = np.meshgrid(c[0] + g, c[1] + g)
    vals = render_through_plane(prev, prod, X_site, n_site, np.stack([us, vs], -1), antialias)
    return vals, (np.asarray(centre_uv, float) - c) / float(step_px) + half


def plane_warped_template(prev: ImageProduct, prod: ImageProduct, X_site, n_site, centre_uv, half: int,
                          antialias: bool = False):
    """The window of ``prod`` around ``centre_uv`` as ``prev`` saw it, through the local plane (X_site, n_site).

    Each template pixel's ray (new camera, new pose estimate) meets the plane;
    the point is projected into the previous image and sampled. Returns
    ``(template (2h+1, 2h+1) float32 or None, template_center_uv (2,))``.
    """
    vals, tc = plane_warped_view(prev, prod, X_site, n_site, centre_uv, half, antialias=antialias)
    if np.isfinite(vals).mean() < 0.9:
        return None, None
    vals = np.where(np.isfinite(vals), vals, np.nanmean(vals)).astype(np.float32)
    return vals, tc
