"""Read the pictures a simulator texture is made from (``synth --texture-from DIR``).

Every file under ``DIR`` (recursively, sorted by relative path, hidden files skipped) that is a PNG/JPEG picture
or a product the scipctl readers read (PDS3, VICAR, PDS4 with its data or browse file) becomes a grey picture
(colour as luminance) in fractions of full scale (8-bit: /255; 16-bit holding 12-bit data: /4095; else /65535).
Pictures with the same pixels (a product and its detached label, a raw-image JSON and its PNG) are used once.
Pictures whose crop holds no textured, unsaturated patch are skipped (by
:func:`scipctl.sim.texture.texture_sources_from_pictures`), with the reason recorded. The repository
keeps no copy of any of them; the simulation record lists every file used with its SHA-256.
"""

from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np

from ..core.image import full_scale
from ..model import InputError

PICTURE_SUFFIXES = (".png", ".jpg", ".jpeg")


def _read_one(path: Path, label: str):
    """``(H, W)`` integer pixels, or None if the file is not a picture or product (raises InputError if it is but
    cannot be read)."""
    from .pds_products import read_product_file, sniff
    from .product_pixels import read_picture

    if path.suffix.lower() in PICTURE_SUFFIXES:
        return read_picture(path, label, "pixels")
    kind = sniff(path)
    if kind in ("pds3", "vicar", "pds4"):
        return read_product_file(path, kind).pixels
    return None


def iter_texture_pictures(folder):
    """The pictures under ``folder`` for a simulator texture, in order, lazily: yields ``(name, sha256, pixels)``
    for a picture (``name``: path relative to ``folder``; ``pixels``: ``(H, W)`` float32 fractions of full scale)
    or ``(name, None, reason)`` for a file seen and skipped (unreadable, same pixels as one already given).
    Files that are not pictures or products are passed over in silence.

    :class:`InputError` (naming the folder and ``--texture-from``) if ``folder`` is not a folder.
    :func:`scipctl.sim.texture.texture_sources_from_pictures` chooses the usable ones.
    """
    from .provenance import sha256_file

    root = Path(folder)
    if not root.is_dir():
        raise InputError(str(folder), "--texture-from", "not a folder")
    files = sorted((p for p in root.rglob("*") if p.is_file() and not any(part.startswith(".") for part in p.relative_to(root).parts)),
                   key=lambda p: p.relative_to(root).as_posix())
    seen = set()
    for p in files:
        rel = p.relative_to(root).as_posix()
        try:
            px = _read_one(p, rel)
        except InputError as e:
            yield rel, None, f"unreadable: {e.field}: {e.message}"
            continue
        except Exception as e:  # a reader library's own failure on a damaged file: skip it, say why
            yield rel, None, f"unreadable: {type(e).__name__}: {str(e).splitlines()[0] if str(e) else ''}"
            continue
        if px is None:
            continue  # not a picture or product (labels without data, models, text)
        key = hashlib.sha256(px.tobytes() + repr((px.shape, px.dtype.str)).encode()).hexdigest()
        if key in seen:
            yield rel, None, "same pixels as a file already used"
            continue
        seen.add(key)
        gray = (px.astype(np.float32) / np.float32(full_scale(px)[0])).astype(np.float32)
        yield rel, sha256_file(p), gray
