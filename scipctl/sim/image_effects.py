"""Image formation the renderer does not do, applied to finished pixels (pure numerics).

The renderer (:mod:`.render`) box-filters its supersamples, adds shot and read noise and quantises. Real
cameras and downlinks do more, and a scene rendered by someone else's renderer will differ in exactly these
ways. To measure whether an answer (and its trust) depends on them, these functions change an image's pixels
after the fact:

* :func:`optical_blur` -- a Gaussian point-spread function of ``sigma_px`` (an optics' MTF). Applied after the
  noise here, so it also smooths the noise (a real PSF acts before it): a bound on the effect, not a model
  of one camera.
* :func:`companded_jpeg` -- the way MSL and Mars 2020 downlink most images: 12-bit data companded to 8 bits
  by a square-root look-up table, then lossy compression (JPEG ``quality``; the missions use ICER or JPEG),
  expanded back on the ground. 8-bit images are only compressed.
* :func:`tone_curve` -- a camera's response ``out = in ** gamma`` on the normalised scale; a different
  ``gamma`` per eye is a tone mismatch inside a stereo pair, which normalised cross-correlation
  (affine-invariant) does not remove.

Every function takes and returns ``(H, W)`` uint8 or uint16 pixels (uint16: 12-bit data bit-replicated to
16 bits, as :func:`.render.expose` writes and PDS 12-bit products read) and keeps the dtype.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Optional

import numpy as np

from .render import bit_replicate_12

TWELVE_BIT_MAX = 4095


def _check(pixels: np.ndarray) -> np.ndarray:
    px = np.asarray(pixels)
    if px.ndim != 2 or px.dtype not in (np.uint8, np.uint16):
        raise ValueError(f"pixels: expected (H, W) uint8 or uint16, got {px.shape} {px.dtype}")
    return px


def _to_unit(px: np.ndarray) -> np.ndarray:
    """uint8 / uint16 -> float64 in [0, 1] (uint16 on its 12-bit value)."""
    if px.dtype == np.uint8:
        return px.astype(np.float64) / 255.0
    return (px >> 4).astype(np.float64) / TWELVE_BIT_MAX


def _from_unit(x: np.ndarray, dtype) -> np.ndarray:
    """float in [0, 1] -> uint8, or 12-bit data bit-replicated to uint16 (rounded to nearest)."""
    x = np.clip(x, 0.0, 1.0)
    if dtype == np.uint8:
        return np.rint(x * 255.0).astype(np.uint8)
    return bit_replicate_12(np.rint(x * TWELVE_BIT_MAX).astype(np.uint16))


def optical_blur(pixels: np.ndarray, sigma_px: float) -> np.ndarray:
    """``(H, W)`` pixels convolved with a Gaussian of ``sigma_px`` (> 0; reflected borders), same dtype."""
    import cv2

    px = _check(pixels)
    if not (np.isfinite(sigma_px) and sigma_px > 0):
        raise ValueError(f"sigma_px: must be a positive number, got {sigma_px}")
    x = cv2.GaussianBlur(_to_unit(px), (0, 0), float(sigma_px), borderType=cv2.BORDER_REFLECT)
    return _from_unit(x, px.dtype)


def sqrt_compand_lut() -> np.ndarray:
    """``(4096,)`` uint8: 12-bit value -> 8-bit code, ``round(255 * sqrt(v / 4095))``."""
    v = np.arange(TWELVE_BIT_MAX + 1, dtype=np.float64)
    return np.rint(255.0 * np.sqrt(v / TWELVE_BIT_MAX)).astype(np.uint8)


def sqrt_expand_lut() -> np.ndarray:
    """``(256,)`` uint16: 8-bit code -> the 12-bit value at the middle of the values it stands for."""
    lut = sqrt_compand_lut()
    out = np.empty(256, np.uint16)
    v = np.arange(TWELVE_BIT_MAX + 1)
    for c in range(256):
        members = v[lut == c]
        out[c] = int(np.rint(members.mean())) if members.size else int(np.rint(TWELVE_BIT_MAX * (c / 255.0) ** 2))
    return out


def companded_jpeg(pixels: np.ndarray, quality: int) -> np.ndarray:
    """``(H, W)`` pixels after 8-bit square-root companding (uint16 only) and a JPEG round trip of ``quality``
    (1-100, OpenCV's encoder, 4:4:4 grey), same dtype."""
    import cv2

    px = _check(pixels)
    q = int(quality)
    if not 1 <= q <= 100:
        raise ValueError(f"quality: must be in 1..100, got {quality}")
    code = px if px.dtype == np.uint8 else sqrt_compand_lut()[px >> 4]
    ok, buf = cv2.imencode(".jpg", code, [cv2.IMWRITE_JPEG_QUALITY, q])
    if not ok:
        raise ValueError("JPEG encoding failed")
    dec = cv2.imdecode(buf, cv2.IMREAD_GRAYSCALE)
    if px.dtype == np.uint8:
        return dec
    return bit_replicate_12(sqrt_expand_lut()[dec])


def tone_curve(pixels: np.ndarray, gamma: float) -> np.ndarray:
    """``(H, W)`` pixels mapped by ``out = in ** gamma`` on the normalised scale (``gamma`` > 0), same dtype."""
    px = _check(pixels)
    if not (np.isfinite(gamma) and gamma > 0):
        raise ValueError(f"gamma: must be a positive number, got {gamma}")
    return _from_unit(_to_unit(px) ** float(gamma), px.dtype)


@dataclass(frozen=True)
class EffectSpec:
    """What to do to every image, in this order: blur, tone curve, compression. ``None`` skips a stage."""

    blur_sigma_px: Optional[float] = None
    gamma_left: Optional[float] = None
    gamma_right: Optional[float] = None
    jpeg_quality: Optional[int] = None

    def to_dict(self) -> dict:
        return asdict(self)

    def apply(self, pixels: np.ndarray, eye: str) -> np.ndarray:
        """``(H, W)`` pixels of a ``"left"`` or ``"right"`` image -> the changed pixels, same dtype."""
        if eye not in ("left", "right"):
            raise ValueError(f"eye: expected 'left' or 'right', got {eye!r}")
        px = _check(pixels)
        if self.blur_sigma_px is not None:
            px = optical_blur(px, self.blur_sigma_px)
        gamma = self.gamma_left if eye == "left" else self.gamma_right
        if gamma is not None:
            px = tone_curve(px, gamma)
        if self.jpeg_quality is not None:
            px = companded_jpeg(px, self.jpeg_quality)
        return px
