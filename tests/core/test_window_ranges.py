"""The window range gap of a designation (scipctl/core/window_ranges.py), on arrays with exact truth."""

import math

import numpy as np
import pytest

from scipctl.core.window_ranges import MIN_WINDOW_POINTS, window_pixels, window_range_gap
from scipctl.core.windows import crop_window


@pytest.mark.parametrize("uv", [(100.0, 50.0), (100.4, 49.6), (7.5, 3.49), (0.0, 0.0)])
def test_window_pixels_are_the_pixels_crop_window_cuts(uv):
    """Same centre rule as point stereo's window (crop_window): the nearest pixel, +-half the side."""
    H, W, k = 120, 200, 10
    image = np.arange(H * W, dtype=float).reshape(H, W)  # each pixel's value is its index: v * W + u
    win, _, _ = crop_window(image, uv, k)
    pix = window_pixels(uv, 2 * k + 1)
    assert pix.shape == ((2 * k + 1) ** 2, 2)
    inside = (pix[:, 0] >= 0) & (pix[:, 1] >= 0) & (pix[:, 0] < W) & (pix[:, 1] < H)
    got = sorted((pix[inside, 1] * W + pix[inside, 0]).astype(int).tolist())
    assert got == sorted(win.astype(int).ravel().tolist())


@pytest.mark.parametrize("uv, window_px", [((1.0, np.nan), 21), ((1.0, 2.0, 3.0), 21), ((1.0, 2.0), 20), ((1.0, 2.0), 0)])
def test_window_pixels_refuse_a_bad_centre_or_size(uv, window_px):
    with pytest.raises(ValueError):
        window_pixels(uv, window_px)


def test_gap_is_zero_on_one_surface_and_the_split_on_two():
    # one surface at the point's range: no gap whatever the spread around it (the median is the point's)
    gap, n = window_range_gap(np.array([4.9, 5.0, 5.1] * 10), 5.0)
    assert gap == 0.0 and n == 30
    # a window that is 60 % a nearer edge at 4.7 m, 40 % the target's ground at 5.3 m; point stereo took 4.7 m
    ranges = np.r_[np.full(60, 4.7), np.full(40, 5.3)]
    gap, n = window_range_gap(ranges, 4.7)
    assert gap == 0.0 and n == 100  # the median is the edge's: nothing to see from the ranges alone
    ranges = np.r_[np.full(40, 4.7), np.full(60, 5.3)]
    gap, _ = window_range_gap(ranges, 4.7)
    assert gap == pytest.approx(0.6 / 4.7, rel=1e-12)  # the window is mostly the ground the point was not put on


def test_gap_ignores_pixels_without_a_range_and_needs_enough_of_them():
    ranges = np.r_[np.full(MIN_WINDOW_POINTS, 5.5), np.full(50, np.nan), [-1.0, 0.0, np.inf]]
    gap, n = window_range_gap(ranges, 5.0)
    assert n == MIN_WINDOW_POINTS and gap == pytest.approx(0.1, rel=1e-12)
    gap, n = window_range_gap(ranges[1:], 5.0)
    assert n == MIN_WINDOW_POINTS - 1 and math.isnan(gap)
    for bad_range in (0.0, -2.0, np.nan):
        assert math.isnan(window_range_gap(np.full(20, 5.0), bad_range)[0])
