"""PNG encode/decode for image products (OpenCV, imported lazily)."""

from __future__ import annotations

import struct
import zlib

import numpy as np

from ..errors import InputError

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


def png_size(data: bytes, product_id: str) -> tuple[int, int]:
    """``(width, height)`` from a PNG's IHDR, after checking the chunk layout and every chunk's CRC.

    :class:`InputError` ``(product_id, "image", ...)`` unless ``data`` is a complete PNG stream (signature,
    IHDR first, IDAT, IEND) whose CRCs all match. :func:`decode_png` checks this before OpenCV sees the
    bytes: libpng and OpenCV report damaged data by printing to the process's stderr (a second line
    beside the CLI's one-line error), and a CRC catches any damage in transit, cheaply (about 3% of a
    decode). A stream damaged on purpose, with CRCs to match, still reaches libpng.
    """
    if not isinstance(data, (bytes, bytearray, memoryview)) or bytes(data[:8]) != PNG_SIGNATURE:
        raise InputError(product_id, "image", "not PNG data")
    mv = memoryview(data).cast("B")
    n, pos, size, idat = len(mv), 8, None, False
    while True:
        if pos + 12 > n:
            raise InputError(product_id, "image", f"corrupt PNG (truncated: no IEND chunk in {n} bytes)")
        length, ctype = struct.unpack_from(">I4s", mv, pos)
        end = pos + 12 + length
        if not ctype.isalpha():
            raise InputError(product_id, "image", f"corrupt PNG (bad chunk type {ctype!r} at byte {pos})")
        name = ctype.decode("ascii")
        if end > n:
            raise InputError(product_id, "image", f"corrupt PNG (truncated: {name} chunk at byte {pos} runs past the end)")
        if zlib.crc32(mv[pos + 4:end - 4]) != struct.unpack_from(">I", mv, end - 4)[0]:
            raise InputError(product_id, "image", f"corrupt PNG ({name} chunk at byte {pos} fails its CRC)")
        if size is None:
            if name != "IHDR" or length != 13:
                raise InputError(product_id, "image", f"corrupt PNG (starts with a {name} chunk, not IHDR)")
            size = struct.unpack_from(">II", mv, pos + 8)
        idat = idat or name == "IDAT"
        if name == "IEND":
            break
        pos = end
    if not idat:
        raise InputError(product_id, "image", "corrupt PNG (no IDAT chunk)")
    return size


def decode_png(data: bytes, product_id: str) -> np.ndarray:
    """PNG bytes -> ``(H, W)`` uint8/uint16 array; :class:`InputError` naming the product if not a valid single-channel PNG."""
    import cv2

    png_size(data, product_id)  # damaged streams never reach libpng (which would print to stderr)
    bit_depth, colour_type = data[24], data[25]  # IHDR, first (checked by png_size)
    if colour_type == 0 and bit_depth not in (8, 16):  # OpenCV would scale 1/2/4-bit samples to 8 bits, silently
        raise InputError(product_id, "image", f"expected 8- or 16-bit samples, got a {bit_depth}-bit greyscale PNG")
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
