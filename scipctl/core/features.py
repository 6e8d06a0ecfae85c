"""Feature-guided coarse localisation: find where a reference point went in another image (pure numerics).

Pixel convention (docs/conventions.md): ``(u, v)`` = (column, row), 0-based,
``(0, 0)`` is the centre of the top-left pixel; an image is indexed
``img[v, u]``.

NCC over a large search region on sand texture finds better-looking wrong
places when the prediction is hundreds of pixels off. Local features are
robust to that: SIFT keypoints (OpenCV ``cv2.SIFT_create``) are detected in a
reference image around the reference point and in the whole searched image,
matched with Lowe's ratio test, and a geometric model (similarity, affine or
homography) is fitted to the matches with RANSAC. The reference point mapped
through the model is the coarse position; the number of RANSAC inliers (and
how many of them lie near the point) is its confidence. A refinement (NCC in
a small radius, :func:`scipctl.core.tracking.track`) is expected to follow.

SIFT is invariant to scale and in-plane rotation, not to strong perspective
change: a ground patch seen at a grazing angle from 10 m and again from 4.5 m
is foreshortened differently, so the caller should first warp the reference
into the new view's geometry (e.g. through the local ground plane) and use
this module to find the remaining, mostly translational, offset.

OpenCV is imported inside the functions (``scipctl --help`` stays fast).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Optional

import numpy as np

from .ransac import ransac

__all__ = ["Features", "FeatureLocation", "KnnMatches", "detect_features", "knn_matches", "locate_by_features", "mutual_knn_matches", "to_uint8"]

_MODELS = ("translation", "similarity", "affine", "homography")


@dataclass(frozen=True)
class Features:
    """Keypoints of one image: ``uv`` ``(N, 2)`` full-resolution pixels, ``descriptors`` ``(N, 128)`` float32,
    ``size_px`` ``(N,)`` keypoint diameter in full-resolution pixels; ``shape`` = the image's ``(H, W)``."""

    uv: np.ndarray
    descriptors: np.ndarray
    size_px: np.ndarray
    shape: tuple

    def __len__(self) -> int:
        return int(self.uv.shape[0])

    def subset(self, keep: np.ndarray) -> "Features":
        """The keypoints where boolean ``keep`` ``(N,)`` is true."""
        keep = np.asarray(keep, bool)
        if keep.shape != (len(self),):
            raise ValueError(f"keep: expected ({len(self)},) booleans, got {keep.shape}")
        return Features(self.uv[keep], self.descriptors[keep], self.size_px[keep], self.shape)


@dataclass(frozen=True)
class FeatureLocation:
    """Outcome of :func:`locate_by_features`.

    ``uv`` (2,): the reference point mapped into the searched image (NaN when
    no model was found). ``transform`` (3, 3): the fitted model, reference
    pixels -> searched pixels (homogeneous; NaN when none). ``n_matches``:
    ratio-test matches; ``n_inliers``: RANSAC inliers; ``n_local_inliers``:
    inliers whose reference keypoint lies within ``local_radius_px`` of the
    reference point; ``rms_px``: RMS residual of the inliers under the model.
    ``ok`` is ``False`` with a one-line ``reason`` when the location is not
    supported by at least ``min_inliers`` inliers.
    """

    ok: bool
    reason: str
    uv: np.ndarray
    transform: np.ndarray
    n_matches: int
    n_inliers: int
    n_local_inliers: int
    rms_px: float

    @staticmethod
    def failed(reason: str, n_matches: int = 0, n_inliers: int = 0) -> "FeatureLocation":
        return FeatureLocation(False, reason, np.full(2, np.nan), np.full((3, 3), np.nan), n_matches, n_inliers, 0,
                               float("nan"))


@dataclass(frozen=True)
class KnnMatches:
    """The two nearest searched-image descriptors (L2) of every reference keypoint, as OpenCV's brute-force
    ``knnMatch(k=2)`` finds them: ``best`` ``(N,)`` the nearest one's index, ``best_d`` / ``second_d`` ``(N,)``
    their distances (float32, as OpenCV gives them; ``second_d`` is NaN where fewer than two exist).

    A keypoint's neighbours depend only on its own descriptor and the searched set, so the matches of a
    subset of the reference keypoints are the rows of the whole set's: :func:`locate_by_features` takes
    them (``knn=``) to match a reference image once for several candidate reaches.
    """

    best: np.ndarray
    best_d: np.ndarray
    second_d: np.ndarray

    def __len__(self) -> int:
        return int(self.best.shape[0])


def _integer_descriptors(d: np.ndarray) -> bool:
    """Float32 descriptors whose values are whole numbers in [0, 255] (OpenCV's SIFT stores them so), few enough
    per row that every squared distance and dot product is an integer below 2**24 (exact in float32)."""
    return (d.dtype == np.float32 and d.ndim == 2 and 0 < d.shape[1] * 255**2 < 2**24 and d.size > 0
            and float(d.min()) >= 0.0 and float(d.max()) <= 255.0 and bool(np.all(d == np.rint(d))))


def _distance_blocks(q: np.ndarray, t: np.ndarray, block: int):
    """``(start, stop, d)`` over blocks of the queries ``q`` ``(N, D)``: ``d`` ``(stop - start, M)`` float32 L2
    distances to ``t`` ``(M, D)``, exact for integer-valued descriptors (see :func:`_knn2_integer`)."""
    q_sq = np.einsum("ij,ij->i", q, q)
    t_sq = np.einsum("ij,ij->i", t, t)
    tT = np.ascontiguousarray(t.T)
    for s in range(0, len(q), block):
        e = min(s + block, len(q))
        d = q[s:e] @ tT
        d *= np.float32(-2.0)
        d += q_sq[s:e, None]
        d += t_sq[None, :]
        np.sqrt(d, out=d)
        yield s, e, d


def _rows_2nn(d: np.ndarray):
    """Each row's nearest column, its distance and the second-nearest distance (ties: the lower index); ``d`` is
    changed (each row's nearest set to inf)."""
    rows = np.arange(len(d))
    j = d.argmin(axis=1)
    best_d = d[rows, j]
    d[rows, j] = np.inf
    return j, best_d, d[rows, d.argmin(axis=1)]


def _knn2_integer(q: np.ndarray, t: np.ndarray, block: int = 256) -> KnnMatches:
    """OpenCV's brute-force 2-NN (L2) of integer-valued float32 descriptors ``q`` ``(N, D)`` in ``t`` ``(M >= 2, D)``,
    bit for bit: ``|q|^2 + |t|^2 - 2 q.t`` are integers below 2**24, so float32 matrix products and sums are exact
    whatever their order, as OpenCV's sum of squared differences is; the distance is their float32 square root;
    ties go to the lower index (``argmin``), as in OpenCV's insertion. Queries in blocks (memory O(block M))."""
    n = len(q)
    best, best_d, second_d = np.zeros(n, np.int64), np.empty(n, np.float32), np.empty(n, np.float32)
    for s, e, d in _distance_blocks(q, t, block):
        best[s:e], best_d[s:e], second_d[s:e] = _rows_2nn(d)
    return KnnMatches(best, best_d, second_d)


def _mutual_knn2_integer(a: np.ndarray, b: np.ndarray, block: int = 256) -> tuple[KnnMatches, KnnMatches]:
    """``(_knn2_integer(a, b), _knn2_integer(b, a))`` from one pass over the distance matrix, bit for bit: its
    entries are the same integers whichever side is the query (every sum in :func:`_knn2_integer` is exact), so the
    columns' 2-NN is read from the same blocks (running over the blocks of ``a``; a later block takes a column's best
    only when strictly nearer, so ties keep the lower index). ``a`` ``(N >= 2, D)``, ``b`` ``(M >= 2, D)``."""
    n, m = len(a), len(b)
    best, best_d, second_d = np.zeros(n, np.int64), np.empty(n, np.float32), np.empty(n, np.float32)
    c_best = np.zeros(m, np.int64)
    c_best_d = np.full(m, np.inf, np.float32)
    c_second_d = np.full(m, np.inf, np.float32)
    cols = np.arange(m)
    for s, e, d in _distance_blocks(a, b, block):
        # the columns (b's keypoints among this block of a's): best and second within the block, then merged
        jc = d.argmin(axis=0)
        bd = d[jc, cols]
        d[jc, cols] = np.inf
        b2 = d.min(axis=0)
        d[jc, cols] = bd
        nearer = bd < c_best_d
        c_second_d = np.where(nearer, np.minimum(c_best_d, b2), np.minimum(c_second_d, bd))
        c_best = np.where(nearer, jc + s, c_best)
        c_best_d = np.where(nearer, bd, c_best_d)
        best[s:e], best_d[s:e], second_d[s:e] = _rows_2nn(d)  # the rows, as _knn2_integer reads them
    return KnnMatches(best, best_d, second_d), KnnMatches(c_best, c_best_d, c_second_d)


def mutual_knn_matches(a: Features, b: Features) -> tuple[KnnMatches, KnnMatches]:
    """``(knn_matches(a, b), knn_matches(b, a))``, the same answers; for SIFT's integer-valued descriptors from one
    distance matrix (:func:`_mutual_knn2_integer`: half the arithmetic of two calls)."""
    if len(a) >= 2 and len(b) >= 2 and _integer_descriptors(a.descriptors) and _integer_descriptors(b.descriptors) \
            and a.descriptors.shape[1] == b.descriptors.shape[1]:
        return _mutual_knn2_integer(a.descriptors, b.descriptors)
    return knn_matches(a, b), knn_matches(b, a)


def knn_matches(ref: Features, target: Features) -> KnnMatches:
    """:class:`KnnMatches` of every keypoint of ``ref`` among those of ``target``: OpenCV's brute-force L2 matcher
    (``BFMatcher.knnMatch(k=2)``), or for SIFT's integer-valued descriptors the same answer computed exactly with
    float32 matrix products (:func:`_knn2_integer`, ~4x less CPU; tests/core/test_features.py compares the two)."""
    import cv2

    n = len(ref)
    if n and len(target) >= 2 and _integer_descriptors(ref.descriptors) and _integer_descriptors(target.descriptors) \
            and ref.descriptors.shape[1] == target.descriptors.shape[1]:
        return _knn2_integer(ref.descriptors, target.descriptors)
    best, best_d, second_d = np.zeros(n, np.int64), np.full(n, np.nan, np.float32), np.full(n, np.nan, np.float32)
    if n and len(target):
        for i, m in enumerate(cv2.BFMatcher(cv2.NORM_L2).knnMatch(ref.descriptors, target.descriptors, k=2)):
            if len(m) >= 1:
                best[i], best_d[i] = m[0].trainIdx, m[0].distance
            if len(m) >= 2:
                second_d[i] = m[1].distance
    return KnnMatches(best, best_d, second_d)


def to_uint8(image, valid: Optional[np.ndarray] = None) -> np.ndarray:
    """``image`` ``(H, W)`` (any real dtype, NaN allowed) stretched to uint8 between its 0.5 and 99.5 percentiles.

    Only pixels where ``valid`` ``(H, W)`` (default: finite) is true set the
    stretch; the others become the mid-grey of the stretch.
    """
    a = np.asarray(image, dtype=np.float32)
    if a.ndim != 2:
        raise ValueError(f"image: expected (H, W), got shape {a.shape}")
    ok = np.isfinite(a) if valid is None else (np.asarray(valid, bool) & np.isfinite(a))
    if not ok.any():
        return np.zeros(a.shape, np.uint8)
    lo, hi = np.percentile(a[ok], [0.5, 99.5])
    if not hi > lo:
        hi = lo + 1.0
    out = np.subtract(a, lo)  # float64 (lo is), in place from here on: the same operations without temporaries
    out *= 255.0 / (hi - lo)
    np.clip(out, 0, 255, out=out)
    np.copyto(out, 127.5, where=~ok)
    np.round(out, out=out)
    return out.astype(np.uint8)


def detect_features(image, valid: Optional[np.ndarray] = None, downsample: float = 1.0,
                    contrast_threshold: float = 0.02, max_features: int = 0, median_px: int = 0) -> Features:
    """SIFT keypoints and descriptors of ``image`` ``(H, W)``.

    ``valid`` ``(H, W)`` bool (default: the finite pixels): keypoints are kept
    only where the whole keypoint footprint is valid (so that the border of a
    warped, partly empty image makes no features). ``downsample`` (factor >= 1):
    detect on the image area-resampled to ``round(W / f) x round(H / f)`` (faster,
    and a way to match the blur of a coarser reference); ``uv`` is still
    returned in full-resolution pixels (detection pixel ``i`` is centred on
    full-resolution ``s (i + 0.5) - 0.5``, ``s = W / round(W / f)``). ``max_features``: keep the
    strongest this many (0: all). ``median_px``: an odd kernel size (detection pixels) of a median filter applied
    after the downsampling, before detection (0 or 1: none). It removes isolated specks one or two detection pixels
    across (bright grains, pits): texture a coarser view of the same ground does not resolve, and whose keypoints
    therefore match nothing in it; the keypoints left are those of structure both views show.
    """
    import cv2

    a = np.asarray(image, dtype=np.float32)
    if a.ndim != 2:
        raise ValueError(f"image: expected (H, W), got shape {a.shape}")
    f = float(downsample)
    if not (np.isfinite(f) and f >= 1.0):
        raise ValueError(f"downsample: must be a finite factor >= 1, got {downsample}")
    if not (isinstance(median_px, (int, np.integer)) and not isinstance(median_px, bool)
            and (median_px in (0, 1) or (median_px >= 3 and median_px % 2 == 1))):
        raise ValueError(f"median_px: must be 0, 1 or an odd integer >= 3, got {median_px!r}")
    ok = np.isfinite(a) if valid is None else np.asarray(valid, bool) & np.isfinite(a)
    if ok.shape != a.shape:
        raise ValueError(f"valid: expected shape {a.shape}, got {ok.shape}")
    img8 = to_uint8(a, ok)
    okf = ok.astype(np.float32)
    H, W = a.shape
    w2, h2 = max(int(round(W / f)), 1), max(int(round(H / f)), 1)
    sx, sy = W / w2, H / h2  # full-resolution pixels per detection pixel (exactly f when it divides the size)
    if f > 1.0:
        img8 = cv2.resize(img8, (w2, h2), interpolation=cv2.INTER_AREA)
        okf = cv2.resize(okf, (w2, h2), interpolation=cv2.INTER_AREA)
    if median_px > 1:
        img8 = cv2.medianBlur(img8, int(median_px))
    sift = cv2.SIFT_create(nfeatures=int(max_features), contrastThreshold=float(contrast_threshold))
    kps, desc = sift.detectAndCompute(img8, None)
    empty = Features(np.zeros((0, 2)), np.zeros((0, 128), np.float32), np.zeros(0), tuple(a.shape))
    if not kps or desc is None:
        return empty
    uv = np.array([k.pt for k in kps], dtype=float)
    size = np.array([k.size for k in kps], dtype=float)
    # the keypoint's footprint (radius ~ size) must lie in the valid part of the image
    if not ok.all():
        erode = max(3, int(np.ceil(np.median(size))) | 1)
        inside = cv2.erode((okf > 0.999).astype(np.uint8), np.ones((erode, erode), np.uint8))
        iu = np.clip(np.round(uv[:, 0]).astype(int), 0, inside.shape[1] - 1)
        iv = np.clip(np.round(uv[:, 1]).astype(int), 0, inside.shape[0] - 1)
        keep = inside[iv, iu] > 0
        uv, size, desc = uv[keep], size[keep], desc[keep]
    # detection pixel centre i covers full-resolution [s i - 0.5, s (i + 1) - 0.5]: its centre is s (i + 0.5) - 0.5
    uv = (uv + 0.5) * np.array([sx, sy]) - 0.5
    # a fixed order (row, column, size, then descriptor), whatever order the detector emitted them in: matching and
    # the RANSAC draw then do not depend on it
    order = np.lexsort((desc[:, 0], size, uv[:, 0], uv[:, 1]))
    uv, size, desc = uv[order], size[order], desc[order]
    return Features(uv, np.ascontiguousarray(desc, np.float32), size * np.sqrt(sx * sy), tuple(a.shape))


def _fit(model: str, src: np.ndarray, dst: np.ndarray, threshold_px: float, seed: int):
    """Robust fit of ``model`` to ``src`` -> ``dst`` ``(N, 2)``: ``(M (3, 3) or None, inliers (N,) bool)``.

    Translation: every match proposes a shift (no random draw). The others:
    seeded LO-RANSAC (:func:`scipctl.core.ransac.ransac`), the same on every
    OpenCV build.
    """
    n = len(src)
    if model == "translation":
        # 1-point RANSAC: every match proposes a shift; keep the one with most support, refit by the median
        shifts = dst - src
        # proposals: every match, or an even subset of at most 500 of them (memory stays O(500 N))
        prop = shifts[np.linspace(0, n - 1, min(n, 500)).astype(int)]
        dd = np.linalg.norm(prop[:, None, :] - shifts[None, :, :], axis=2)
        support = (dd <= threshold_px).sum(1)
        inl = dd[int(np.argmax(support))] <= threshold_px
        t = np.median(shifts[inl], axis=0)
        inl = np.linalg.norm(shifts - t, axis=1) <= threshold_px
        M = np.eye(3)
        M[:2, 2] = np.median(shifts[inl], axis=0)
        return M, inl
    res = ransac(model, src, dst, threshold_px, seed=seed, max_iterations=4000, confidence=0.999)
    return res.model, res.inliers


def _apply(M: np.ndarray, uv: np.ndarray) -> np.ndarray:
    p = np.c_[uv, np.ones(len(uv))] @ M.T
    return p[:, :2] / p[:, 2:3]


def locate_by_features(
    ref: Features,
    ref_uv,
    target: Features,
    ref_radius_px: float,
    search_center_uv=None,
    search_radius_px: Optional[float] = None,
    model: str = "similarity",
    ratio: float = 0.8,
    ransac_threshold_px: float = 4.0,
    min_inliers: int = 8,
    local_radius_px: Optional[float] = None,
    seed: int = 0,
    knn: Optional[KnnMatches] = None,
) -> FeatureLocation:
    """Where the reference point ``ref_uv`` (reference-image pixels) lies in the target image.

    Parameters
    ----------
    ref, target : Features
        Keypoints of the reference image and of the searched image
        (:func:`detect_features`).
    ref_uv : (2,)
        The point to map, reference-image pixels.
    ref_radius_px : float
        Only reference keypoints within this distance of ``ref_uv`` are matched.
    search_center_uv : (2,), optional; search_radius_px : float, optional
        When both are given, only target keypoints in the square of this
        half-width around this centre are matched (default: the whole image).
    model : {"translation", "similarity", "affine", "homography"}
        The geometric model fitted by RANSAC (4, 4, 6, 8 degrees of freedom).
    ratio : float
        Lowe's ratio test: a match is kept when its descriptor distance is
        below ``ratio`` times the second-best one.
    ransac_threshold_px : float
        RANSAC inlier threshold (target pixels).
    min_inliers : int
        Fewer inliers -> ``ok=False``.
    local_radius_px : float, optional
        Radius around ``ref_uv`` counted for ``n_local_inliers`` (default
        ``ref_radius_px / 2``).
    seed : int
        Seed of the RANSAC draw (the same seed and keypoints give the same
        answer on every machine and OpenCV build).
    knn : KnnMatches, optional
        ``knn_matches(ref, target)``, computed once by a caller that locates
        several points or reaches in the same pair of keypoint sets (the
        same answer as matching here; not with a search square).

    Returns
    -------
    FeatureLocation
        ``uv`` (2,) in the target image's pixels.
    """
    if model not in _MODELS:
        raise ValueError(f"model: expected one of {_MODELS}, got {model!r}")
    p = np.asarray(ref_uv, dtype=float).reshape(-1)
    if p.shape != (2,) or not np.all(np.isfinite(p)):
        raise ValueError(f"ref_uv: expected a finite (u, v) pair, got {ref_uv!r}")
    if not (np.isfinite(ref_radius_px) and ref_radius_px > 0):
        raise ValueError(f"ref_radius_px: must be finite and > 0, got {ref_radius_px}")
    if local_radius_px is None:
        local_radius_px = ref_radius_px / 2.0
    keep = np.linalg.norm(ref.uv - p, axis=1) <= ref_radius_px if len(ref) else np.zeros(0, bool)
    r = ref.subset(keep) if len(ref) else ref
    t = target
    searched = search_center_uv is not None and search_radius_px is not None
    if knn is not None and (searched or len(knn) != len(ref)):
        raise ValueError("knn: must be knn_matches(ref, target) of the whole target (no search square)")
    if searched and len(t):
        c = np.asarray(search_center_uv, dtype=float).reshape(2)
        t = t.subset(np.all(np.abs(t.uv - c) <= search_radius_px, axis=1))
    need = {"translation": 1, "similarity": 2, "affine": 3, "homography": 4}[model]
    if len(r) < max(need, 2) or len(t) < 2:
        return FeatureLocation.failed(f"too few keypoints (reference {len(r)}, target {len(t)})")
    if knn is None:
        knn = knn_matches(r, t)
    else:
        rows = np.flatnonzero(keep)
        knn = KnnMatches(knn.best[rows], knn.best_d[rows], knn.second_d[rows])
    # Lowe's ratio test, in double precision as on OpenCV's DMatch distances (float32 values)
    passed = np.flatnonzero(knn.best_d.astype(np.float64) < ratio * knn.second_d.astype(np.float64))
    qi, ti = passed.tolist(), knn.best[passed].tolist()
    n_matches = len(qi)
    if n_matches < max(need + 1, 3):
        return FeatureLocation.failed(f"too few feature matches ({n_matches})", n_matches)
    src, dst = r.uv[qi], t.uv[ti]
    M, inl = _fit(model, src, dst, float(ransac_threshold_px), seed)
    n_in = int(inl.sum())
    if M is None or not np.all(np.isfinite(M)) or n_in < need:
        return FeatureLocation.failed("no geometric model fits the matches", n_matches, n_in)
    uv = _apply(M, p[None])[0]
    res = np.linalg.norm(_apply(M, src[inl]) - dst[inl], axis=1)
    rms = float(np.sqrt(np.mean(res**2))) if n_in else float("nan")
    n_local = int(np.sum(np.linalg.norm(src[inl] - p, axis=1) <= local_radius_px))
    ok, reason = True, ""
    if not np.all(np.isfinite(uv)):
        ok, reason = False, "the model maps the point to infinity"
    elif n_in < min_inliers:
        ok, reason = False, f"weak feature match ({n_in} inliers < {min_inliers})"
    return FeatureLocation(ok, reason, uv, M, n_matches, n_in, n_local, rms)
