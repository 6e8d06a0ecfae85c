"""PNG encode/decode for image products (OpenCV, imported lazily)."""

from __future__ import annotations

import numpy as np

from ..model import InputError


def decode_png(data: bytes, product_id: str) -> np.ndarray:
    """PNG bytes -> ``(H, W)`` uint8/uint16 array; :class:`InputError` naming the product if not a valid single-channel PNG."""
    import cv2

    if not isinstance(data, (bytes, bytearray, memoryview)) or len(data) < 8 or bytes(data[:8]) != b"\x89PNG\r\n\x1a\n":
        raise InputError(product_id, "image", "not PNG data")
    arr = np.frombuffer(bytes(data), dtype=np.uint8)
    img = cv2.imdecode(arr, cv2.IMREAD_UNCHANGED)
    if img is None:
        raise InputError(product_id, "image", "corrupt PNG (cannot be decoded)")
    if img.ndim != 2:
        raise InputError(product_id, "image", f"expected a single-channel image, got {img.shape[2]} channels")
    if img.dtype not in (np.uint8, np.uint16):
        raise InputError(product_id, "image", f"expected 8- or 16-bit pixels, got {img.dtype}")
    return img


def encode_png(pixels: np.ndarray) -> bytes:
    """``(H, W)`` uint8/uint16 -> PNG bytes (deterministic)."""
    import cv2

    if pixels.ndim != 2 or pixels.dtype not in (np.uint8, np.uint16):
        raise ValueError(f"pixels: expected (H, W) uint8/uint16, got {pixels.shape} {pixels.dtype}")
    ok, buf = cv2.imencode(".png", pixels, [cv2.IMWRITE_PNG_COMPRESSION, 6])
    if not ok:
        raise ValueError("PNG encoding failed")
    return buf.tobytes()
