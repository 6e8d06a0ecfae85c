"""Image windows: the centre convention, clipping at the border, rescaling between cameras."""

import numpy as np
import pytest

from scipctl.core.windows import extract_window, scale_window, window_scale_for_handoff


def test_extract_window_centre_convention_and_border():
    v, u = np.mgrid[0:50, 0:60].astype(np.float32)
    ramp = 3.0 * u + 0.5 * v + 10.0  # bilinear resampling is exact on a linear ramp
    c = (20.3, 30.75)
    w = extract_window(ramp, c, 4)
    assert w.shape == (9, 9) and w.dtype == np.float32
    assert w[4, 4] == pytest.approx(3.0 * 20.3 + 0.5 * 30.75 + 10.0, abs=1e-3)
    assert np.allclose(np.diff(w, axis=1), 3.0, atol=1e-3)
    assert np.allclose(np.diff(w, axis=0), 0.5, atol=1e-3)
    # at the border the missing part repeats the edge pixels
    wb = extract_window(ramp, (1.0, 25.0), 4)
    assert np.allclose(wb[:, :3], wb[:, [3]], atol=1e-4)
    assert np.allclose(wb[4, 3:], 3.0 * np.arange(0, 6) + 0.5 * 25 + 10.0, atol=1e-3)


def test_scale_window_keeps_centre_and_scale():
    v, u = np.mgrid[0:61, 0:61].astype(np.float32)
    ramp = 2.0 * (u - 30) - 1.0 * (v - 30) + 50.0
    w = scale_window(ramp, 1.0 / 3.0)
    assert w.shape == (19, 19)  # largest odd <= 61 / 3
    assert w[9, 9] == pytest.approx(50.0, abs=1e-3)
    # a linear ramp stays linear; slope per output pixel is 3x (blur keeps ramps away from the border)
    assert np.allclose(np.diff(w[5:14, 5:14], axis=1), 6.0, atol=1e-2)
    assert np.allclose(np.diff(w[5:14, 5:14], axis=0), -3.0, atol=1e-2)
    w2 = scale_window(ramp[:41, :41], 1.5)
    assert w2.shape == (61, 61)
    assert w2[30, 30] == pytest.approx(ramp[20, 20], abs=1e-3)
    with pytest.raises(ValueError):
        scale_window(ramp, 0.0)


def test_window_scale_for_handoff():
    # pancam -> navcam at the same range: IFOV ratio
    assert window_scale_for_handoff(0.28e-3, 4.5, 0.82e-3, 4.5) == pytest.approx(0.28 / 0.82)
    # px per metre: 1 / (r i) in each camera
    r1, i1, r2, i2 = 3.0, 0.8e-3, 1.2, 2.1e-3
    s = window_scale_for_handoff(i1, r1, i2, r2)
    assert s == pytest.approx((1 / (r2 * i2)) / (1 / (r1 * i1)))
    with pytest.raises(ValueError):
        window_scale_for_handoff(0.0, 1.0, 1.0, 1.0)


def test_filtered_crop_is_the_image_filtered_where_the_reach_lies():
    """Within ``reach_px`` of the centre the crop is the whole image filtered (the margin covers the filter's radius),
    the origin is aligned, and a region outside the image gives None."""
    from scipctl.core.windows import filtered_crop, median_image

    rng = np.random.default_rng(5)
    img = rng.random((300, 400)).astype(np.float32)
    crop, o = filtered_crop(img, (201.3, 150.6), 40, 3, lambda a: median_image(a, 7))
    assert o[0] % 64 == 0 and o[1] % 64 == 0
    whole = median_image(img, 7)
    u0, v0 = int(o[0]), int(o[1])
    # the pixels within the reach of the centre (201, 151)
    sub = crop[151 - 40 - v0:151 + 41 - v0, 201 - 40 - u0:201 + 41 - u0]
    assert np.array_equal(sub, whole[111:192, 161:242])
    same, o2 = filtered_crop(img, (201.3, 150.6), 40, 3, lambda a: a)
    assert np.array_equal(o2, o) and np.array_equal(same, img[v0:v0 + same.shape[0], u0:u0 + same.shape[1]])
    assert filtered_crop(img, (-500.0, 150.0), 40, 3, lambda a: a)[0] is None
    with pytest.raises(ValueError, match="center_uv"):
        filtered_crop(img, (np.nan, 1.0), 40, 3, lambda a: a)


def test_the_median_removes_a_speck_and_keeps_an_edge():
    from scipctl.core.windows import median_image

    img = np.zeros((21, 21), np.float32)
    img[:, 11:] = 1.0  # a vertical edge
    img[5, 4] = 1.0  # a one-pixel speck on the dark side
    img[15, 16] = 0.0  # a one-pixel pit on the bright side
    out = median_image(img, 3)
    assert out.dtype == np.float32 and out.shape == img.shape
    assert out[5, 4] == 0.0 and out[15, 16] == 1.0
    assert np.array_equal(out[:, :11] == 0.0, np.ones((21, 11), bool)) and np.all(out[:, 11:] == 1.0)
    for bad in (1, 2, 4, 3.5):
        with pytest.raises(ValueError, match="size_px"):
            median_image(img, bad)
