"""Checks of the image and pixel arguments of the core's image functions (pure numerics).

Pixel convention (docs/conventions.md): ``(u, v)`` = (column, row), 0-based,
``(0, 0)`` is the centre of the top-left pixel; an image is indexed
``img[v, u]``. Every ``uv`` here is a ``(2,)`` float array in that convention.
"""

from __future__ import annotations

import numpy as np

__all__ = ["as_float_image", "as_uv", "full_scale"]

#: the largest value of 12-bit data (MER/MSL/Mars 2020 cameras, stored in 16-bit words)
FULL_SCALE_12BIT = 4095


def full_scale(px: np.ndarray) -> tuple[float, int]:
    """``(full-scale value, bits)`` of an image's data: 8-bit for uint8; for 16-bit words, 12-bit data when no value
    exceeds 4095 (the rover cameras' 12-bit samples in 16-bit words: a real label's ``SAMPLE_BIT_MASK`` of 12 ones),
    else 16-bit. A 16-bit image whose data really span 16 bits but stay below 4096 reads as 12-bit: its flags then
    judge it brighter, never darker, than it is."""
    a = np.asarray(px)
    if a.dtype == np.uint8:
        return 255.0, 8
    if int(a.max(initial=0)) <= FULL_SCALE_12BIT:
        return float(FULL_SCALE_12BIT), 12
    return 65535.0, 16


def as_float_image(img, name: str = "image") -> np.ndarray:
    """A single-channel image (``(H, W)``, any real dtype) as contiguous float32; checks the shape."""
    a = np.asarray(img)
    if a.ndim != 2:
        raise ValueError(f"{name}: expected a single-channel (H, W) image, got shape {a.shape}")
    if a.shape[0] < 1 or a.shape[1] < 1:
        raise ValueError(f"{name}: empty image {a.shape}")
    if a.dtype.kind not in "uif" and a.dtype != bool:
        raise ValueError(f"{name}: unsupported dtype {a.dtype}")
    return np.ascontiguousarray(a, dtype=np.float32)


def as_uv(uv, name: str) -> np.ndarray:
    """A pixel ``(u, v)`` (any shape holding two numbers) as a finite ``(2,)`` float array; ``name`` in the error."""
    a = np.asarray(uv, dtype=float).reshape(-1)
    if a.shape != (2,) or not np.all(np.isfinite(a)):
        raise ValueError(f"{name}: expected a finite (u, v) pair, got {uv!r}")
    return a
