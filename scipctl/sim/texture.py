"""Real Mars texture draped on the simulated terrain (pure numerics; ``io/texture_sources.py`` reads the files,
:func:`texture_sources_from_pictures` chooses among the pictures).

The texture is a property of the **surface**, not of an image: a periodic atlas of relative albedo
``tex(x, y)`` (dimensionless, mean ~0) in the site plane, sampled at every ray hit on the terrain, so every view
of the same ground sees the same texture. The soil's albedo becomes ``base(x, y) (1 + tex(x, y))`` (``base``: the
procedural soil/sand level and metre-scale patchiness, unchanged); ``tex`` replaces the procedural soil grain and
specks. Drift sand and rocks keep their procedural albedo.

Building the atlas (:func:`build_surface_texture`), seeded by the scene seed:

1. Each source image ``I`` (``(H, W)``, fractions of full scale) becomes relative contrast
   ``C = I / G_sigma(I) - 1`` (``G_sigma``: Gaussian blur, ``HIGHPASS_SIGMA_PX`` = 12 px): illumination
   gradients and vignetting divide out, grain, pebbles and specks stay (clipped to [-0.9, 2]).
2. Only a crop of each image is used (``crop_frac`` = (x0, y0, x1, y1) fractions; default the lower middle of
   the frame: ground, away from the sky above and the rover's deck/wheels at the bottom edge). Patches of
   ``PATCH_PX`` x ``PATCH_PX`` are drawn at random inside the crop (random source, place, 90-degree rotation and
   mirror); a patch touching saturated or black pixels (> 1 %) or with contrast std < 0.02 (sky, blank) is
   redrawn.
3. Patches are laid on a periodic grid of ``STRIDE_PX`` cells (``CELLS`` x ``CELLS``; 2016 px = 5.04 m at
   2.5 mm/px) and blended with separable trapezoid weights (ramps over the 32 px overlap), divided by
   ``sqrt(sum w^2)`` so the blend keeps the sources' variance. Each patch's core (``PATCH_PX - 2 overlap``
   square) is exactly the source's contrast there (tested).
4. A Gaussian (mip) pyramid, built with wrap-around borders: samples whose surface footprint is larger than a
   texture pixel read the level whose pixel matches it (trilinear), so the texture is anti-aliased like the
   procedural octaves.

Scale: one texture pixel is ``pixel_m`` on the ground (default 2.5 mm, a navcam's pixel at ~3 m). The source
frames are perspective views, so their ground sampling varies over the crop and rows are foreshortened; the
texture keeps those statistics (it is "real image texture", not an orthophoto). Shading of small relief in the
sources is baked into ``tex``.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass, field

import numpy as np

TEXTURE_PIXEL_M = 0.0025
PATCH_PX = 128
STRIDE_PX = 96
OVERLAP_PX = PATCH_PX - STRIDE_PX
CELLS = 21
HIGHPASS_SIGMA_PX = 12.0
DEFAULT_CROP = (0.1, 0.55, 0.9, 0.92)  # x0, y0, x1, y1 fractions of the width / height
CONTRAST_RANGE = (-0.9, 2.0)
MIN_PATCH_STD = 0.02
MAX_BAD_FRACTION = 0.01
DRAWS_PER_CELL = 60
MAX_IMAGES = 64  # usable source pictures at most


@dataclass(frozen=True)
class TextureImage:
    """One source picture: ``name`` (path relative to the source folder), ``sha256`` of the file, ``pixels``
    ``(H, W)`` float32 fractions of full scale (0 .. 1)."""

    name: str
    sha256: str
    pixels: np.ndarray = field(repr=False)


@dataclass(frozen=True)
class TextureSources:
    """The pictures a texture is made from, the crop used in each, and the ground size of a texture pixel."""

    source_dir: str
    images: tuple  # TextureImage, sorted by name
    crop_frac: tuple = DEFAULT_CROP
    pixel_m: float = TEXTURE_PIXEL_M
    skipped: tuple = ()  # ((name, reason), ...) files seen but not used

    @property
    def digest(self) -> str:
        """SHA-256 over what determines the texture (file hashes, crop, pixel size)."""
        h = hashlib.sha256()
        for im in self.images:
            h.update(f"{im.name}\0{im.sha256}\n".encode())
        h.update(repr((tuple(float(c) for c in self.crop_frac), float(self.pixel_m))).encode())
        return h.hexdigest()

    def to_record(self) -> dict:
        return {"source_dir": self.source_dir, "crop_frac": [float(c) for c in self.crop_frac], "pixel_m": self.pixel_m,
                "digest": self.digest,
                "files": [{"file": im.name, "sha256": im.sha256, "shape": list(im.pixels.shape)} for im in self.images],
                "skipped": [{"file": n, "reason": r} for n, r in self.skipped]}


def relative_contrast(pixels: np.ndarray, sigma_px: float = HIGHPASS_SIGMA_PX) -> np.ndarray:
    """``(H, W)`` picture -> ``(H, W)`` float32 ``I / blur(I) - 1`` clipped to ``CONTRAST_RANGE``."""
    import cv2

    img = np.asarray(pixels, np.float32)
    low = cv2.GaussianBlur(img, (0, 0), sigma_px, borderType=cv2.BORDER_REFLECT)
    c = img / np.maximum(low, np.float32(1e-3)) - np.float32(1.0)
    return np.clip(c, *CONTRAST_RANGE).astype(np.float32)


def crop_box_px(shape, crop_frac) -> tuple[int, int, int, int]:
    """``(row0, row1, col0, col1)`` of the crop of an image of ``shape`` ``(H, W)``."""
    H, W = shape[:2]
    x0, y0, x1, y1 = crop_frac
    return int(round(y0 * H)), int(round(y1 * H)), int(round(x0 * W)), int(round(x1 * W))


def _bad_mask(pixels: np.ndarray) -> np.ndarray:
    return (pixels <= 1.0 / 255.0) | (pixels >= 0.985)


def _patch_ok(contrast: np.ndarray, bad: np.ndarray, r0: int, c0: int) -> bool:
    b = bad[r0:r0 + PATCH_PX, c0:c0 + PATCH_PX]
    if b.mean() > MAX_BAD_FRACTION:
        return False
    return float(contrast[r0:r0 + PATCH_PX, c0:c0 + PATCH_PX].std()) >= MIN_PATCH_STD


def _grid_patches(contrast: np.ndarray, bad: np.ndarray, box) -> list:
    """Top-left corners ``[(row, col)]`` of the usable patches on a 4 x 6 grid over the crop ``box``."""
    r0, r1, c0, c1 = box
    if r1 - r0 < PATCH_PX or c1 - c0 < PATCH_PX:
        return []
    return [(int(r), int(c)) for r in np.linspace(r0, r1 - PATCH_PX, 4).astype(int)
            for c in np.linspace(c0, c1 - PATCH_PX, 6).astype(int) if _patch_ok(contrast, bad, int(r), int(c))]


def usable_reason(pixels: np.ndarray, crop_frac) -> str:
    """``""`` if the crop of ``pixels`` ``(H, W)`` holds a usable patch, else why not (one line)."""
    box = crop_box_px(pixels.shape, crop_frac)
    r0, r1, c0, c1 = box
    if r1 - r0 < PATCH_PX or c1 - c0 < PATCH_PX:
        return f"crop {c1 - c0} x {r1 - r0} px is smaller than a {PATCH_PX} px patch"
    if not _grid_patches(relative_contrast(pixels), _bad_mask(pixels), box):
        return "no patch of the crop is textured and unsaturated"
    return ""


def texture_sources_from_pictures(source_dir: str, pictures, crop_frac=None, pixel_m=None) -> TextureSources:
    """:class:`TextureSources` from ``pictures``, an iterable of ``(name, sha256, pixels)`` (``pixels`` ``(H, W)``
    float32 fractions of full scale) or ``(name, None, reason)`` for a file skipped before
    (:func:`scipctl.io.texture_sources.iter_texture_pictures`), in order.

    A picture whose crop holds no usable patch (:func:`usable_reason`) is skipped with the reason, as is any beyond
    the first ``MAX_IMAGES`` usable ones. :class:`InputError` naming
    ``source_dir`` and ``--texture-from`` if no picture is usable.
    """
    from ..errors import InputError

    crop_frac = tuple(DEFAULT_CROP if crop_frac is None else crop_frac)
    pixel_m = TEXTURE_PIXEL_M if pixel_m is None else float(pixel_m)
    images, skipped = [], []
    for name, sha256, pixels in pictures:
        if sha256 is None:
            skipped.append((name, pixels))
            continue
        why = usable_reason(pixels, crop_frac)
        if why:
            skipped.append((name, why))
            continue
        if len(images) >= MAX_IMAGES:
            skipped.append((name, f"beyond the first {MAX_IMAGES} usable pictures"))
            continue
        images.append(TextureImage(name, sha256, pixels))
    if not images:
        detail = "; ".join(f"{n}: {r}" for n, r in skipped[:3])
        raise InputError(str(source_dir), "--texture-from", "no usable picture (PNG/JPEG or PDS3/VICAR/PDS4 product with a "
                         f"textured crop of at least 128 x 128 px){' -- ' + detail if detail else ''}")
    return TextureSources(str(source_dir), tuple(images), crop_frac, pixel_m, tuple(skipped))


@dataclass(frozen=True)
class PlacedPatch:
    """A source patch in the atlas: source image index, top-left pixel in the source, rotation (k x 90 deg,
    ``np.rot90``, applied after the mirror ``fliplr`` when ``mirror``), top-left pixel in the atlas."""

    source: int
    row0: int
    col0: int
    rot90: int
    mirror: bool
    atlas_row0: int
    atlas_col0: int


def patch_pixels(src: np.ndarray, p: PlacedPatch) -> np.ndarray:
    """The ``(PATCH_PX, PATCH_PX)`` patch ``p`` of the source array ``src`` as it lies in the atlas."""
    a = src[p.row0:p.row0 + PATCH_PX, p.col0:p.col0 + PATCH_PX]
    if p.mirror:
        a = a[:, ::-1]
    return np.rot90(a, p.rot90)


def _ramp() -> np.ndarray:
    k = np.arange(PATCH_PX) + 0.5
    return (np.clip(k / OVERLAP_PX, 0, 1) * np.clip((PATCH_PX - k) / OVERLAP_PX, 0, 1)).astype(np.float64)


@dataclass
class SurfaceTexture:
    """The relative-albedo atlas on the site plane: level ``l`` of ``levels`` is ``(n / 2^l, n / 2^l)`` float32 with
    pixel ``pixel_m * 2^l``; atlas row = site x / pixel, column = site y / pixel, periodic."""

    pixel_m: float
    levels: list = field(repr=False)
    patches: tuple = field(repr=False)
    seed: int = 0
    digest: str = ""

    @property
    def period_m(self) -> float:
        return self.levels[0].shape[0] * self.pixel_m

    def atlas_rc(self, xy: np.ndarray) -> np.ndarray:
        """Site ``xy`` ``(N, 2)`` -> continuous level-0 atlas (row, col) ``(N, 2)`` (pixel centres at integers)."""
        return np.asarray(xy, np.float64) / self.pixel_m

    @staticmethod
    def _bilinear_wrap(L: np.ndarray, r: np.ndarray, c: np.ndarray) -> np.ndarray:
        n = L.shape[0]
        r0 = np.floor(r)
        c0 = np.floor(c)
        fr = (r - r0).astype(np.float32)
        fc = (c - c0).astype(np.float32)
        i0 = r0.astype(np.int64) % n
        j0 = c0.astype(np.int64) % n
        i1 = (i0 + 1) % n
        j1 = (j0 + 1) % n
        top = L[i0, j0] * (1 - fc) + L[i0, j1] * fc
        bot = L[i1, j0] * (1 - fc) + L[i1, j1] * fc
        return top * (1 - fr) + bot * fr

    def sample(self, xy: np.ndarray, footprint_m=None) -> np.ndarray:
        """``tex`` at site ``xy`` ``(N, 2)`` -> ``(N,)`` float32; ``footprint_m`` ``(N,)`` picks the pyramid level
        (trilinear) whose pixel matches the sample's footprint; None: full detail."""
        rc = self.atlas_rc(xy)
        N = len(rc)
        if footprint_m is None:
            return self._bilinear_wrap(self.levels[0], rc[:, 0], rc[:, 1]).astype(np.float32)
        fp = np.asarray(footprint_m, np.float64)
        lev = np.clip(np.log2(np.maximum(fp, 1e-12) / self.pixel_m), 0, len(self.levels) - 1)
        lev = np.where(np.isfinite(lev), lev, len(self.levels) - 1)
        l0 = np.floor(lev).astype(int)
        frac = (lev - l0).astype(np.float32)
        out = np.zeros(N, np.float32)
        for l in np.unique(l0):
            sel = np.flatnonzero(l0 == l)
            s = 2.0 ** l
            # cv2.pyrDown keeps the even pixels of the blurred level: level-l pixel i sits at level-0 coordinate 2^l i
            a = self._bilinear_wrap(self.levels[l], rc[sel, 0] / s, rc[sel, 1] / s)
            if l + 1 < len(self.levels):
                b = self._bilinear_wrap(self.levels[l + 1], rc[sel, 0] / (2 * s), rc[sel, 1] / (2 * s))
                a = a * (1 - frac[sel]) + b * frac[sel]
            out[sel] = a
        return out

    def to_record(self) -> dict:
        return {"atlas_px": int(self.levels[0].shape[0]), "period_m": self.period_m, "patch_px": PATCH_PX,
                "stride_px": STRIDE_PX, "highpass_sigma_px": HIGHPASS_SIGMA_PX, "atlas_seed": int(self.seed),
                "n_patches": len(self.patches),
                "patches_per_source": np.bincount([p.source for p in self.patches]).tolist()}


def _pyr_down_wrap(L: np.ndarray) -> np.ndarray:
    import cv2

    pad = 8
    big = np.pad(L, pad, mode="wrap")
    d = cv2.pyrDown(big)
    return np.ascontiguousarray(d[pad // 2:-(pad // 2), pad // 2:-(pad // 2)], np.float32)


def build_surface_texture(sources: TextureSources, seed: int, cells: int = CELLS) -> SurfaceTexture:
    """The atlas of ``sources`` for a scene: deterministic in (the sources' pixels, crop, ``seed``).

    Raises ``ValueError`` if no source has a usable patch.
    """
    if not sources.images:
        raise ValueError("texture: no source images")
    rng = np.random.default_rng(np.random.SeedSequence([int(seed) & 0xFFFFFFFF, 0x7E47]))
    contrast = [relative_contrast(im.pixels) for im in sources.images]
    bad = [_bad_mask(im.pixels) for im in sources.images]
    boxes = [crop_box_px(im.pixels.shape, sources.crop_frac) for im in sources.images]
    grid = [_grid_patches(contrast[i], bad[i], boxes[i]) for i in range(len(boxes))]
    usable = [i for i in range(len(boxes)) if grid[i]]
    if not usable:
        raise ValueError(f"texture: no source crop holds a textured, unsaturated {PATCH_PX} x {PATCH_PX} px patch")
    n = cells * STRIDE_PX
    acc = np.zeros((n, n), np.float64)
    wsum2 = np.zeros((n, n), np.float64)
    w1 = _ramp()
    W = np.outer(w1, w1)
    placed = []
    for ci in range(cells):
        for cj in range(cells):
            p = None
            for _ in range(DRAWS_PER_CELL):
                s = usable[int(rng.integers(len(usable)))]
                r0, r1, c0, c1 = boxes[s]
                rr = int(rng.integers(r0, r1 - PATCH_PX + 1))
                cc = int(rng.integers(c0, c1 - PATCH_PX + 1))
                k = int(rng.integers(4))
                mirror = bool(rng.integers(2))
                if _patch_ok(contrast[s], bad[s], rr, cc):
                    p = PlacedPatch(s, rr, cc, k, mirror, ci * STRIDE_PX, cj * STRIDE_PX)
                    break
            if p is None:  # random draws failed (a mostly blank crop): one of the grid patches known to be usable
                s = usable[int(rng.integers(len(usable)))]
                rr, cc = grid[s][int(rng.integers(len(grid[s])))]
                p = PlacedPatch(s, rr, cc, int(rng.integers(4)), bool(rng.integers(2)), ci * STRIDE_PX, cj * STRIDE_PX)
            placed.append(p)
            rows = (p.atlas_row0 + np.arange(PATCH_PX)) % n
            cols = (p.atlas_col0 + np.arange(PATCH_PX)) % n
            acc[np.ix_(rows, cols)] += W * patch_pixels(contrast[p.source], p)
            wsum2[np.ix_(rows, cols)] += W * W
    L0 = np.clip(acc / np.sqrt(np.maximum(wsum2, 1e-12)), *CONTRAST_RANGE).astype(np.float32)
    levels = [L0]
    while levels[-1].shape[0] % 2 == 0 and levels[-1].shape[0] >= 64:
        levels.append(_pyr_down_wrap(levels[-1]))
    return SurfaceTexture(float(sources.pixel_m), levels, tuple(placed), int(seed), sources.digest)
