"""Rendering: determinism, crops, sub-pixel response, cross-view consistency, radiometry."""

import numpy as np
import pytest

from scipctl.sim.render import Sensor, auto_exposure, crop_model, expose, render_radiance, subpixel_offsets
from scipctl.sim.marks import project_visible


def _product(sim, stop, cam, eye):
    return next(p for p in sim.products if p.stop == stop and p.camera == cam and p.eye == eye)


def _ncc(a, b):
    a = a - a.mean()
    b = b - b.mean()
    return float((a * b).sum() / np.sqrt((a * a).sum() * (b * b).sum()))


def test_subpixel_offsets_tile_the_pixel():
    for s in (1, 2, 3, 4):
        o = subpixel_offsets(s)
        assert len(o) == s and abs(o.mean()) < 1e-15
        assert np.allclose(np.diff(o), 1.0 / s) and o[0] == pytest.approx(-0.5 + 0.5 / s)


def test_render_is_deterministic_and_thread_independent(run_exact):
    p = _product(run_exact, "near", "hazcam", "left")
    a = render_radiance(run_exact.scene, p.model_true_site, p.width, p.height, 2, threads=1, rows_per_block=16)
    b = render_radiance(run_exact.scene, p.model_true_site, p.width, p.height, 2, threads=2, rows_per_block=16)
    assert a.shape == (128, 128) and a.dtype == np.float32
    assert np.array_equal(a, b)
    assert np.isfinite(a).all() and a.min() > 0


def test_crop_renders_the_same_pixels(run_full_exact):
    p = _product(run_full_exact, "near", "navcam", "left")
    m = p.model_true_site
    big = render_radiance(run_full_exact.scene, crop_model(m, 480, 500), 48, 48, 2)
    small = render_radiance(run_full_exact.scene, crop_model(m, 496, 508), 24, 24, 2)
    diff = np.abs(big[8:32, 16:40] - small)
    assert np.median(diff) < 1e-6 and np.mean(diff < 1e-4) > 0.99


def _lk_shift(a, b, iters=20, border=6):
    """Sub-pixel ``s`` with ``a(x + s) = b(x)`` by Lucas-Kanade (Gauss-Newton on bicubic resampling)."""
    import cv2

    h, w = a.shape
    X, Y = np.meshgrid(np.arange(w, dtype=np.float32), np.arange(h, dtype=np.float32))
    s = np.zeros(2)
    inner = (slice(border, h - border), slice(border, w - border))
    for _ in range(iters):
        ws = cv2.remap(a, X + np.float32(s[0]), Y + np.float32(s[1]), cv2.INTER_CUBIC)
        gx = cv2.Sobel(ws, cv2.CV_32F, 1, 0, ksize=3) / 8.0
        gy = cv2.Sobel(ws, cv2.CV_32F, 0, 1, ksize=3) / 8.0
        r = (b - ws)[inner].ravel()
        G = np.stack([gx[inner].ravel(), gy[inner].ravel()], 1).astype(np.float64)
        step = np.linalg.solve(G.T @ G, G.T @ r)
        s += step
        if np.abs(step).max() < 1e-5:
            break
    return s


def test_subpixel_shift_of_the_camera_shifts_the_image_by_that_much(run_full_exact):
    """A window moved by (0.3, -0.2) px shows the scene moved by that much: sub-pixel truth means something."""
    p = _product(run_full_exact, "near", "hazcam", "left")
    m = p.model_true_site
    mark = run_full_exact.downlink.targets[0].mark_in(p.product_id)
    u0, v0 = round(mark.u) - 32, round(mark.v) - 32
    a = render_radiance(run_full_exact.scene, crop_model(m, u0, v0), 64, 64, 3)
    b = render_radiance(run_full_exact.scene, crop_model(m, u0 + 0.3, v0 - 0.2), 64, 64, 3)
    s = _lk_shift(a, b)
    assert s[0] == pytest.approx(0.3, abs=0.03) and s[1] == pytest.approx(-0.2, abs=0.03)
    assert np.abs(_lk_shift(a, a)).max() < 1e-6


def _warped_ncc(sim, src, dst, target_index, half=15, ss=2):
    """NCC between a window of ``src`` around a target's mark and ``dst`` resampled there through the true
    geometry (ray cast from src's true model, projection into dst's true model). Occluded pixels are dropped."""
    import cv2

    mark = sim.downlink.targets[target_index].mark_in(src.product_id)
    ms, md = src.model_true_site, dst.model_true_site
    u0, v0 = round(mark.u) - half, round(mark.v) - half
    n = 2 * half + 1
    a = render_radiance(sim.scene, crop_model(ms, u0, v0), n, n, ss)
    U, V = np.meshgrid(np.arange(n) + u0, np.arange(n) + v0)
    o, d = ms.unproject(np.stack([U.ravel(), V.ravel()], 1).astype(float))
    X = sim.scene.cast(o, d).points
    uv, vis = project_visible(sim.scene, md, dst.width, dst.height, X)
    lo = np.floor(uv[vis].min(axis=0)).astype(int) - 3
    hi = np.ceil(uv[vis].max(axis=0)).astype(int) + 3
    b = render_radiance(sim.scene, crop_model(md, lo[0], lo[1]), hi[0] - lo[0], hi[1] - lo[1], ss)
    mx = (uv[:, 0] - lo[0]).reshape(n, n).astype(np.float32)
    my = (uv[:, 1] - lo[1]).reshape(n, n).astype(np.float32)
    w = cv2.remap(b, np.nan_to_num(mx), np.nan_to_num(my), cv2.INTER_CUBIC)
    keep = vis.reshape(n, n)
    return _ncc(a[keep], w[keep]), float(keep.mean())


def test_stereo_views_agree_through_the_true_geometry(run_full_exact):
    """Left and right near-navcam radiance, right warped into the left through the true 3-D surface."""
    sim = run_full_exact
    scores = []
    for k in range(len(sim.downlink.targets)):
        ncc, frac = _warped_ncc(sim, _product(sim, "near", "navcam", "left"), _product(sim, "near", "navcam", "right"), k)
        assert frac > 0.5
        scores.append(ncc)
    assert min(scores) > 0.95, scores


def test_far_apart_views_agree_through_the_true_geometry(run_full_exact):
    """Near navcam (looking down from 1.5 m) vs hazcam (0.5 m, 45 deg): very different viewpoints, same surface."""
    sim = run_full_exact
    scores = []
    for k in range(len(sim.downlink.targets)):
        ncc, frac = _warped_ncc(sim, _product(sim, "near", "hazcam", "left"), _product(sim, "near", "navcam", "left"), k)
        if frac > 0.5:
            scores.append(ncc)
    assert scores and min(scores) > 0.8, scores


def test_exposure_bits_saturation_and_noise():
    rad = np.linspace(0, 2.0, 10000, dtype=np.float32).reshape(100, 100)
    s8, s12 = Sensor(bits=8), Sensor(bits=12)
    e = auto_exposure(rad, s8)
    assert np.percentile(rad, 99.5) * e == pytest.approx(s8.target_fraction)
    a = expose(rad, e, 1.0, s8, None)
    assert a.dtype == np.uint8 and a.min() == 0 and a.max() == round(255 * rad.max() * e)  # no clipping
    over = expose(rad, 2 * e, 1.0, s8, None)  # twice too long: the top saturates
    assert over.max() == 255 and np.mean(over == 255) == pytest.approx(np.mean(rad * 2 * e >= 1 - 0.5 / 255), abs=1e-3)
    b = expose(rad, 2 * e, 1.0, s12, None)
    assert b.dtype == np.uint16 and b.max() == 65535  # 4095 bit-replicated
    v12 = b >> 4
    assert np.array_equal(b, (v12 << 4) | (v12 >> 8))
    assert np.allclose(v12 / 4095.0, over / 255.0, atol=1 / 255.0)
    # responsivity scales the signal; saturation clips it
    half = expose(rad, e, 0.5, s12, None) >> 4
    lin = rad * e < 0.9
    assert np.allclose(half[lin], np.rint(np.rint(rad[lin] * e * 0.5 * 4095)), atol=1)
    # shot + read noise: variance = electrons + read^2 (in electrons)
    flat = np.full((300, 300), 0.5, np.float32)
    img = expose(flat, 1.0, 1.0, s12, np.random.default_rng(0)) >> 4
    e_mean = 0.5 * s12.full_well_e
    sigma_dn = np.sqrt(e_mean + s12.read_noise_e ** 2) / s12.full_well_e * 4095
    assert img.std() == pytest.approx(sigma_dn, rel=0.05)
    with pytest.raises(ValueError):
        Sensor(bits=10)
