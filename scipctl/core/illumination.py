"""Images compared for their texture rather than their lighting (pure numerics).

A Lambertian surface's image is albedo x irradiance: ``I = a * s``. Under another sun the irradiance ``s``
changes (shading of the relief, cast shadows) while the albedo ``a`` does not. In the logarithm the two add,
``log I = log a + log s``, and over flat ground ``log s`` is nearly constant except across a shadow's edge (a step
of ``log`` (direct + sky) / sky). :func:`log_highpass` keeps what varies faster than ``sigma_px``: the albedo's
texture, inside a shadow as outside it, and a thin line along each shadow's edge.
"""

from __future__ import annotations

import numpy as np

FLOOR = 1.0 / 255.0  # the log of anything darker is the log of one 8-bit count: noise, not texture


def log_highpass(image: np.ndarray, sigma_px: float, floor: float = FLOOR) -> np.ndarray:
    """``log(max(image, floor))`` minus its Gaussian blur of standard deviation ``sigma_px`` (pixels).

    ``image``: ``(H, W)`` real, non-negative intensities (any positive scale: a gain cancels exactly in the log,
    up to rounding); non-finite pixels count as ``floor`` and stay non-finite in the output. The blur reflects at
    the borders. Returns ``(H, W)`` float32, zero where the image is a constant times a field that is constant over
    a few ``sigma_px``.
    """
    import cv2

    a = np.asarray(image)
    if a.ndim != 2 or a.shape[0] < 2 or a.shape[1] < 2:
        raise ValueError(f"image: expected (H, W) with H, W >= 2, got shape {a.shape}")
    if not (np.isscalar(sigma_px) and np.isfinite(sigma_px) and sigma_px > 0):
        raise ValueError(f"sigma_px: must be a finite number > 0, got {sigma_px!r}")
    if not (np.isscalar(floor) and np.isfinite(floor) and floor > 0):
        raise ValueError(f"floor: must be a finite number > 0, got {floor!r}")
    a = a.astype(np.float32)
    bad = ~np.isfinite(a)
    logi = np.log(np.maximum(np.where(bad, np.float32(floor), a), np.float32(floor)))
    blur = cv2.GaussianBlur(logi, (0, 0), sigmaX=float(sigma_px), sigmaY=float(sigma_px),
                            borderType=cv2.BORDER_REFLECT)
    out = logi - blur
    out[bad] = np.nan
    return out
