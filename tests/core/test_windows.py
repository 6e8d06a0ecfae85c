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
