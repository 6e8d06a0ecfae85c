"""NCC primitives: the map against its definition, the sub-pixel peak fit on an exact quadratic."""

import numpy as np
import pytest

from scipctl.core.ncc import ncc_map, subpixel_peak


def test_subpixel_peak_on_exact_quadratic():
    y, x = np.mgrid[0:7, 0:7].astype(float)
    x0, y0 = 3.3, 2.8
    m = 1.0 - 0.1 * (x - x0) ** 2 - 0.05 * (y - y0) ** 2 - 0.02 * (x - x0) * (y - y0)
    iy, ix = np.unravel_index(np.argmax(m), m.shape)
    dx, dy, sharp = subpixel_peak(m, iy, ix)
    assert ix + dx == pytest.approx(x0, abs=1e-9)
    assert iy + dy == pytest.approx(y0, abs=1e-9)
    ev = np.linalg.eigvalsh(np.array([[0.2, 0.02], [0.02, 0.1]]))
    assert sharp == pytest.approx(ev.min(), rel=1e-9)
    assert subpixel_peak(m, 0, 3)[:2] == (0.0, 0.0)  # border: no fit


def test_ncc_map_matches_definition():
    rng = np.random.default_rng(0)
    img = rng.normal(size=(20, 25))
    tpl = img[5:12, 8:13] * 3.0 + 1.0
    m = ncc_map(tpl, img)
    assert m.shape == (14, 21)
    y, x = 9, 4
    a = img[y : y + 7, x : x + 5]
    a = a - a.mean()
    t = tpl - tpl.mean()
    assert m[y, x] == pytest.approx((a * t).sum() / np.sqrt((a * a).sum() * (t * t).sum()), abs=1e-5)
    assert m[5, 8] == pytest.approx(1.0, abs=1e-5)
