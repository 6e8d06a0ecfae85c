"""Matched blur: make a sharp image as blurred as a template rendered from a coarser view of the same surface.

A template rendered from an earlier, farther image (``pipeline/plane_warp.render_through_plane``: bilinear samples
of that image) carries that image's pixel footprint, seen through the map from the new image's pixels to the earlier
image's. Near a point the map is linear, ``J_prev_new`` (2, 2): d(prev px) / d(new px). A prev pixel's box
(variance 1/12 px^2 per axis) plus the bilinear kernel's (1/6) is a blur of covariance ``0.25 I`` prev px^2, i.e.
``J^-1 (0.25 I) J^-T`` new px^2: anisotropic when the earlier view saw the surface at a grazing angle (ground at
10 m: ~5x coarser along the range than at 4.5 m, ~2.2x across it). The new image already has its own pixel's 1/12;
the rest is the blur to add before NCC, so both sides have the same resolution (NCC between a smooth template and an
image with detail the template cannot have scores low and is drawn to that detail).
"""

from __future__ import annotations

import math

import numpy as np

#: variance (prev px^2 per axis) of a bilinearly sampled pixel's footprint: the box (1/12) plus the triangle (1/6)
SOURCE_VAR_PX2 = 0.25
#: variance (px^2 per axis) the new image's own pixel box already has
OWN_VAR_PX2 = 1.0 / 12.0
#: blurs whose largest standard deviation is below this are not applied (px)
MIN_SIGMA_PX = 0.3


def footprint_cov(J_prev_new, source_var_px2: float = SOURCE_VAR_PX2, own_var_px2: float = OWN_VAR_PX2):
    """The blur (2, 2) covariance, new px^2, that brings the new image to the template's resolution.

    ``J_prev_new`` (2, 2): the Jacobian of the map new pixel -> previous pixel at the target. Returns the positive
    semi-definite part of ``J^-1 (source_var I) J^-T - own_var I`` (eigenvalues below zero set to zero), or None
    when ``J`` is not finite or singular.
    """
    J = np.asarray(J_prev_new, float)
    if J.shape != (2, 2):
        raise ValueError(f"J_prev_new: expected shape (2, 2), got {J.shape}")
    if not np.all(np.isfinite(J)) or abs(np.linalg.det(J)) < 1e-12:
        return None
    Ji = np.linalg.inv(J)
    C = source_var_px2 * (Ji @ Ji.T) - own_var_px2 * np.eye(2)
    w, V = np.linalg.eigh(0.5 * (C + C.T))
    return (V * np.clip(w, 0.0, None)) @ V.T


def gaussian_kernel(cov, max_sigma_px: float) -> np.ndarray | None:
    """A normalised (k, k) float32 kernel of the 2-D Gaussian with covariance ``cov`` (2, 2) (x = u across, y = v
    down), k = 2 ceil(3 sigma_max) + 1; None when its largest sigma is below :data:`MIN_SIGMA_PX`. A direction of
    zero variance gets a floor of 0.05 px^2 (a kernel one pixel wide there); no direction's sigma exceeds
    ``max_sigma_px`` (a plane seen edge-on has an unbounded footprint; the caller passes a third of its template's
    half-size, so that the kernel is never wider than the template: beyond that the template is flat along that
    direction and more blur changes nothing NCC can use)."""
    if not (max_sigma_px > 0 and math.isfinite(max_sigma_px)):
        raise ValueError(f"max_sigma_px: must be a positive number, got {max_sigma_px!r}")
    C = np.asarray(cov, float)
    w, V = np.linalg.eigh(C)
    if not np.all(np.isfinite(w)) or math.sqrt(max(w.max(), 0.0)) < MIN_SIGMA_PX:
        return None
    w = np.clip(w, 0.05, max_sigma_px ** 2)
    r = int(math.ceil(3.0 * math.sqrt(w.max())))
    g = np.arange(-r, r + 1, dtype=float)
    X = np.stack(np.meshgrid(g, g), -1)  # (k, k, 2): (u, v)
    Ci = (V / w) @ V.T
    q = np.einsum("...i,ij,...j->...", X, Ci, X)
    K = np.exp(-0.5 * q)
    return (K / K.sum()).astype(np.float32)


def blurred_crop(image, center_uv, reach_px: int, kernel, align: int = 64):
    """The part of ``image`` (H, W) within ``reach_px`` (plus the kernel's radius) of ``center_uv`` (2,), blurred by
    ``kernel`` (edges replicated), as ``(crop float32 (h, w), origin_uv (2,))``: image pixel = crop pixel + origin;
    ``(None, origin)`` when that region lies wholly outside the image. The origin is a multiple of ``align`` (a
    tracker's pyramid stays aligned with the whole image's). (:func:`~scipctl.core.windows.filtered_crop` with the
    blur.)"""
    import cv2

    from .windows import filtered_crop

    return filtered_crop(image, center_uv, reach_px, kernel.shape[0],
                         lambda c: cv2.filter2D(c, cv2.CV_32F, kernel, borderType=cv2.BORDER_REPLICATE), align)
