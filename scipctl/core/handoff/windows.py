"""Expected hazcam windows built from the navcam image (pure numerics).

* :func:`draped_window` — the navcam image draped over the hazcam stereo
  surface (refined and coarse-fine geometric);
* :func:`plane_window` — the navcam image through the local plane of the
  target (refined-kinematic far, beyond the paper), with
  :func:`nav_plane_normal` fitting that plane;
* :func:`sample_nav` — anti-aliased sampling of the navcam image at navcam
  pixels, :func:`fill_nan` — filling the holes of a window.
"""

from __future__ import annotations

from typing import Optional

import numpy as np

from ..expected import antialiased_sample, drape, map_jacobian, plane_points, project_map
from ..transforms import RigidTransform
from .case import HandoffCase
from .params import HandoffParams
from .steps import local_ifov_rad, project_haz


def draped_window(case: HandoffCase, params: HandoffParams, centre_uv, T_haz_nav: RigidTransform, half: int):
    """Expected hazcam window (2 half + 1)^2 around ``centre_uv``: navcam image draped over hazcam stereo.

    Returns ``(window (2 half + 1, 2 half + 1) float32 or None, draped fraction, window centre pixel (2,))``.
    Beyond the paper (``params.drape_antialias``): the navcam image is low-pass filtered before it is
    sampled (:func:`~scipctl.core.expected.footprint_blur_cov` of the local
    navcam-per-hazcam pixel Jacobian at the window centre), so that a
    navcam finer than the hazcam at the target (near navcams, ~1.5 navcam px
    per hazcam px) is integrated over the hazcam pixel's footprint as the
    hazcam itself does, instead of point-sampled (aliased).
    """
    k = half
    c = np.round(np.asarray(centre_uv, float))
    us, vs = np.meshgrid(np.arange(c[0] - k, c[0] + k + 1), np.arange(c[1] - k, c[1] + k + 1))
    uv = np.stack([us, vs], -1).reshape(-1, 2)
    X_haz = case.haz.xyz_at(uv)
    X_nav = T_haz_nav.inverse().apply(np.where(np.isfinite(X_haz), X_haz, 0.0))
    X_nav[~np.all(np.isfinite(X_haz), axis=1)] = np.nan
    if params.drape_antialias:
        q = project_map(X_nav.reshape(2 * k + 1, 2 * k + 1, 3), case.nav.left_model)
        A = map_jacobian(q)
        vals = sample_nav(case, q, A) if A is not None else drape(X_nav, case.nav.left_model, case.nav.left_img)
    else:
        vals = drape(X_nav, case.nav.left_model, case.nav.left_img)
    vals = np.asarray(vals, np.float32).reshape(2 * k + 1, 2 * k + 1)
    frac = float(np.isfinite(vals).mean())
    return fill_nan(vals), frac, c


def nav_plane_normal(case: HandoffCase, params: HandoffParams, nav_uv, X_nav,
                     half_px: Optional[int] = None) -> Optional[np.ndarray]:
    """Unit normal ``(3,)`` (navcam rover frame) of a plane fitted to the navcam dense points around the target.

    Points on a ``(2 h + 1)^2`` pixel grid around ``nav_uv`` (``h``: the
    hazcam template's size in navcam pixels, from ``far_plane_radius_m``),
    within ``far_plane_radius_m`` of the target ``X_nav`` (3,); least squares
    (SVD), refitted once without the points beyond 3x the median residual.
    None with fewer than 30 points.
    """
    r = params.far_plane_radius_m
    if half_px is None:
        rng = float(np.linalg.norm(X_nav - case.nav.left_model.C))
        half_px = int(np.clip(np.ceil(r / (rng * local_ifov_rad(case.nav.left_model, nav_uv))), 3, 60))
    c = np.asarray(nav_uv, float)
    us, vs = np.meshgrid(np.arange(-half_px, half_px + 1), np.arange(-half_px, half_px + 1))
    uv = c + np.stack([us, vs], -1).reshape(-1, 2)
    P = case.nav.xyz_at(uv)
    P = P[np.all(np.isfinite(P), axis=1)]
    P = P[np.linalg.norm(P - X_nav, axis=1) < r]
    for _ in range(2):
        if len(P) < 30:
            return None
        m = P.mean(axis=0)
        _, _, Vt = np.linalg.svd(P - m, full_matrices=False)
        n = Vt[2]
        res = np.abs((P - m) @ n)
        P = P[res <= max(3.0 * float(np.median(res)), 1e-4)]
    return n / np.linalg.norm(n)


def plane_window(case: HandoffCase, X_haz, n_haz, half: int):
    """Expected hazcam window from the navcam image through the local plane (beyond the paper).

    The ``(2 half + 1)^2`` hazcam pixels around the projection of the target
    ``X_haz`` (3,) are cast onto the plane through it with normal ``n_haz``
    (both in the hazcam rover frame), the plane points projected into the
    navcam (through ``case.T_haz_nav``), and the navcam image sampled there after
    the anti-alias blur of :func:`~scipctl.core.expected.footprint_blur_cov`.
    Returns ``(template, template centre uv (2,), A (2, 2) navcam px per hazcam px)``
    or ``(None, None, None)``.
    """
    centre = project_haz(case, X_haz)
    if not np.all(np.isfinite(centre)):
        return None, None, None
    k = half
    c = np.round(centre)
    us, vs = np.meshgrid(np.arange(c[0] - k, c[0] + k + 1), np.arange(c[1] - k, c[1] + k + 1))
    grid = np.stack([us, vs], -1)
    P = plane_points(case.haz.left_model, grid, X_haz, n_haz)
    q = case.nav.left_model.project(case.T_haz_nav.inverse().apply(P.reshape(-1, 3))).reshape(grid.shape)
    A = np.stack([(q[k, k + 1] - q[k, k - 1]) / 2, (q[k + 1, k] - q[k - 1, k]) / 2], axis=1)
    if not (np.all(np.isfinite(A)) and np.isfinite(q).mean() > 0.9):
        return None, None, None
    vals = sample_nav(case, q, A)
    tpl = fill_nan(vals)
    if tpl is None:
        return None, None, None
    return tpl, centre - (c - k), A


def sample_nav(case: HandoffCase, q: np.ndarray, A: np.ndarray) -> np.ndarray:
    """The navcam-left image at navcam pixels ``q`` (h, w, 2) -> (h, w) float32 (NaN where ``q`` is not finite),
    anti-aliased for ``A`` (2, 2) = d(navcam px)/d(hazcam px) (:func:`~scipctl.core.expected.antialiased_sample`)."""
    return antialiased_sample(case.nav.left_img, q, A)


def fill_nan(img: Optional[np.ndarray]) -> Optional[np.ndarray]:
    """Fill NaN pixels of ``img`` (h, w) with the nearest valid values (repeated 3x3 means) -> (h, w) float32;
    None if under 30 % is valid."""
    import cv2

    a = np.asarray(img, np.float32).copy()
    valid = np.isfinite(a)
    if not valid.any():
        return None
    if valid.mean() < 0.3:
        return None
    for _ in range(64):
        if valid.all():
            break
        num = cv2.boxFilter(np.where(valid, a, 0).astype(np.float32), -1, (3, 3), normalize=False,
                            borderType=cv2.BORDER_CONSTANT)
        den = cv2.boxFilter(valid.astype(np.float32), -1, (3, 3), normalize=False, borderType=cv2.BORDER_CONSTANT)
        grow = ~valid & (den > 0)
        a[grow] = num[grow] / den[grow]
        valid = valid | grow
    return a
