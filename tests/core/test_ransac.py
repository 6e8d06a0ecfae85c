"""Seeded LO-RANSAC (scipctl.core.ransac): exact truth, outliers, determinism, order independence."""

import numpy as np
import pytest

from scipctl.core.ransac import MIN_SAMPLES, MODELS, apply_model, fit_model, ransac

_c, _s = 1.3 * np.cos(np.radians(7)), 1.3 * np.sin(np.radians(7))
TRUE = {
    "translation": np.array([[1.0, 0, -12.5], [0, 1.0, 40.25], [0, 0, 1.0]]),
    "similarity": np.array([[_c, -_s, -60.0], [_s, _c, 45.0], [0, 0, 1.0]]),
    "affine": np.array([[1.1, 0.07, -35.0], [-0.05, 0.92, 22.0], [0, 0, 1.0]]),
    "homography": np.array([[1.08, 0.06, -35.0], [-0.04, 0.93, 22.0], [1.2e-4, -6e-5, 1.0]]),
}


def _pairs(model, n=200, outlier_fraction=0.3, noise_px=0.0, seed=0):
    r = np.random.default_rng(seed)
    src = r.uniform(0, 600, (n, 2))
    dst = apply_model(TRUE[model], src) + r.normal(0, noise_px, (n, 2)) if noise_px else apply_model(TRUE[model], src)
    bad = r.random(n) < outlier_fraction
    dst[bad] = r.uniform(0, 600, (int(bad.sum()), 2))
    # an outlier may land on the model by chance; the truth is what is within the threshold of the true model
    return src, dst, bad


@pytest.mark.parametrize("model", MODELS)
def test_least_squares_fit_recovers_an_exact_model(model):
    src, dst, _ = _pairs(model, n=50, outlier_fraction=0.0)
    M = fit_model(model, src, dst)
    # exact data: only rounding error (entries are O(1..100); 1e-8 is ~1e6 ulps of slack for the SVD/lstsq)
    np.testing.assert_allclose(M, TRUE[model], rtol=0, atol=1e-8)


@pytest.mark.parametrize("model", MODELS)
def test_ransac_finds_the_model_among_30_percent_outliers(model):
    src, dst, bad = _pairs(model)
    res = ransac(model, src, dst, threshold_px=1.0, seed=0)
    assert res.model is not None
    # the consensus set is exactly the clean pairs (plus any outlier that fell within 1 px of the true model)
    within = np.linalg.norm(apply_model(TRUE[model], src) - dst, axis=1) <= 1.0
    np.testing.assert_array_equal(res.inliers, within)
    assert (~bad <= res.inliers).all()
    # refitted by least squares on exact inliers: the true model to rounding
    np.testing.assert_allclose(res.model, TRUE[model], rtol=0, atol=1e-7)


@pytest.mark.parametrize("model", ["similarity", "homography"])
def test_noisy_inliers_give_a_model_within_the_noise(model):
    """0.3 px noise on 140 inliers: the least-squares refit maps points to well within the noise (checked at the
    points: a 0.3 px per-point error averages down to ~0.3 / sqrt(140 / dof) px)."""
    src, dst, bad = _pairs(model, noise_px=0.3, seed=3)
    res = ransac(model, src, dst, threshold_px=1.5, seed=0)
    err = np.linalg.norm(apply_model(res.model, src[~bad]) - apply_model(TRUE[model], src[~bad]), axis=1)
    assert err.max() < 0.3


@pytest.mark.parametrize("model", ["similarity", "affine", "homography"])
def test_same_seed_same_bits_and_the_draw_does_not_matter(model):
    src, dst, _ = _pairs(model, noise_px=0.5, seed=5)
    a = ransac(model, src, dst, threshold_px=2.0, seed=0)
    b = ransac(model, src, dst, threshold_px=2.0, seed=0)
    assert np.array_equal(a.model, b.model) and np.array_equal(a.inliers, b.inliers)
    # another seed or another order of the pairs draws other samples; the local optimisation ends on the same
    # consensus set, so the same model up to rounding
    c = ransac(model, src, dst, threshold_px=2.0, seed=12345)
    p = np.random.default_rng(9).permutation(len(src))
    d = ransac(model, src[p], dst[p], threshold_px=2.0, seed=0)
    assert np.array_equal(c.inliers, a.inliers) and np.array_equal(d.inliers, a.inliers[p])
    np.testing.assert_allclose(c.model, a.model, rtol=0, atol=1e-9)
    np.testing.assert_allclose(d.model, a.model, rtol=0, atol=1e-9)


def test_degenerate_and_too_few_pairs():
    line = np.c_[np.linspace(0, 100, 10), np.linspace(0, 50, 10)]
    assert fit_model("homography", line[:4], line[:4] + 3.0) is None  # collinear: no unique homography
    res = ransac("homography", line, line + 3.0, threshold_px=1.0)
    assert res.model is None and not res.inliers.any()
    res = ransac("affine", line[:2], line[:2], threshold_px=1.0)
    assert res.model is None and res.inliers.shape == (2,)
    with pytest.raises(ValueError):
        fit_model("similarity", line[:1], line[:1])
    with pytest.raises(ValueError):
        ransac("projective", line, line, threshold_px=1.0)
    with pytest.raises(ValueError):
        ransac("affine", line, line[:, :1], threshold_px=1.0)
    with pytest.raises(ValueError):
        ransac("affine", line, line, threshold_px=float("nan"))
    assert MIN_SAMPLES["homography"] == 4


def _fit_homography_plain(s, d):
    """The homography fit as first written (the full SVD, U included): the reference that
    ransac._fit_homography must reproduce bit for bit."""
    from scipctl.core.ransac import _normaliser

    T_srcnorm_src, T_dstnorm_dst = _normaliser(s), _normaliser(d)
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
    _, sv, Vt = np.linalg.svd(A)
    if n == 4 and sv[-2] < 1e-9 * sv[0]:
        return None
    Hn = Vt[-1].reshape(3, 3)
    H = np.linalg.solve(T_dstnorm_dst, Hn @ T_srcnorm_src)
    if not np.all(np.isfinite(H)) or abs(H[2, 2]) < 1e-12:
        return None
    return H / H[2, 2]


def test_homography_fit_is_bit_for_bit_the_full_svd_fit():
    """The homography fit without the SVD's U gives exactly the fit with it: random pairs (exact, noisy and
    random homographies, outliers, collinear minimal samples), 4 to 700 pairs."""
    from scipctl.core.ransac import _fit_homography

    rng = np.random.default_rng(3)
    for trial in range(400):
        n = int(rng.choice([4, 4, 5, 6, 7, 8, 9, 12, 20, 50, 150, 700]))
        s = rng.uniform(0, 1024, (n, 2))
        H = np.eye(3) + rng.normal(0, [[0.05, 0.05, 20], [0.05, 0.05, 20], [1e-4, 1e-4, 0]], (3, 3))
        d = apply_model(H, s) + rng.normal(0, rng.choice([0.0, 0.3, 3.0]), (n, 2))
        if trial % 5 == 0:
            d[: n // 3] = rng.uniform(0, 1024, (n // 3, 2))
        if trial % 17 == 0:  # collinear sources: degenerate
            s[:, 1] = 2.0 * s[:, 0] + 1.0
        got, want = _fit_homography(s, d), _fit_homography_plain(s, d)
        assert (got is None) == (want is None)
        if got is not None:
            assert np.array_equal(got, want)


def test_batched_minimal_homography_fits_are_bit_for_bit_the_plain_fits():
    """_fit_homographies (RANSAC's minimal samples fitted together) gives exactly _fit_homography on each sample:
    random, noisy, collinear and repeated-point samples at several coordinate scales."""
    from scipctl.core.ransac import _fit_homographies, _fit_homography

    rng = np.random.default_rng(8)
    nones = 0
    for trial in range(120):
        n_pts = 40
        s = rng.uniform(0, 1024, (n_pts, 2)) * rng.choice([1e-3, 1.0, 1e3])
        d = s + rng.normal(0, rng.choice([0.5, 5.0, 50.0]), s.shape)
        if trial % 7 == 0:
            s[:, 1] = 3.0 * s[:, 0] - 2.0  # collinear: every sample degenerate
        if trial % 11 == 0:
            s[::2] = s[0]  # repeated points
        for k in (4, 4, 5, 9):
            idx = np.array([rng.choice(n_pts, k, replace=False) for _ in range(int(rng.integers(1, 40)))])
            got = _fit_homographies(s[idx], d[idx])
            assert len(got) == len(idx)
            for b, row in enumerate(idx):
                want = _fit_homography(s[row], d[row])
                assert (got[b] is None) == (want is None)
                nones += want is None
                if want is not None:
                    assert np.array_equal(got[b], want)
    assert nones > 0


def _ransac_plain(model, src, dst, threshold_px, seed=0, max_iterations=2000, confidence=0.999, lo_iterations=10):
    """RANSAC as first written (one draw, one fit, one score at a time): the reference that ransac (which fits
    homography samples in batches drawn ahead) must reproduce bit for bit."""
    from scipctl.core.ransac import _FITTERS, _homogeneous, _residual_sq

    s, d = np.asarray(src, float), np.asarray(dst, float)
    n, k = len(s), MIN_SAMPLES[model]
    if n < k:
        return None, np.zeros(n, bool), 0
    t2 = float(threshold_px) ** 2
    fit = _FITTERS[model]
    rng = np.random.default_rng(seed)
    s_h = _homogeneous(s)
    best_cost, best_M, best_count = np.inf, None, 0
    needed, it = max_iterations, 0
    while it < min(needed, max_iterations):
        it += 1
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
        return None, np.zeros(n, bool), it
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
            break
        M, done = M2, bool(np.array_equal(inl2, inl))
        inl = inl2
        if done:
            break
    return M, inl, it


@pytest.mark.parametrize("model", ["homography", "similarity", "affine"])
def test_ransac_is_bit_for_bit_the_one_at_a_time_loop(model):
    """The same models, inliers and iteration counts as the one-draw-at-a-time loop, on random matches with
    0-90 % outliers (short and long runs, early stops inside a batch) and a few max_iterations."""
    rng = np.random.default_rng(9)
    for trial in range(40):
        n = int(rng.choice([4, 6, 12, 30, 80, 300]))
        src = rng.uniform(0, 1024, (n, 2))
        H = np.eye(3) + rng.normal(0, [[0.03, 0.03, 15], [0.03, 0.03, 15], [5e-5, 5e-5, 0]], (3, 3))
        dst = apply_model(H, src) + rng.normal(0, 0.5, (n, 2))
        bad = rng.random(n) < rng.uniform(0, 0.9)
        dst[bad] = rng.uniform(0, 1024, (int(bad.sum()), 2))
        kw = dict(seed=int(rng.integers(0, 1000)), max_iterations=int(rng.choice([1, 7, 100, 2000])))
        got = ransac(model, src, dst, 2.0, **kw)
        M, inl, it = _ransac_plain(model, src, dst, 2.0, **kw)
        assert got.iterations == it
        assert np.array_equal(got.inliers, inl)
        assert (got.model is None) == (M is None)
        if M is not None:
            assert np.array_equal(got.model, M)
