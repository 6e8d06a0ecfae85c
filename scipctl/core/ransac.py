"""Seeded, locally optimised RANSAC for 2-D point-to-point models (pure numerics).

Why not OpenCV's: ``cv2.findHomography`` / ``cv2.estimateAffinePartial2D``
draw their samples from a generator and stop by rules that changed between
OpenCV builds (4.x and 5.x give different inlier sets on the same matches),
so the chain's answer depended on which OpenCV was installed. Here every
step is numpy with a generator seeded by the caller, and the answer is made
insensitive to the draw:

1. minimal samples are drawn from ``np.random.default_rng(seed)`` over the
   matches in the order given (callers sort them, so the order does not
   depend on a detector's output order);
2. each hypothesis is scored by its truncated squared residuals (MSAC:
   ``sum(min(r^2, t^2))``), which ranks two hypotheses with the same inlier
   count by how well they fit instead of by which was drawn first;
3. the best hypothesis is locally optimised: refitted by least squares on its
   inliers, inliers recomputed, until the set stops changing (LO-RANSAC,
   Chum et al. 2003). Different draws that find the same consensus set
   therefore end at the same model.

Models (``src`` ``(N, 2)`` -> ``dst`` ``(N, 2)``, returned as ``(3, 3)``
homogeneous matrices acting on column vectors ``(u, v, 1)``):

=============  ====  =======================================================
model          dof   least-squares fit
=============  ====  =======================================================
translation    2     mean shift
similarity     4     closed form (Umeyama, no reflection)
affine         6     linear least squares
homography     8     normalised DLT (Hartley), SVD
=============  ====  =======================================================
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["MODELS", "MIN_SAMPLES", "RansacResult", "fit_model", "apply_model", "ransac"]

MODELS = ("translation", "similarity", "affine", "homography")
MIN_SAMPLES = {"translation": 1, "similarity": 2, "affine": 3, "homography": 4}


@dataclass(frozen=True)
class RansacResult:
    """``model`` ``(3, 3)`` or None when no hypothesis had a minimal consensus; ``inliers`` ``(N,)`` bool;
    ``iterations``: hypotheses drawn."""

    model: np.ndarray | None
    inliers: np.ndarray
    iterations: int


def _check_pairs(src, dst) -> tuple[np.ndarray, np.ndarray]:
    s = np.asarray(src, dtype=float)
    d = np.asarray(dst, dtype=float)
    if s.ndim != 2 or s.shape[1] != 2 or d.shape != s.shape:
        raise ValueError(f"src, dst: expected two (N, 2) arrays, got {s.shape} and {d.shape}")
    return s, d


def _homogeneous(uv) -> np.ndarray:
    """``(N, 3)`` float64 rows ``(u, v, 1)`` of ``uv`` ``(N, 2)``."""
    uv = np.asarray(uv)
    h = np.empty((len(uv), 3))
    h[:, :2] = uv
    h[:, 2] = 1.0
    return h


def _dehomogenise(p: np.ndarray) -> np.ndarray:
    with np.errstate(divide="ignore", invalid="ignore"):
        return p[:, :2] / p[:, 2:3]


def apply_model(M: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """``uv`` ``(N, 2)`` mapped through the homogeneous ``M`` ``(3, 3)``; ``(N, 2)`` (inf/NaN at infinity)."""
    return _dehomogenise(_homogeneous(uv) @ np.asarray(M, float).T)


def _normaliser(p: np.ndarray) -> np.ndarray:
    """Hartley's similarity taking ``p`` ``(N, 2)`` to zero mean and mean distance sqrt(2)."""
    n = len(p)
    c = np.add.reduce(p, axis=0) / n  # p.mean(axis=0), without its Python-level overhead (same arithmetic)
    d = np.add.reduce(np.sqrt(((p - c) ** 2).sum(axis=1))) / n
    s = np.sqrt(2.0) / d if d > 0 else 1.0
    return np.array([[s, 0.0, -s * c[0]], [0.0, s, -s * c[1]], [0.0, 0.0, 1.0]])


def _fit_translation(s, d):
    M = np.eye(3)
    M[:2, 2] = (d - s).mean(axis=0)
    return M


def _fit_similarity(s, d):
    cs, cd = s.mean(axis=0), d.mean(axis=0)
    a, b = s - cs, d - cd
    var = (a**2).sum()
    if var <= 0:
        return None
    # rotation + scale in closed form: [p, -q; q, p]
    p = (a[:, 0] * b[:, 0] + a[:, 1] * b[:, 1]).sum() / var
    q = (a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]).sum() / var
    R = np.array([[p, -q], [q, p]])
    M = np.eye(3)
    M[:2, :2] = R
    M[:2, 2] = cd - R @ cs
    return M


def _fit_affine(s, d):
    A = np.c_[s, np.ones(len(s))]
    if np.linalg.matrix_rank(A) < 3:
        return None
    X, *_ = np.linalg.lstsq(A, d, rcond=None)
    M = np.eye(3)
    M[:2, :] = X.T
    return M


def _fit_homography(s, d):
    T_srcnorm_src, T_dstnorm_dst = _normaliser(s), _normaliser(d)  # pixels -> normalised pixels (3, 3)
    sn = apply_model(T_srcnorm_src, s)
    dn = apply_model(T_dstnorm_dst, d)
    n = len(s)
    A = np.zeros((2 * n, 9))
    A[0::2, 0:2], A[0::2, 2] = sn, 1.0
    A[0::2, 6:8] = -dn[:, :1] * sn
    A[0::2, 8] = -dn[:, 0]
    A[1::2, 3:5], A[1::2, 5] = sn, 1.0
    A[1::2, 6:8] = -dn[:, 1:2] * sn
    A[1::2, 8] = -dn[:, 1]
    # only sv and Vt are used: without the (2n, 2n) U (LAPACK's gesdd computes the same R, bidiagonal form,
    # singular values and Vt with or without it; the local optimisation fits hundreds of pairs, where the full U
    # cost ~5x the rest). A minimal sample (8 x 9) needs the full Vt: its null vector is Vt's 9th row.
    _, sv, Vt = np.linalg.svd(A, full_matrices=n <= 4)
    if n == 4 and sv[-2] < 1e-9 * sv[0]:  # a degenerate (e.g. collinear) sample has a 2-D null space
        return None
    Hn = Vt[-1].reshape(3, 3)
    H = np.linalg.solve(T_dstnorm_dst, Hn @ T_srcnorm_src)
    if not np.all(np.isfinite(H)) or abs(H[2, 2]) < 1e-12:
        return None
    return H / H[2, 2]


def _fit_homographies(S: np.ndarray, D: np.ndarray) -> list:
    """:func:`_fit_homography` of many samples at once: ``S``, ``D`` ``(B, n, 2)``; a list of ``B`` models
    ``(3, 3)`` or None, each bit for bit ``_fit_homography(S[b], D[b])`` (the same operations on each sample's
    numbers, batched: the normalisers' sums run over the same axis lengths, the SVDs and solves are LAPACK's
    per matrix; ``tests/core/test_ransac.py`` compares them on random samples). RANSAC's minimal samples.
    Returns None instead when LAPACK raised for one of them (the plain fit of that sample raises too)."""
    B, n, _ = S.shape

    def normalisers(p):  # (B, 3, 3): _normaliser of each sample
        c = np.add.reduce(p, axis=1) / n
        d = np.add.reduce(np.sqrt(((p - c[:, None, :]) ** 2).sum(axis=2)), axis=1) / n
        pos = d > 0
        sc = np.where(pos, np.sqrt(2.0) / np.where(pos, d, 1.0), 1.0)
        T_norm_pix = np.zeros((B, 3, 3))
        T_norm_pix[:, 0, 0], T_norm_pix[:, 1, 1], T_norm_pix[:, 2, 2] = sc, sc, 1.0
        T_norm_pix[:, 0, 2], T_norm_pix[:, 1, 2] = -sc * c[:, 0], -sc * c[:, 1]
        return T_norm_pix

    def applied(T_norm_pix, p):  # apply_model of each sample
        h = np.empty((B, n, 3))
        h[..., :2] = p
        h[..., 2] = 1.0
        q = h @ T_norm_pix.transpose(0, 2, 1)
        with np.errstate(divide="ignore", invalid="ignore"):
            return q[..., :2] / q[..., 2:3]

    T_srcnorm_src, T_dstnorm_dst = normalisers(S), normalisers(D)
    sn, dn = applied(T_srcnorm_src, S), applied(T_dstnorm_dst, D)
    A = np.zeros((B, 2 * n, 9))
    A[:, 0::2, 0:2], A[:, 0::2, 2] = sn, 1.0
    A[:, 0::2, 6:8] = -dn[..., :1] * sn
    A[:, 0::2, 8] = -dn[..., 0]
    A[:, 1::2, 3:5], A[:, 1::2, 5] = sn, 1.0
    A[:, 1::2, 6:8] = -dn[..., 1:2] * sn
    A[:, 1::2, 8] = -dn[..., 1]
    try:
        _, sv, Vt = np.linalg.svd(A, full_matrices=n <= 4)
        H = np.linalg.solve(T_dstnorm_dst, Vt[:, -1].reshape(B, 3, 3) @ T_srcnorm_src)
    except np.linalg.LinAlgError:  # a sample whose own fit raises (non-finite pairs): the caller fits each alone
        return None
    out = []
    for b in range(B):
        Hb = H[b]
        if (n == 4 and sv[b, -2] < 1e-9 * sv[b, 0]) or not np.all(np.isfinite(Hb)) or abs(Hb[2, 2]) < 1e-12:
            out.append(None)
        else:
            out.append(Hb / Hb[2, 2])
    return out


_FITTERS = {"translation": _fit_translation, "similarity": _fit_similarity, "affine": _fit_affine,
            "homography": _fit_homography}
#: fitters of many minimal samples at once (bit for bit the plain fitter on each)
_BATCH_FITTERS = {"homography": _fit_homographies}
_UNFITTED = object()


def fit_model(model: str, src, dst) -> np.ndarray | None:
    """Least-squares ``model`` taking ``src`` ``(N, 2)`` to ``dst`` ``(N, 2)``; ``(3, 3)`` or None if degenerate."""
    if model not in MODELS:
        raise ValueError(f"model: expected one of {MODELS}, got {model!r}")
    s, d = _check_pairs(src, dst)
    if len(s) < MIN_SAMPLES[model]:
        raise ValueError(f"{model}: needs at least {MIN_SAMPLES[model]} point pairs, got {len(s)}")
    M = _FITTERS[model](s, d)
    if M is None or not np.all(np.isfinite(M)):
        return None
    return M


def _residual_sq(M, s, d, s_h=None):
    """Squared residuals ``(N,)`` of ``M`` on the pairs (inf where not finite); ``s_h``: ``_homogeneous(s)``,
    if the caller keeps it."""
    r = _dehomogenise((_homogeneous(s) if s_h is None else s_h) @ np.asarray(M, float).T) - d
    e = (r**2).sum(axis=1)
    return np.where(np.isfinite(e), e, np.inf)


def ransac(model: str, src, dst, threshold_px: float, seed: int = 0, max_iterations: int = 2000,
           confidence: float = 0.999, lo_iterations: int = 10) -> RansacResult:
    """Robust fit of ``model`` to the pairs ``src`` -> ``dst`` ``(N, 2)`` (see the module docstring).

    ``threshold_px``: a pair is an inlier when its residual is at most this.
    ``seed``: the generator's seed (the same seed and input give the same
    answer on every machine). Stops after ``max_iterations`` hypotheses or
    when a sample free of outliers has been drawn with ``confidence``.
    """
    if model not in MODELS:
        raise ValueError(f"model: expected one of {MODELS}, got {model!r}")
    s, d = _check_pairs(src, dst)
    if not (np.isfinite(threshold_px) and threshold_px > 0):
        raise ValueError(f"threshold_px: must be finite and > 0, got {threshold_px}")
    n, k = len(s), MIN_SAMPLES[model]
    none = RansacResult(None, np.zeros(n, bool), 0)
    if n < k:
        return none
    t2 = float(threshold_px) ** 2
    fit = _FITTERS[model]
    rng = np.random.default_rng(seed)
    s_h = _homogeneous(s)
    best_cost, best_M, best_count = np.inf, None, 0
    needed, it = max_iterations, 0
    # a model with a batch fitter draws the next samples ahead (the same draws in the same order: the generator
    # is used for nothing else) and fits them together, 8 then up to 64 at a time; the hypotheses are then
    # scored one by one as before, and the draws beyond the stop are dropped
    fit_many, ahead, block = _BATCH_FITTERS.get(model), [], 8
    while it < min(needed, max_iterations):
        it += 1
        if fit_many is not None:
            if not ahead:
                m = min(block, min(needed, max_iterations) - it + 1)
                idx = np.array([rng.choice(n, size=k, replace=False) for _ in range(m)])
                fitted = fit_many(s[idx], d[idx])  # None: LAPACK raised on one; each is then fitted in its turn
                ahead = list(zip(idx, fitted if fitted is not None else [_UNFITTED] * m))[::-1]
                block = min(2 * block, 64)
            row, M = ahead.pop()
            if M is _UNFITTED:
                M = fit(s[row], d[row])
        else:
            idx = rng.choice(n, size=k, replace=False)
            M = fit(s[idx], d[idx])
        if M is None or not np.all(np.isfinite(M)):
            continue
        e = _residual_sq(M, s, d, s_h)
        cost = float(np.minimum(e, t2).sum())
        if cost < best_cost:
            best_cost, best_M = cost, M
            best_count = int((e <= t2).sum())
            w = best_count / n
            if w >= 1.0:
                needed = it
            elif w > 0:
                needed = int(np.ceil(np.log(1 - confidence) / np.log(max(1 - w**k, 1e-300))))
    if best_M is None or best_count < k:
        return RansacResult(None, np.zeros(n, bool), it)
    # local optimisation: least squares on the consensus set until it stops changing
    M = best_M
    inl = _residual_sq(M, s, d, s_h) <= t2
    for _ in range(lo_iterations):
        if inl.sum() < k:
            break
        M2 = fit(s[inl], d[inl])
        if M2 is None or not np.all(np.isfinite(M2)):
            break
        inl2 = _residual_sq(M2, s, d, s_h) <= t2
        if inl2.sum() < inl.sum():
            break  # the refit lost support: keep the previous model
        M, done = M2, bool(np.array_equal(inl2, inl))
        inl = inl2
        if done:
            break
    return RansacResult(M, inl, it)
