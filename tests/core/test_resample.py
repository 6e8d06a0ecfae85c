"""Exact sub-pixel resampling (scipctl.core.resample): exact truth, OpenCV 5's exact-position warp, borders."""

import numpy as np
import pytest

from scipctl.core.resample import (cubic_axis, cubic_weights, sample_bicubic, sample_bicubic_grid, sample_bicubic_grids,
                                   sample_bicubic_uv, sample_bilinear)

cv2 = pytest.importorskip("cv2")


def _texture(shape=(120, 140), seed=0):
    r = np.random.default_rng(seed)
    return cv2.GaussianBlur(r.normal(0, 1, shape).astype(np.float32), (0, 0), 2.0)


def test_cubic_weights_partition_unity_and_interpolate():
    t = np.linspace(0, 0.999, 101)
    w = cubic_weights(t)
    np.testing.assert_allclose(w.sum(axis=-1), 1.0, rtol=0, atol=1e-15)
    np.testing.assert_allclose(cubic_weights(np.array(0.0)), [0, 1, 0, 0], rtol=0, atol=1e-15)
    # Keys' kernel reproduces a linear function exactly only with a = -0.5: sum w_k (k - 1) = t (offsets -1..2);
    # OpenCV's a = -0.75 trades that for a sharper response
    np.testing.assert_allclose(cubic_weights(t, a=-0.5) @ np.array([-1.0, 0.0, 1.0, 2.0]), t, rtol=0, atol=1e-14)
    assert np.abs(w @ np.array([-1.0, 0.0, 1.0, 2.0]) - t).max() > 1e-3


@pytest.mark.parametrize("sampler", [sample_bilinear, sample_bicubic])
def test_integer_positions_return_the_pixels_and_bilinear_ramps_are_exact(sampler):
    img = _texture()
    v, u = np.mgrid[3:40, 5:60].astype(float)
    np.testing.assert_array_equal(sampler(img, u, v), img[3:40, 5:60].astype(np.float64))
    if sampler is sample_bicubic:
        return  # a = -0.75 does not reproduce ramps (above); the OpenCV comparison checks its values
    # bilinear reproduces a linear ramp exactly at any position
    ramp = (0.5 * np.arange(140)[None, :] - 0.25 * np.arange(120)[:, None]).astype(np.float64)
    r = np.random.default_rng(1)
    uu, vv = r.uniform(2, 130, 500), r.uniform(2, 110, 500)
    np.testing.assert_allclose(sampler(ramp, uu, vv), 0.5 * uu - 0.25 * vv, rtol=0, atol=1e-12)


@pytest.mark.parametrize("flag,sampler", [(cv2.INTER_LINEAR, sample_bilinear), (cv2.INTER_CUBIC, sample_bicubic)])
def test_agrees_with_opencv_warp(flag, sampler):
    """OpenCV's warpAffine (replicate border) as an independent implementation. OpenCV 5 samples at the exact
    position: equal to float32 rounding (1e-6 on a unit-range image; measured 2.5e-7). OpenCV 4 rounds positions
    to 1/32 px: a sample then differs by at most |gradient| / 64 per axis (the texture's gradient is < 0.25 per px,
    so 0.008; measured 0.0021)."""
    img = _texture()
    for du, dv in ((10.3, 7.6), (-3.3, -2.2), (50.71, 33.02)):
        M = np.array([[1.0, 0.0, du], [0.0, 1.0, dv]])
        ref = cv2.warpAffine(img, M, (60, 50), flags=flag | cv2.WARP_INVERSE_MAP, borderMode=cv2.BORDER_REPLICATE)
        v, u = np.mgrid[0:50, 0:60].astype(float)
        got = sampler(img, u + du, v + dv)
        bound = 1e-5 if int(cv2.__version__.split(".")[0]) >= 5 else 0.008
        assert np.abs(got - ref).max() < bound, (du, dv, cv2.__version__)


def test_border_repeats_the_edge_and_bad_input():
    img = _texture((10, 12))
    np.testing.assert_allclose(sample_bilinear(img, np.array([-5.0]), np.array([-7.0])), [img[0, 0]], rtol=0, atol=1e-7)
    np.testing.assert_allclose(sample_bicubic(img, np.array([30.0]), np.array([4.0])), [img[4, 11]], rtol=0, atol=1e-7)
    with pytest.raises(ValueError):
        sample_bicubic(img, np.zeros(3), np.zeros(2))
    with pytest.raises(ValueError):
        sample_bilinear(img, np.array([np.nan]), np.array([1.0]))
    with pytest.raises(ValueError):
        sample_bicubic(img[None], np.zeros(1), np.zeros(1))


@pytest.mark.parametrize("contiguous", [True, False])
def test_grid_sampling_is_bit_for_bit_the_pointwise_sampling(contiguous):
    """sample_bicubic_grid (taps per column and per row) gives exactly sample_bicubic on the meshgrid: the NCC
    refinement's patches must not move by a bit (docs/sequence.md, "Speed")."""
    rng = np.random.default_rng(7)
    img = rng.random((23, 31)).astype(np.float32)
    if not contiguous:
        img = np.asfortranarray(img)
    for du, dv in [(0.0, 0.0), (0.3, -0.2), (-1.75, 0.125), (1e-9, 0.999999)]:
        # columns and rows inside, on and beyond the border (the taps repeat the edge pixels there)
        u = np.arange(-3, 34, dtype=np.float64) + du
        v = np.arange(-2, 26, 1.5, dtype=np.float64) + dv
        U, V = np.meshgrid(u, v)
        want = sample_bicubic(img, U, V)
        got = sample_bicubic_grid(img, u, v)
        assert got.dtype == want.dtype and got.shape == want.shape
        assert np.array_equal(got, want)
        assert np.array_equal(sample_bicubic_grid(img, cubic_axis(u, img.shape[1]), cubic_axis(v, img.shape[0])), want)
    with pytest.raises(ValueError):
        sample_bicubic_grid(img, np.array([np.nan]), np.zeros(2))


def _bits(a):
    """The float64 array's bit patterns (tells -0.0 from 0.0 and compares NaNs)."""
    return np.ascontiguousarray(a, dtype=np.float64).view(np.int64)


@pytest.mark.parametrize("dtype", [np.float32, np.float64, np.uint8, np.uint16])
def test_grids_are_bit_for_bit_the_grid_sampling(dtype):
    """sample_bicubic_grids (several column and row shifts at once: the NCC peak refinement's 3 x 3 steps) gives,
    for every pair, exactly sample_bicubic_grid: random images, shapes and positions (inside, on and beyond the
    border), integer positions (zero weights) and images holding -0.0 (the sum's zeros keep their sign)."""
    rng = np.random.default_rng(11)
    for trial in range(300):
        H, W = rng.integers(1, 40, 2)
        h, w = rng.integers(1, 30, 2)
        A, B = rng.integers(1, 4, 2)
        if trial < 6:  # a single column (and a single grid): numpy would sum one column pairwise
            w, A = 1, 1
        if dtype in (np.uint8, np.uint16):
            img = rng.integers(0, np.iinfo(dtype).max, (H, W), endpoint=True).astype(dtype)
        else:
            img = (rng.standard_normal((H, W)) * rng.choice([1e-3, 1.0, 255.0])).astype(dtype)
            img[rng.random((H, W)) < 0.2] = -0.0
            img[rng.random((H, W)) < 0.1] = 0.0
        if trial % 3 == 0:  # whole-pixel positions and shifts: weights exactly 0 and 1
            u = rng.integers(-3, W + 3, w).astype(np.float64)[None] + rng.integers(-2, 3, A)[:, None]
            v = rng.integers(-3, H + 3, h).astype(np.float64)[None] + rng.integers(-2, 3, B)[:, None]
        else:
            u = np.sort(rng.uniform(-3, W + 3, w))[None] + rng.uniform(-1, 1, A)[:, None]
            v = np.sort(rng.uniform(-3, H + 3, h))[None] + rng.uniform(-1, 1, B)[:, None]
        got = sample_bicubic_grids(img, u, v)
        assert got.shape == (B, A, h, w) and got.dtype == np.float64 and got.flags.c_contiguous
        for b in range(B):
            for a in range(A):
                assert np.array_equal(_bits(got[b, a]), _bits(sample_bicubic_grid(img, u[a], v[b])))
    with pytest.raises(ValueError):
        sample_bicubic_grids(np.zeros((4, 4)), np.array([[np.nan]]), np.zeros((1, 2)))
    with pytest.raises(ValueError):
        sample_bicubic_grids(np.zeros((4, 4)), np.zeros(3), np.zeros((1, 2)))


@pytest.mark.parametrize("dtype", [np.float32, np.float64, np.uint8, np.uint16])
@pytest.mark.parametrize("contiguous", [True, False])
def test_stacked_sampling_is_bit_for_bit_the_pointwise_sampling(dtype, contiguous):
    """sample_bicubic_uv (u and v stacked: affine point stereo's Nelder-Mead) gives exactly sample_bicubic:
    random images, shapes and positions inside, on and beyond the border, whole-pixel positions, -0.0 pixels."""
    rng = np.random.default_rng(12)
    for trial in range(300):
        H, W = rng.integers(1, 40, 2)
        shape = tuple(rng.integers(1, 25, rng.integers(1, 3))) if trial >= 4 else [(1,), (1, 1), (2,), (1, 2)][trial]
        if dtype in (np.uint8, np.uint16):
            img = rng.integers(0, np.iinfo(dtype).max, (H, W), endpoint=True).astype(dtype)
        else:
            img = (rng.standard_normal((H, W)) * rng.choice([1e-3, 1.0, 255.0])).astype(dtype)
            img[rng.random((H, W)) < 0.2] = -0.0
        if not contiguous:
            img = np.asfortranarray(img)
        if trial % 3 == 0:
            u = rng.integers(-3, W + 3, shape).astype(np.float64)
            v = rng.integers(-3, H + 3, shape).astype(np.float64)
        else:
            u = rng.uniform(-3, W + 3, shape)
            v = rng.uniform(-3, H + 3, shape)
        got = sample_bicubic_uv(img, np.stack([u, v]))
        want = sample_bicubic(img, u, v)
        assert got.shape == want.shape == shape and got.dtype == want.dtype
        assert np.array_equal(_bits(got), _bits(want))
    with pytest.raises(ValueError):
        sample_bicubic_uv(np.zeros((4, 4)), np.array([[np.nan], [0.0]]))
    with pytest.raises(ValueError):
        sample_bicubic_uv(np.zeros((4, 4)), np.zeros((3, 2)))


def test_shifted_image_is_bicubic_sampling_on_the_shifted_grid():
    """Separable translation (rows, then columns) against the 2-D kernel at the same positions: equal up to
    float64 rounding of a different summation order (values of order 1: 1e-12); whole-pixel shifts move pixels
    exactly, the border repeated."""
    from scipctl.core.resample import sample_bicubic, shifted_image

    rng = np.random.default_rng(7)
    img = rng.random((37, 53))
    for d in [(0.3, -2.48), (-1.75, 0.5), (0.0, 0.0), (4.2, 3.9)]:
        out = shifted_image(img, d)
        U, V = np.meshgrid(np.arange(53) + d[0], np.arange(37) + d[1])
        assert out.shape == img.shape
        assert np.max(np.abs(out - sample_bicubic(img, U, V))) < 1e-12
    out = shifted_image(img, (2.0, -3.0))
    assert np.array_equal(out[3:, :-2], img[:-3, 2:])
    assert np.array_equal(out[:3, :-2], np.repeat(img[:1, 2:], 3, axis=0))  # rows above the image: the first row
    with pytest.raises(ValueError):
        shifted_image(img, (np.nan, 0.0))
