"""core/illumination.log_highpass: against scipy, and what it must not see (a gain, a shadow's interior)."""

import numpy as np
import pytest
import scipy.ndimage as ndi

from scipctl.core.illumination import FLOOR, log_highpass


def _texture(shape=(160, 200), seed=0):
    rng = np.random.default_rng(seed)
    return ndi.gaussian_filter(rng.uniform(0.2, 0.9, shape), 1.0).astype(np.float32)


def test_it_is_the_log_less_its_gaussian_blur_as_scipy_computes_it():
    a = _texture()
    got = log_highpass(a, 3.0)
    logi = np.log(np.maximum(a, np.float32(FLOOR))).astype(np.float64)
    # OpenCV's BORDER_REFLECT is scipy's 'reflect' (edge pixel repeated); both truncate the kernel near 4 sigma.
    # Measured 2.2e-7 (float32 sums, kernel discretisation; OpenCV 5.0 and 4.14, 1 and 2 threads); 1e-4 of a
    # log-intensity is 0.01 % of the intensity, far below one 8-bit count.
    want = logi - ndi.gaussian_filter(logi, 3.0, mode="reflect", truncate=4.0)
    assert got.dtype == np.float32 and got.shape == a.shape
    assert np.max(np.abs(got - want)) < 1e-4


def test_a_gain_cancels():
    a = _texture()
    # log(g a) = log g + log a, and the blur of a constant is that constant: only float32 rounding is left
    # (|log a| < 2, float32 ulp ~2.4e-7 there; a few ulps of margin). Measured 7.2e-7, 3 ulps (OpenCV 5.0 and 4.14, 1
    # and 2 threads): bound 5e-6, 7x that
    assert np.max(np.abs(log_highpass(0.37 * a, 5.0) - log_highpass(a, 5.0))) < 5e-6


def test_a_shadow_changes_only_a_band_along_its_edge():
    a = _texture()
    shade = np.ones_like(a)
    shade[:, 100:] = 0.25  # the shadow: a quarter of the light beyond column 100
    lit, shadowed = log_highpass(a, 4.0), log_highpass(a * shade, 4.0)
    diff = np.abs(shadowed - lit)
    # beyond 4 sigma (16 px) of the edge the blur's kernel (truncated at 4 sigma) no longer reaches across it: float32
    # rounding only, measured 0 and 7.7e-7 (OpenCV 5.0 and 4.14, 1 and 2 threads), bound 5e-6 as above
    assert diff[:, :83].max() < 5e-6 and diff[:, 117:].max() < 5e-6
    # at the edge the step remains, up to |log 0.25| / 2 = 0.69 on either side: measured 0.62 (OpenCV 5.0 and 4.14, 1
    # and 2 threads), bound 0.5 (0.72 of the ideal step)
    assert diff[:, 98:102].max() > 0.5
    # the raw images' NCC over a window across the edge collapses; the filtered images' does much less
    win = (slice(40, 120), slice(60, 140))

    def ncc(x, y):
        x, y = x - x.mean(), y - y.mean()
        return float((x * y).sum() / np.sqrt((x * x).sum() * (y * y).sum()))

    # measured gain 0.47 (OpenCV 5.0 and 4.14, 1 and 2 threads); bound 0.2 (2.4x margin)
    assert ncc(lit[win], shadowed[win]) > ncc(a[win], (a * shade)[win]) + 0.2


def test_dark_and_missing_pixels():
    a = _texture()
    a[10, 10] = 0.0
    a[20, 20] = np.nan
    out = log_highpass(a, 2.0)
    assert np.isfinite(out[10, 10]) and np.isnan(out[20, 20])
    assert np.isfinite(np.delete(out.ravel(), 20 * a.shape[1] + 20)).all()


@pytest.mark.parametrize("image, sigma", [(np.zeros((5,)), 1.0), (np.zeros((1, 5)), 1.0), (np.zeros((5, 5)), 0.0),
                                          (np.zeros((5, 5)), np.nan), (np.zeros((5, 5, 2)), 1.0)])
def test_bad_arguments_are_refused_naming_them(image, sigma):
    with pytest.raises(ValueError, match="image|sigma_px"):
        log_highpass(image, sigma)
