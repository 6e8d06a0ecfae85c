"""Read the pictures a simulator texture is made from (``synth --texture-from DIR``).

Every file under ``DIR`` (recursively, sorted by relative path, hidden files skipped) that is a PNG/JPEG picture
or a product the scipctl readers read (PDS3, VICAR, PDS4 with its data or browse file) becomes a grey picture
(colour as luminance) in fractions of full scale (8-bit: /255; 16-bit holding 12-bit data: /4095; else /65535).
Pictures with the same pixels (a product and its detached label, a raw-image JSON and its PNG) are used once.
Pictures whose crop holds no textured, unsaturated patch are skipped, with the reason recorded. The repository
keeps no copy of any of them; the simulation record lists every file used with its SHA-256.
"""

from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np

from ..model import InputError

PICTURE_SUFFIXES = (".png", ".jpg", ".jpeg")
MAX_IMAGES = 64


def _full_scale(px: np.ndarray) -> float:
    if px.dtype == np.uint8:
        return 255.0
    return 4095.0 if int(px.max(initial=0)) <= 4095 else 65535.0


def _read_one(path: Path, label: str):
    """``(H, W)`` integer pixels, or None if the file is not a picture or product (raises InputError if it is but
    cannot be read)."""
    from .pds_products import read_picture, read_product_file, sniff

    if path.suffix.lower() in PICTURE_SUFFIXES:
        return read_picture(path, label, "pixels")
    kind = sniff(path)
    if kind in ("pds3", "vicar", "pds4"):
        return read_product_file(path, kind).pixels
    return None


def read_texture_sources(folder, crop_frac=None, pixel_m=None):
    """:class:`~scipctl.sim.texture.TextureSources` from the pictures under ``folder``.

    :class:`InputError` (naming the folder and ``--texture-from``) if it is not a folder or holds no usable picture.
    """
    from ..sim.texture import DEFAULT_CROP, TEXTURE_PIXEL_M, TextureImage, TextureSources, usable_reason
    from .provenance import sha256_file

    crop_frac = tuple(DEFAULT_CROP if crop_frac is None else crop_frac)
    pixel_m = TEXTURE_PIXEL_M if pixel_m is None else float(pixel_m)
    root = Path(folder)
    if not root.is_dir():
        raise InputError(str(folder), "--texture-from", "not a folder")
    files = sorted((p for p in root.rglob("*") if p.is_file() and not any(part.startswith(".") for part in p.relative_to(root).parts)),
                   key=lambda p: p.relative_to(root).as_posix())
    images, skipped, seen = [], [], set()
    for p in files:
        rel = p.relative_to(root).as_posix()
        try:
            px = _read_one(p, rel)
        except InputError as e:
            skipped.append((rel, f"unreadable: {e.field}: {e.message}"))
            continue
        except Exception as e:  # a reader library's own failure on a damaged file: skip it, say why
            skipped.append((rel, f"unreadable: {type(e).__name__}: {str(e).splitlines()[0] if str(e) else ''}"))
            continue
        if px is None:
            continue  # not a picture or product (labels without data, models, text)
        key = hashlib.sha256(px.tobytes() + repr((px.shape, px.dtype.str)).encode()).hexdigest()
        if key in seen:
            skipped.append((rel, "same pixels as a file already used"))
            continue
        seen.add(key)
        gray = (px.astype(np.float32) / np.float32(_full_scale(px))).astype(np.float32)
        why = usable_reason(gray, crop_frac)
        if why:
            skipped.append((rel, why))
            continue
        if len(images) >= MAX_IMAGES:
            skipped.append((rel, f"beyond the first {MAX_IMAGES} usable pictures"))
            continue
        images.append(TextureImage(rel, sha256_file(p), gray))
    if not images:
        detail = "; ".join(f"{n}: {r}" for n, r in skipped[:3])
        raise InputError(str(folder), "--texture-from", "no usable picture (PNG/JPEG or PDS3/VICAR/PDS4 product with a textured "
                         f"crop of at least 128 x 128 px){' -- ' + detail if detail else ''}")
    return TextureSources(str(folder), tuple(images), crop_frac, pixel_m, tuple(skipped))
