"""Pixels of real rover products: label-described arrays and PNG/JPEG pictures -> ``(H, W)`` uint8/uint16."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import InputError


def to_single_channel(arr: np.ndarray, product: str, field_name: str, what: str) -> np.ndarray:
    """``(H, W)``, ``(1, H, W)``, ``(3, H, W)`` or ``(H, W, 3)`` integer pixels -> ``(H, W)`` uint8/uint16.

    Colour (3 bands) becomes luminance (OpenCV RGB->GRAY weights); 12-bit data
    in 16-bit words stays 16-bit. Negative or floating-point samples are an error.
    """
    import cv2

    a = np.asarray(arr)
    if a.ndim == 3 and a.shape[0] in (1, 3) and a.shape[2] not in (1, 3):
        a = np.moveaxis(a, 0, -1)  # band-sequential -> interleaved
    if a.ndim == 3 and a.shape[2] == 1:
        a = a[..., 0]
    if a.dtype.kind == "f":
        raise InputError(product, field_name, f"{what}: floating-point samples are not supported (the downlink carries 8/16-bit images)")
    if a.dtype.kind not in "iu":
        raise InputError(product, field_name, f"{what}: unsupported sample type {a.dtype}")
    if a.size and a.dtype.kind == "i" and int(a.min()) < 0:
        raise InputError(product, field_name, f"{what}: negative sample values (min {int(a.min())})")
    top = int(a.max()) if a.size else 0
    if a.dtype.itemsize == 1:
        a = a.astype(np.uint8)
    elif top <= 0xFFFF:
        a = a.astype(np.uint16)
    else:
        raise InputError(product, field_name, f"{what}: samples above 65535 (max {top})")
    if a.ndim == 3 and a.shape[2] == 3:
        a = cv2.cvtColor(np.ascontiguousarray(a), cv2.COLOR_RGB2GRAY)
    if a.ndim != 2:
        raise InputError(product, field_name, f"{what}: expected one or three bands, got shape {tuple(arr.shape)}")
    return np.ascontiguousarray(a)


def read_picture(path: Path, product: str, field_name: str) -> np.ndarray:
    """A PNG/JPEG picture -> ``(H, W)`` uint8/uint16 (colour as luminance)."""
    import cv2

    img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if img is None:
        raise InputError(product, field_name, f"cannot decode the picture {path.name}")
    if img.ndim == 3 and img.shape[2] == 4:
        img = img[..., :3]
    if img.ndim == 3:
        img = img[..., ::-1]  # OpenCV's BGR -> RGB
    return to_single_channel(img, product, field_name, path.name)
