"""Dense ("JPL") stereo: disparity and 3-D for a whole stereo pair (pure numerics).

Frames: every 3-D quantity is in the frame of the camera models passed in
(for downlink products, the rover frame at acquisition). Pixels follow
docs/conventions.md: ``(u, v)`` = (column, row), ``(0, 0)`` the centre of the
top-left pixel. Range is the distance from the left camera's ``C``.

:func:`dense_stereo`: rectify the pair to shared-plane CAHV models
(:func:`scipctl.core.rectify.rectify_pair`), run OpenCV's semi-global block
matcher (``StereoSGBM``, 3-way mode) with a left-right consistency check, a
uniqueness ratio and a speckle filter, and convert disparity to 3-D on the
rectified-left pixel grid (:class:`DenseStereo`). At full and half resolution
the search is coarse-to-fine: a pass on a twice coarser grid
(:func:`dense_stereo_coarse`) bounds the disparities of each band of rows, and
the fine pass searches only those.

OpenCV is imported inside the functions (``scipctl --help`` stays fast).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Optional

import numpy as np

from .camera import CameraModel, check_camera_model
from .image import as_float_image

__all__ = ["DenseStereo", "dense_stereo", "dense_stereo_coarse", "sgbm_parameters"]


def sgbm_parameters(num_disparities: int, min_disparity: int = 0, block_size: int = 5,
                    uniqueness_ratio: int = 10, speckle_window: int = 100, speckle_range_px: int = 2,
                    pre_filter_cap: int = 63) -> dict:
    """Keyword arguments for ``cv2.StereoSGBM_create``: smoothness penalties ``P1 = 8 b^2``, ``P2 = 32 b^2``
    (OpenCV's recommendation for single-channel images, ``b`` = block size), 3-way mode (the fastest:
    parallel over image strips)."""
    import cv2

    nd = int(num_disparities)
    if nd < 16 or nd % 16:
        raise ValueError(f"num_disparities: must be a positive multiple of 16, got {nd}")
    b = int(block_size)
    if b < 1 or b % 2 == 0:
        raise ValueError(f"block_size: must be odd and >= 1, got {b}")
    return dict(
        minDisparity=int(min_disparity),
        numDisparities=nd,
        blockSize=b,
        P1=8 * b * b,
        P2=32 * b * b,
        disp12MaxDiff=-1,  # the left-right check is done by dense_stereo(lr_check="flip")
        preFilterCap=int(pre_filter_cap),
        uniquenessRatio=int(uniqueness_ratio),
        speckleWindowSize=int(speckle_window),
        speckleRange=int(speckle_range_px),
        mode=cv2.STEREO_SGBM_MODE_SGBM_3WAY,
    )


@dataclass
class DenseStereo:
    """Dense stereo of a pair on the rectified-left pixel grid.

    ``rectified``: the :class:`scipctl.core.rectify.RectifiedPair`.
    ``disparity_px`` (h, w) float32: ``u_left - u_right`` in rectified pixels,
    NaN where invalid. ``xyz`` (h, w, 3) float64: 3-D points in the models'
    frame, NaN where invalid. ``valid`` (h, w) bool. ``range_m`` (h, w):
    distance from the left camera centre, NaN where invalid.
    ``left_rect`` (h, w) float32: the rectified left image (input units).
    ``downsample``: the factor (1, 2, 4) of the rectified grid relative to the input images.
    """

    rectified: object
    disparity_px: np.ndarray
    xyz: np.ndarray
    valid: np.ndarray
    range_m: np.ndarray
    left_rect: np.ndarray
    downsample: int = 1
    num_disparities: int = 0
    min_disparity: int = 0

    def point_cloud(self) -> tuple[np.ndarray, np.ndarray]:
        """Valid points ``(N, 3)`` (models' frame) and their rectified-left intensities ``(N,)``."""
        return self.xyz[self.valid], self.left_rect[self.valid].astype(float)

    def depth_from_disparity(self, disparity_px) -> np.ndarray:
        """Depth along the rectified axis ``A`` (m) for rectified disparities."""
        with np.errstate(divide="ignore", invalid="ignore"):
            return self._fb() / np.asarray(disparity_px, dtype=float)

    @property
    def focal_baseline_px_m(self) -> float:
        """``f B`` (rectified focal length in px times the baseline along the rows, m): depth ``Z = f B / d``,
        so a disparity uncertainty ``s`` px gives a depth uncertainty ``Z^2 s / (f B)``."""
        return self._fb()

    def _fb(self) -> float:
        rp = self.rectified
        return float(rp.left_model.hs * np.dot(rp.right_model.C - rp.left_model.C, rp.left_model.h_axis))

    def disparity_at_rect_uv(self, uv_rect) -> np.ndarray:
        """Disparity at rectified-left pixels ``(N, 2)`` -> ``(N,)``: bilinear where the 4 neighbours are valid
        and agree within 1 px, else the nearest pixel's; NaN where that is invalid or outside."""
        p = np.asarray(uv_rect, dtype=float)
        if p.ndim != 2 or p.shape[1] != 2:
            raise ValueError(f"uv_rect: expected (N, 2), got {p.shape}")
        D = self.disparity_px
        h, w = D.shape
        out = np.full(len(p), np.nan)
        fin = np.all(np.isfinite(p), axis=1)
        u, v = np.where(fin, p[:, 0], -10.0), np.where(fin, p[:, 1], -10.0)
        inside = fin & (u >= -0.5) & (u <= w - 0.5) & (v >= -0.5) & (v <= h - 0.5)
        iu0 = np.clip(np.floor(u).astype(int), 0, w - 2)
        iv0 = np.clip(np.floor(v).astype(int), 0, h - 2)
        fu = np.clip(u - iu0, 0.0, 1.0)
        fv = np.clip(v - iv0, 0.0, 1.0)
        d00 = D[iv0, iu0].astype(float)
        d01 = D[iv0, iu0 + 1].astype(float)
        d10 = D[iv0 + 1, iu0].astype(float)
        d11 = D[iv0 + 1, iu0 + 1].astype(float)
        quad = np.stack([d00, d01, d10, d11], 1)
        fin4 = np.all(np.isfinite(quad), 1)
        q = np.where(fin4[:, None], quad, 0.0)
        ok4 = fin4 & ((q.max(1) - q.min(1)) <= 1.0)
        bil = (1 - fv) * ((1 - fu) * d00 + fu * d01) + fv * ((1 - fu) * d10 + fu * d11)
        nu = np.clip(np.floor(u + 0.5).astype(int), 0, w - 1)
        nv = np.clip(np.floor(v + 0.5).astype(int), 0, h - 1)
        near = D[nv, nu].astype(float)
        out = np.where(ok4, bil, near)
        out[~inside] = np.nan
        return out

    def xyz_at_left_uv(self, uv) -> np.ndarray:
        """3-D points ``(N, 3)`` (models' frame) seen at ORIGINAL left pixels ``uv`` ``(N, 2)``; NaN where invalid.

        The pixel is mapped to the rectified grid, the disparity interpolated
        there (:meth:`disparity_at_rect_uv`), turned into depth along the
        rectified axis and placed on the original pixel's own ray.
        """
        p = np.asarray(uv, dtype=float)
        if p.ndim != 2 or p.shape[1] != 2:
            raise ValueError(f"uv: expected (N, 2), got {p.shape}")
        rp = self.rectified
        uv_rect = rp.left_uv_to_rect(p)
        d = self.disparity_at_rect_uv(uv_rect)
        Z = self.depth_from_disparity(d)
        o, dirs = rp.orig_left.unproject(p)
        A = rp.left_model.A
        C = rp.left_model.C
        with np.errstate(divide="ignore", invalid="ignore"):
            t = (Z - (o - C) @ A) / (dirs @ A)
        X = o + t[:, None] * dirs
        bad = ~(np.isfinite(t) & (t > 0))
        X[bad] = np.nan
        return X


def _to_uint8(img: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """Stretch the 0.5..99.5 percentiles of the valid pixels to 0..255 (equalises camera gains)."""
    vals = img[::2, ::2][valid[::2, ::2]]  # a quarter of the pixels is plenty for percentiles
    if vals.size == 0:
        vals = img[valid]
    if vals.size == 0:
        return np.zeros(img.shape, np.uint8)
    lo, hi = np.percentile(vals, [0.5, 99.5])
    if hi <= lo:
        hi = lo + 1.0
    out = np.subtract(img, lo)  # in place from here on (float64, as before: 4-5x faster than with temporaries)
    out *= 255.0 / (hi - lo)
    np.clip(out, 0, 255, out=out)
    return out.astype(np.uint8)


def _map_valid(maps, shape_src) -> np.ndarray:
    """Rectified pixels whose source position lies inside the source image ``shape_src`` (H, W)."""
    mu, mv = maps
    Hs, Ws = shape_src
    return (mu >= -0.5) & (mu <= Ws - 0.5) & (mv >= -0.5) & (mv <= Hs - 0.5)


def _sgbm_disparity(ref8: np.ndarray, oth8: np.ndarray, d_lo: int, nd: int, params: dict) -> np.ndarray:
    """SGBM disparity ``d`` in ``[d_lo, d_lo + nd)`` of reference ``ref8`` (h, w) uint8 against ``oth8``:
    ``ref(u) ~ oth(u - d)``. Returns (h, w) float32, NaN where invalid.

    The pair is cropped instead of padded: reference columns ``u < d_lo`` can never match (``u - d < 0``),
    so the matcher sees ``ref[:, d_lo:]`` against ``oth[:, :w - d_lo]`` with disparities ``0 .. nd - 1``,
    both padded on the left by ``nd`` columns (SGBM leaves the first ``numDisparities`` columns unmatched).
    """
    import cv2

    h, w = ref8.shape
    out = np.full((h, w), np.nan, np.float32)
    if d_lo >= w:
        return out
    p = dict(params, minDisparity=0, numDisparities=int(nd))
    A = cv2.copyMakeBorder(ref8[:, d_lo:], 0, 0, nd, 0, cv2.BORDER_REPLICATE)
    B = cv2.copyMakeBorder(oth8[:, : w - d_lo], 0, 0, nd, 0, cv2.BORDER_REPLICATE)
    raw = cv2.StereoSGBM_create(**p).compute(A, B)[:, nd:]
    sub = out[:, d_lo:]
    ok = raw >= 0
    sub[ok] = raw[ok].astype(np.float32) * np.float32(1.0 / 16.0) + np.float32(d_lo)
    return out


def _lr_disparity(L8, R8, d_lo, nd, params, lr_check, lr_max_diff_px) -> np.ndarray:
    """Left-view disparity (h, w) float32 (NaN invalid) in ``[d_lo + 1, d_lo + nd - 2]``, left-right checked if asked.

    Disparities at the ends of the searched interval are rejected: SGBM puts a pixel whose true disparity lies
    beyond the interval at its end (hazcam ground nearer than ``min_range_m`` along the rectified axis).
    """
    h, w = L8.shape
    disp = _sgbm_disparity(L8, R8, d_lo, nd, params)
    # a disparity within 1 px of the searched interval's ends may be the stand-in of a truth beyond it
    with np.errstate(invalid="ignore"):
        disp[(disp < d_lo + 1) | (disp > d_lo + nd - 2)] = np.nan
    if lr_check == "flip":
        # right-view disparity: the mirrored right image matched against the mirrored left image
        # (running it in a second thread gave no consistent gain on 2 cores: SGBM 3-way is parallel already)
        dR = _sgbm_disparity(np.ascontiguousarray(R8[:, ::-1]), np.ascontiguousarray(L8[:, ::-1]), d_lo, nd,
                             params)[:, ::-1]
        fin = np.isfinite(disp)
        ur = np.round(np.arange(w, dtype=np.float32)[None, :] - np.where(fin, disp, 0.0)).astype(np.intp)
        np.clip(ur, 0, w - 1, out=ur)
        dr = np.take_along_axis(dR, ur, axis=1)
        with np.errstate(invalid="ignore"):
            bad = ~(np.abs(dr - disp) <= lr_max_diff_px)
        disp[bad] = np.nan
    return disp


#: Coarse-to-fine bands: the coarse min..max disparity of a band is widened by this much (fine px) ...
_BAND_MARGIN_PX = 8.0
#: ... and searched with a uniqueness ratio raised by this much: a narrowed interval holds fewer competing
#: disparities, so the plain ratio let more ambiguous (wrong) matches through. Measured on the synthetic scenes
#: of tests/core/test_dense_stereo.py and the 1024^2 benchmark pair: with +15, gross errors and wrong occluded pixels
#: are fewer than with the single full-interval pass, at 0.1-0.3 % less coverage (docs/stereo-and-tracking.md).
_BAND_UNIQUENESS_EXTRA = 15


def _row_map(src_model, dst_model, rows) -> np.ndarray:
    """Rows of rectified model ``dst_model`` seeing the same image-plane ``y`` as rows ``rows`` of ``src_model``."""
    y = (np.asarray(rows, float) - src_model.vc) / src_model.vs
    return dst_model.vc + dst_model.vs * y


def _coarse_on_grid(coarse: "DenseStereo", lm, fb: float, h: int, w: int) -> np.ndarray:
    """Coarse disparities (nearest coarse pixel) on the fine rectified grid of model ``lm`` (h, w), scaled to
    fine pixels; NaN where the coarse pass has none."""
    import cv2

    cm = coarse.rectified.left_model
    rows = _row_map(lm, cm, np.arange(h)).astype(np.float32)
    cols = (cm.hc + cm.hs * (np.arange(w) - lm.hc) / lm.hs).astype(np.float32)
    mu = np.broadcast_to(cols[None, :], (h, w))
    mv = np.broadcast_to(rows[:, None], (h, w))
    out = cv2.remap(coarse.disparity_px, np.ascontiguousarray(mu), np.ascontiguousarray(mv), cv2.INTER_NEAREST,
                    borderMode=cv2.BORDER_CONSTANT, borderValue=float("nan"))
    out *= np.float32(fb / coarse._fb())
    return out


def _band_intervals(coarse: "DenseStereo", lm, fb: float, h: int, d_min: int, d_max: int, band_rows: int,
                    overlap_rows: int, margin_px: float, min_points: int) -> list:
    """Per horizontal band of the fine rectified grid, the disparity interval to search.

    ``coarse``: dense stereo of the same pair on a coarser rectified grid. For fine rows ``[r0, r1)`` the
    coarse rows covering ``[r0 - overlap_rows, r1 + overlap_rows)`` (plus one) give the valid coarse
    disparities, scaled to the fine grid; the interval is their min .. max widened by ``margin_px``, clipped
    to ``[d_min, d_max]``. Bands with fewer than ``min_points`` valid coarse disparities search the whole
    ``[d_min, d_max]``. Returns ``[(r0, r1, lo, hi)]`` (integers, ``lo <= hi``).
    """
    cm = coarse.rectified.left_model
    cfb = coarse._fb()
    s = fb / cfb
    Dc = coarse.disparity_px
    hc = Dc.shape[0]
    out = []
    for r0 in range(0, h, band_rows):
        r1 = min(h, r0 + band_rows)
        c0, c1 = _row_map(lm, cm, [r0 - overlap_rows, r1 - 1 + overlap_rows])
        c0 = int(np.clip(np.floor(c0) - 1, 0, hc))
        c1 = int(np.clip(np.ceil(c1) + 2, 0, hc))
        vals = Dc[c0:c1]
        vals = vals[np.isfinite(vals)]
        if vals.size < min_points:
            lo, hi = d_min, d_max
        else:
            lo = max(d_min, int(math.floor(s * float(vals.min()) - margin_px)))
            hi = min(d_max, int(math.ceil(s * float(vals.max()) + margin_px)))
        out.append((r0, r1, lo, max(lo, hi)))
    return out


def dense_stereo(
    left_img,
    right_img,
    left_model: CameraModel,
    right_model: CameraModel,
    min_range_m: float = 0.5,
    max_range_m: float = 30.0,
    downsample: int = 1,
    block_size: int = 5,
    uniqueness_ratio: int = 10,
    speckle_window: int = 100,
    speckle_range_px: int = 2,
    lr_check: str = "flip",
    lr_max_diff_px: float = 1.0,
    rectified=None,
    coarse_to_fine: Optional[bool] = None,
    coarse=None,
    band_rows: int = 128,
    overlap_rows: int = 16,
) -> DenseStereo:
    """Dense disparity and 3-D for a stereo pair (rectify + ``cv2.StereoSGBM``).

    Parameters
    ----------
    left_img, right_img : (H, W) arrays, same shape (uint8, uint16 or float)
    left_model, right_model : CameraModel
        Same frame; any kind (CAHVORE is rectified for ``ref_range_m`` = 2 m).
    min_range_m, max_range_m : float
        Disparity search interval: ``d = f B / Z`` from ``Z = max_range_m``
        to ``Z = min_range_m`` (depth along the rectified axis is at most the
        range, so ``min_range_m`` bounds the largest disparity); points whose
        range falls outside the interval are invalid.
    downsample : 1, 2 or 4
        Rectified grid at ``1/downsample`` of the input resolution (the input
        is reduced with ``cv2.pyrDown`` first, so there is no aliasing).
    block_size, uniqueness_ratio, speckle_window, speckle_range_px
        SGBM parameters (see :func:`sgbm_parameters`).
    lr_check : "flip" or "none"
        Left-right consistency: ``flip`` computes the right-view disparity
        map with a second matcher on the mirrored images (right image as the
        reference) and rejects left pixels whose right-view disparity differs
        by more than ``lr_max_diff_px`` (occlusions, the left border where
        the right camera does not see, mismatches); it doubles the matching
        time. (SGBM's own ``disp12MaxDiff`` check changed nothing on our
        occlusion test scenes in any mode of OpenCV 5.0, so it is not used.)
    rectified : RectifiedPair, optional
        A precomputed rectification of these models (with ``scale = 1/downsample``).
    coarse_to_fine : bool, optional
        Search per horizontal band of ``band_rows`` rectified rows only the
        disparities a coarse pass (:func:`dense_stereo_coarse`: twice as
        coarse, over ranges down to ``min_range_m / 1.5``) saw in and around
        the band: its min .. max, widened by 8 px and rounded up to a multiple
        of 16 (each band matched with ``overlap_rows`` extra rows above and
        below). Ground rows span a few disparities each, so this searches far
        fewer than the whole interval (1024^2 benchmark: 3-4x less matching).
        Narrowed bands use ``uniqueness_ratio + 15`` (fewer competing
        disparities let more ambiguous matches through otherwise); pixels the
        coarse pass saw outside their band's interval are invalid (e.g. ground
        nearer along the rectified axis than ``min_range_m``, which one pass
        would put at the interval's end). Bands where the coarse pass has
        fewer than 20 points search the whole interval. Default: on for
        ``downsample`` 1 and 2 (grids of at least 256 px).
    coarse : DenseStereo, optional
        The coarse pass to use (from :func:`dense_stereo_coarse` on the same
        images and models); implies ``coarse_to_fine``.
    band_rows, overlap_rows : int
        Band height and the rows matched on each side of a band.

    Returns
    -------
    DenseStereo
        On the rectified-left grid; see :class:`DenseStereo`.
    """
    import cv2

    from .rectify import rectify_pair_cached

    check_camera_model(left_model, "left_model")
    check_camera_model(right_model, "right_model")
    L = as_float_image(left_img, "left_img")
    R = as_float_image(right_img, "right_img")
    if L.shape != R.shape:
        raise ValueError(f"left_img {L.shape} and right_img {R.shape}: dense stereo needs equal image sizes")
    if downsample not in (1, 2, 4):
        raise ValueError(f"downsample: must be 1, 2 or 4, got {downsample}")
    if not (0 < min_range_m < max_range_m and np.isfinite(max_range_m)):
        raise ValueError(f"ranges: need 0 < min_range_m < max_range_m < inf, got {min_range_m}, {max_range_m}")
    if lr_check not in ("flip", "none"):
        raise ValueError(f"lr_check: must be 'flip' or 'none', got {lr_check!r}")
    if int(band_rows) < 16 or int(overlap_rows) < 0:
        raise ValueError(f"band_rows, overlap_rows: need >= 16 and >= 0, got {band_rows}, {overlap_rows}")
    band_rows, overlap_rows = int(band_rows), int(overlap_rows)
    H, W = L.shape
    rp = rectified if rectified is not None else rectify_pair_cached(left_model, right_model, W, H, scale=1.0 / downsample)
    lm, rm = rp.left_model, rp.right_model
    f = float(lm.hs)
    b = rm.C - lm.C
    B_h = float(np.dot(b, lm.h_axis))
    if B_h <= 0 or abs(np.dot(b, lm.A)) > 1e-6 * np.linalg.norm(b) + 1e-9:
        raise ValueError("rectified pair: the baseline is not along +h (rectification is inconsistent)")
    fb = f * B_h
    if abs(np.dot(lm.h_axis, lm.v_axis)) > 1e-9 or abs(np.dot(lm.h_axis, lm.A)) > 1e-9 or not rm.almost_equal(
        CameraModel("CAHV", rm.C, lm.A, lm.H, lm.V), 1e-9
    ):
        raise ValueError("rectified pair: models must share an orthogonal A, H, V")

    # reduce the inputs to the rectified scale before resampling (pyrDown pixel i sits on pixel 2i)
    Ls, Rs = L, R
    for _ in range(int(round(math.log2(downsample)))):
        Ls, Rs = cv2.pyrDown(Ls), cv2.pyrDown(Rs)
    k = 1.0 / downsample
    mapsL = (rp.map_left[0] * np.float32(k), rp.map_left[1] * np.float32(k))
    mapsR = (rp.map_right[0] * np.float32(k), rp.map_right[1] * np.float32(k))
    Lr = cv2.remap(Ls, mapsL[0], mapsL[1], cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0)
    Rr = cv2.remap(Rs, mapsR[0], mapsR[1], cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0)
    vL = _map_valid(mapsL, Ls.shape)
    vR = _map_valid(mapsR, Rs.shape)
    L8 = _to_uint8(Lr, vL)
    R8 = _to_uint8(Rr, vR)

    h, w = L8.shape
    d_min = max(int(math.floor(fb / max_range_m)) - 1, 0)
    d_max = int(math.ceil(fb / min_range_m)) + 1
    d_max = min(d_max, d_min + w - 1)
    nd = max(16, int(math.ceil((d_max - d_min + 1) / 16.0)) * 16)
    params = sgbm_parameters(nd, d_min, block_size, uniqueness_ratio, speckle_window, speckle_range_px)

    if coarse_to_fine is None:
        coarse_to_fine = coarse is not None or (downsample <= 2 and min(h, w) >= 256)
    if not coarse_to_fine:
        disp = _lr_disparity(L8, R8, d_min, nd, params, lr_check, lr_max_diff_px)
    else:
        if coarse is None:
            coarse = dense_stereo_coarse(left_img, right_img, left_model, right_model, min_range_m=min_range_m / 1.5,
                                         max_range_m=max_range_m, downsample=downsample, block_size=block_size,
                                         uniqueness_ratio=uniqueness_ratio, speckle_window=speckle_window,
                                         speckle_range_px=speckle_range_px, lr_check=lr_check,
                                         lr_max_diff_px=lr_max_diff_px)
        elif not isinstance(coarse, DenseStereo):
            raise ValueError(f"coarse: expected a DenseStereo, got {type(coarse).__name__}")
        bands = _band_intervals(coarse, lm, fb, h, d_min, d_min + nd - 1, band_rows, overlap_rows,
                                margin_px=_BAND_MARGIN_PX, min_points=20)
        disp = np.full((h, w), np.nan, np.float32)
        coarse_d = _coarse_on_grid(coarse, lm, fb, h, w)
        for r0, r1, lo, hi in bands:
            n_b = min(nd, max(16, int(math.ceil((hi - lo + 1) / 16.0)) * 16))
            lo_b = max(d_min, lo - (n_b - (hi - lo + 1)) // 2)  # centre the interval in the 16-multiple
            lo_b = min(lo_b, max(d_min, d_min + nd - n_b))
            a0, a1 = max(0, r0 - overlap_rows), min(h, r1 + overlap_rows)
            pb = params if n_b >= nd else dict(params, uniquenessRatio=params["uniquenessRatio"] + _BAND_UNIQUENESS_EXTRA)
            db = _lr_disparity(L8[a0:a1], R8[a0:a1], lo_b, n_b, pb, lr_check, lr_max_diff_px)[r0 - a0 : r1 - a0]
            # where the coarse pass saw a disparity outside the band's interval (e.g. ground nearer along the
            # rectified axis than min_range_m: SGBM would put it at the interval's end), the fine one is not trusted
            cb = coarse_d[r0:r1]
            with np.errstate(invalid="ignore"):
                db[(cb < lo_b) | (cb > lo_b + n_b - 1)] = np.nan
            disp[r0:r1] = db
    valid = np.isfinite(disp)

    # both rectified pixels must come from inside the original images
    valid &= vL
    us = np.arange(w, dtype=np.float32)[None, :] - np.where(valid, disp, np.float32(0))
    ur_n = np.clip(np.round(us).astype(np.intp), 0, w - 1)
    valid &= (us >= -0.5) & np.take_along_axis(vR, ur_n, axis=1)
    with np.errstate(invalid="ignore"):
        valid &= disp > 0

    with np.errstate(divide="ignore", invalid="ignore"):
        Z = fb / np.where(valid, disp, np.float32(np.nan)).astype(np.float64)
    # rectified CAHV: P = C + Z (A + xn h' + yn v'), xn = (u - hc)/hs by column, yn = (v - vc)/vs by row
    xn = (np.arange(w, dtype=float) - lm.hc) / lm.hs
    yn = (np.arange(h, dtype=float) - lm.vc) / lm.vs
    rng = Z * np.sqrt(1.0 + xn[None, :] ** 2 + yn[:, None] ** 2)  # |P - C| (h', v', A orthonormal)
    with np.errstate(invalid="ignore"):
        valid &= (rng >= min_range_m) & (rng <= max_range_m)
    Z[~valid] = np.nan
    rng[~valid] = np.nan
    disp[~valid] = np.nan
    xyz = np.empty((h, w, 3))
    comp = np.empty((h, w))
    for k in range(3):  # one component at a time: no (h, w, 3) temporaries
        np.add(lm.A[k] + yn[:, None] * lm.v_axis[k], xn[None, :] * lm.h_axis[k], out=comp)
        comp *= Z
        comp += lm.C[k]
        xyz[..., k] = comp
    return DenseStereo(
        rectified=rp, disparity_px=disp, xyz=xyz, valid=valid, range_m=rng, left_rect=Lr,
        downsample=downsample, num_disparities=nd, min_disparity=d_min,
    )


def dense_stereo_coarse(
    left_img,
    right_img,
    left_model: CameraModel,
    right_model: CameraModel,
    min_range_m: float = 0.5,
    max_range_m: float = 30.0,
    downsample: int = 1,
    block_size: int = 5,
    uniqueness_ratio: int = 10,
    speckle_window: int = 100,
    speckle_range_px: int = 2,
    lr_check: str = "flip",
    lr_max_diff_px: float = 1.0,
) -> DenseStereo:
    """The coarse pass of :func:`dense_stereo` at ``downsample``: dense stereo on a grid twice as coarse
    (``2 * downsample``, at most 4) with the speckle window scaled to the coarser pixels (``/ 4``); for
    ``downsample=1`` it is itself coarse-to-fine (from a quarter-resolution pass), else one full-interval pass.

    Pass the result as ``dense_stereo(..., coarse=...)`` (same images, models and ranges) to reuse it, e.g.
    after looking at the ranges in view. Arguments as for :func:`dense_stereo`.
    """
    return dense_stereo(left_img, right_img, left_model, right_model, min_range_m=min_range_m,
                        max_range_m=max_range_m, downsample=min(4, 2 * downsample), block_size=block_size,
                        uniqueness_ratio=uniqueness_ratio, speckle_window=max(1, speckle_window // 4),
                        speckle_range_px=speckle_range_px, lr_check=lr_check, lr_max_diff_px=lr_max_diff_px,
                        coarse_to_fine=downsample == 1)
