"""NCC tracker: synthetic images with exact sub-pixel truth (analytic, band-limited textures)."""

import numpy as np
import pytest

from scipctl.core.tracking import TrackResult, track
from scipctl.core.windows import crop_window, extract_window, scale_window, window_scale_for_handoff


class Texture:
    """A band-limited random texture ``T(x, y) = sum a_k cos(2 pi f_k . (x, y) + phi_k)`` (world units).

    ``render`` images it with square pixels of side ``1/scale`` world units,
    integrating each pixel's footprint exactly (the box average of a cosine is
    the cosine times ``sinc``), so every image has exact geometric truth.
    """

    def __init__(self, n=60, fmax=0.2, seed=0):
        r = np.random.default_rng(seed)
        self.f = r.uniform(-fmax, fmax, (n, 2))
        self.phase = r.uniform(0, 2 * np.pi, n)
        self.amp = r.uniform(0.5, 1.0, n)
        self.amp /= np.sqrt(0.5 * np.sum(self.amp**2))  # unit standard deviation

    def render(self, width, height, origin_xy=(0.0, 0.0), scale=1.0, gain=20.0, offset=100.0):
        """Pixel ``(u, v)`` covers the world square centred on ``origin_xy + (u, v) / scale``."""
        v, u = np.mgrid[0:height, 0:width].astype(float)
        x = origin_xy[0] + u / scale
        y = origin_xy[1] + v / scale
        out = np.zeros((height, width))
        for (fx, fy), ph, a in zip(self.f, self.phase, self.amp):
            box = np.sinc(fx / scale) * np.sinc(fy / scale)
            out += a * box * np.cos(2 * np.pi * (fx * x + fy * y) + ph)
        return offset + gain * out


SIZE = 240
TEX = Texture(seed=3)
BASE = TEX.render(SIZE, SIZE)


def _shifted(shift_uv, tex=TEX, size=SIZE):
    """The texture moved by ``shift_uv``: the point at pixel ``p`` of BASE is at ``p + shift_uv``."""
    return tex.render(size, size, origin_xy=(-shift_uv[0], -shift_uv[1]))


@pytest.mark.parametrize("fmax", [0.1, 0.2, 0.3])
def test_recovers_subpixel_shift(fmax):
    tex = Texture(fmax=fmax, seed=5)
    base = tex.render(SIZE, SIZE)
    rng = np.random.default_rng(11)
    c = np.array([120.0, 117.0])
    tpl = base[117 - 15 : 117 + 16, 120 - 15 : 120 + 16]
    errs = []
    for _ in range(12):
        s = rng.uniform(-4, 4, 2)
        img = _shifted(s, tex)
        res = track(tpl, img, c + rng.uniform(-3, 3, 2), search_radius_px=12)
        assert res.ok, res.reason
        assert res.score > 0.99  # measured >= 0.9988
        errs.append(res.uv - (c + s))
    err = np.abs(np.array(errs)).max()
    # measured 0.017 / 0.005 / 0.003 px at fmax 0.1 / 0.2 / 0.3 (session 36, /work/scratch/s36/bounds/track.py: the
    # same digits on OpenCV 5.0 and 4.14 and at one thread); the bound is 3x the worst
    assert err < 0.05, f"max sub-pixel error {err:.4f} px"


def test_plain_quadratic_fit_is_worse_than_iterated():
    """The iteration exists because the 3x3 fit alone is biased (pixel locking) on sharp peaks."""
    tex = Texture(fmax=0.3, seed=5)
    base = tex.render(SIZE, SIZE)
    c = np.array([120.0, 120.0])
    tpl = base[105:136, 105:136]
    e_plain, e_iter = [], []
    for s in np.linspace(0.05, 0.95, 7):
        img = _shifted((s, -s / 2), tex)
        truth = c + (s, -s / 2)
        e_plain.append(np.abs(track(tpl, img, c, 5, subpixel_iterations=0).uv - truth).max())
        e_iter.append(np.abs(track(tpl, img, c, 5).uv - truth).max())
    assert max(e_iter) < 0.05  # measured 0.0022 px
    assert max(e_iter) < 0.5 * max(e_plain)  # measured 0.0022 against 0.062 px: the iteration is 28x better


def test_pyramid_search_over_large_radius():
    rng = np.random.default_rng(2)
    size = 400
    base = TEX.render(size, size)
    c = np.array([200.0, 200.0])
    tpl = base[200 - 20 : 200 + 21, 200 - 20 : 200 + 21]
    for _ in range(3):
        s = rng.uniform(-70, 70, 2)
        img = _shifted(s, size=size)
        res = track(tpl, img, c, search_radius_px=90)
        assert res.levels >= 1
        assert res.ok, res.reason
        assert np.abs(res.uv - (c + s)).max() < 0.05  # measured 0.0053 px over the three


def test_gain_and_offset_invariance():
    s = np.array([2.3, -1.7])
    c = np.array([120.0, 120.0])
    tpl = BASE[105:136, 105:136]
    img = _shifted(s)
    ref = track(tpl, img, c, 8)
    # NCC is exactly invariant to gain and offset: what is left is float32 rounding of the correlation surface,
    # measured (session 36, OpenCV 5.0 and 4.14, and at one thread, the same digits) at 5.3e-7 px and one ulp
    # of the score (6e-8); the bounds allow ~20x that for other CPUs' vector code
    for gain, off in [(0.3, 40.0), (2.5, -120.0), (1.0, 1000.0)]:
        res = track(tpl, gain * img + off, c, 8)
        assert res.ok
        assert np.abs(res.uv - ref.uv).max() < 1e-5
        assert abs(res.score - ref.score) < 1e-6
    # and for a gain change of the template instead (measured 2.3e-7 px)
    res = track(0.2 * tpl + 7.0, img, c, 8)
    assert np.abs(res.uv - ref.uv).max() < 1e-5


@pytest.mark.parametrize("dtype,gain,offset", [(np.uint8, 30.0, 128.0), (np.uint16, 6000.0, 30000.0)])
def test_integer_images(dtype, gain, offset):
    s = np.array([-3.4, 2.6])
    c = np.array([120.0, 120.0])
    base = np.round(TEX.render(SIZE, SIZE, gain=gain, offset=offset)).astype(dtype)
    img = np.round(TEX.render(SIZE, SIZE, origin_xy=-s, gain=gain, offset=offset)).astype(dtype)
    assert base.max() < np.iinfo(dtype).max and base.min() > 0  # no clipping in the synthetic images
    res = track(base[105:136, 105:136], img, c, 8)
    assert res.ok, res.reason
    assert np.abs(res.uv - (c + s)).max() < 0.05


def test_low_texture_template_is_rejected():
    img = _shifted((1.0, 1.0))
    flat = np.full((21, 21), 77, dtype=np.uint8)
    res = track(flat, img, (100.0, 100.0), 10)
    assert not res.ok and res.reason == "low texture"
    assert np.all(np.isnan(res.uv))
    nearly_flat = np.full((21, 21), 77.0)
    nearly_flat[10, 10] += 1e-9
    assert track(nearly_flat, img, (100.0, 100.0), 10).reason == "low texture"


def test_repeated_pattern_is_flagged_by_ratio():
    v, u = np.mgrid[0:SIZE, 0:SIZE].astype(float)
    period = 16.0
    periodic = 100 + 30 * np.cos(2 * np.pi * u / period) * np.cos(2 * np.pi * v / period)
    tpl = periodic[100:121, 100:121]
    res = track(tpl, periodic, (110.0, 110.0), 30)
    assert res.score > 0.99
    assert res.second_score > 0.95
    assert res.ratio < 1.05
    assert not track(tpl, periodic, (110.0, 110.0), 30, min_ratio=1.2).ok
    assert "ambiguous" in track(tpl, periodic, (110.0, 110.0), 30, min_ratio=1.2).reason
    # a random texture has a clear single peak
    res2 = track(BASE[100:121, 100:121], _shifted((0.5, 0.5)), (110.0, 110.0), 30)
    assert res2.ok and res2.ratio > 1.3
    assert res2.second_score < res2.score


def test_edge_has_low_sharpness():
    v, u = np.mgrid[0:SIZE, 0:SIZE].astype(float)
    edge = 100 + 50 * np.tanh((u - 120.3) / 2.0)  # a vertical edge: no information along v
    res_edge = track(edge[100:121, 105:126], edge, (115.0, 110.0), 6)
    res_tex = track(BASE[100:121, 105:126], BASE, (115.0, 110.0), 6)
    assert res_tex.sharpness > 0.01
    assert res_edge.sharpness < 0.1 * res_tex.sharpness


def test_no_match_above_threshold():
    other = Texture(seed=99).render(SIZE, SIZE)
    res = track(BASE[100:131, 100:131], other, (115.0, 115.0), 10, min_score=0.6)
    assert not res.ok
    assert res.reason.startswith("no match above threshold")
    assert res.score < 0.6


def test_search_region_outside_image():
    res = track(BASE[100:121, 100:121], BASE, (-200.0, 50.0), 20)
    assert not res.ok and res.reason == "search region outside image"


def test_target_near_border_with_clipped_window():
    """A target 4 px from the image edge: the window is clipped to the image, the centre is fractional."""
    s = np.array([0.37, -0.21])
    target = np.array([4.2, 130.6])  # in BASE
    win, c_win, frac = crop_window(BASE, target, 12)
    # nearest pixel (4, 131): columns 0..16 (clipped), rows 119..143
    assert win.shape == (25, 17)
    assert frac == pytest.approx(17 / 25)
    assert np.array_equal(win, BASE[119:144, 0:17])
    assert np.allclose(c_win, target - np.array([0, 119]))
    img = _shifted(s)
    res = track(win, img, target + (1.0, -1.0), 6, template_center_uv=c_win)
    assert res.ok, res.reason
    assert np.abs(res.uv - (target + s)).max() < 0.05


def test_whole_template_whose_match_lies_beyond_the_border():
    """A whole window around a point 2.5 px inside the image's left edge (8 of its 21 columns outside the image):
    the best placement inside the image is the last one, where the window touches the edge, ~8 px from the truth.
    By default (a window clipped at the edge belongs there) it is a match; with ``accept_border_peak=False`` it is
    flagged, since the correlation may still rise beyond the edge. An interior match gives the same bits either
    way."""
    tex = Texture(fmax=0.05, seed=3)  # smooth enough that the partial overlap still correlates (NCC ~0.57)
    base = tex.render(SIZE, SIZE)
    big = tex.render(SIZE + 40, SIZE, origin_xy=(-40.0, 0.0))  # big pixel (u + 40, v) = base pixel (u, v)
    target = np.array([2.5, 120.0])  # in base
    tpl = big[120 - 10 : 120 + 11, 40 + 2 - 10 : 40 + 2 + 11]  # 21 x 21 around base (2, 120)
    c_tpl = np.array([10.5, 10.0])  # the target in the template
    kw = dict(template_center_uv=c_tpl, min_score=0.3)
    default = track(tpl, base, target + (6.0, 0.0), 8, **kw)
    whole = track(tpl, base, target + (6.0, 0.0), 8, accept_border_peak=False, **kw)
    assert default.ok, default.reason
    assert default.uv[0] - c_tpl[0] <= 0.5  # the template's left column at (sub-pixel) image column <= 0.5
    assert np.linalg.norm(default.uv - target) > 5.0  # the wrong answer the flag keeps from being trusted
    assert not whole.ok and whole.reason.startswith("peak at the image border"), whole.reason
    assert np.array_equal(whole.uv, default.uv)  # reported, flagged
    interior = np.array([120.3, 117.6])
    tpl_in = BASE[117 - 10 : 117 + 11, 120 - 10 : 120 + 11]
    a = track(tpl_in, _shifted((0.3, 0.6)), interior, 6, template_center_uv=(10.0, 10.0))
    b = track(tpl_in, _shifted((0.3, 0.6)), interior, 6, template_center_uv=(10.0, 10.0), accept_border_peak=False)
    assert a.ok and b.ok and np.array_equal(a.uv, b.uv) and a.score == b.score


def test_scale_handoff_tracks_into_coarser_camera():
    """A window from a fine camera, shrunk by 1/3, found in a camera with 3x coarser pixels."""
    tex = Texture(n=80, fmax=0.12, seed=8)
    fine = tex.render(300, 300)  # world point (150, 150) at fine pixel (150, 150)
    target_coarse = np.array([61.3, 58.7])
    origin = np.array([150.0, 150.0]) - 3.0 * target_coarse
    coarse = tex.render(120, 120, origin_xy=origin, scale=1.0 / 3.0)
    scale = window_scale_for_handoff(1.0, 10.0, 3.0, 10.0)
    assert scale == pytest.approx(1.0 / 3.0)
    win = extract_window(fine, (150.0, 150.0), 45)
    small = scale_window(win, scale)
    res = track(small, coarse, target_coarse + (2.0, -3.0), 8)
    assert res.ok, res.reason
    assert res.score > 0.97
    err = np.abs(res.uv - target_coarse).max()
    assert err < 0.05, f"handoff error {err:.4f} coarse px"
    # without the rescale the same window does not match
    assert track(win[30:61, 30:61], coarse, target_coarse, 8).score < res.score - 0.2


def test_bad_inputs_raise():
    with pytest.raises(ValueError):
        track(np.zeros((2, 2)), BASE, (10, 10), 5)
    with pytest.raises(ValueError):
        track(BASE[:9, :9], np.zeros((10, 10, 3)), (10, 10), 5)
    with pytest.raises(ValueError):
        track(BASE[:9, :9], BASE, (np.nan, 10), 5)
    with pytest.raises(ValueError):
        track(BASE[:9, :9], BASE, (10, 10), -1)


def test_failed_result_shape():
    r = TrackResult.failed("x")
    assert not r.ok and r.uv.shape == (2,) and np.all(np.isnan(r.uv))


def test_template_mask_ignores_a_misplaced_part():
    """A template whose corner shows a patch that in the image lies elsewhere (parallax): counting every pixel
    pulls the peak towards the patch; masking the patch out recovers the exact shift."""
    shift = np.array([3.4, -2.3])
    img = _shifted(shift)
    other = Texture(seed=11, fmax=0.1)
    c = np.array([120.0, 120.0])
    half = 20
    tpl = extract_window(BASE, c, half).copy()
    img = img.copy()
    # a strong patch (a "rock": 4x the texture's contrast) in the template's lower-left quarter, drawn in the image
    # 6 px further down-left than where the template has it
    patch = 80.0 * (other.render(18, 18) - 100.0) / 20.0 + 100.0
    tpl[half + 3:half + 21, 0:18] = patch[:, :18]
    pu, pv = int(c[0] + shift[0]) - half - 6, int(c[1] + shift[1]) + 3 + 6
    img[pv:pv + 18, pu:pu + 18] = patch
    plain = track(tpl, img, c, 10.0, min_score=0.1)
    keep = np.ones(tpl.shape, bool)
    keep[half + 3:, :18] = False
    masked = track(tpl, img, c, 10.0, min_score=0.1, template_mask=keep)
    assert masked.ok
    # the masked template is the texture alone: its sub-pixel accuracy (test_recovers_subpixel_shift's bound)
    assert np.linalg.norm(masked.uv - (c + shift)) < 0.05
    assert np.linalg.norm(plain.uv - (c + shift)) > 0.5  # the patch drags the unmasked peak


def test_template_mask_all_true_matches_unmasked():
    """Every pixel kept: the masked NCC is the plain NCC (OpenCV's masked and unmasked paths agree to float32
    rounding, far below the 1e-3 px asserted)."""
    shift = np.array([1.3, 0.6])
    img = _shifted(shift)
    c = np.array([120.0, 120.0])
    tpl = extract_window(BASE, c, 15)
    a = track(tpl, img, c, 30.0)
    b = track(tpl, img, c, 30.0, template_mask=np.ones(tpl.shape, bool))
    assert a.ok and b.ok
    assert np.linalg.norm(a.uv - b.uv) < 1e-3
    assert abs(a.score - b.score) < 1e-4


def test_template_mask_bad_inputs():
    tpl = extract_window(BASE, (120.0, 120.0), 10)
    with pytest.raises(ValueError, match="template_mask"):
        track(tpl, BASE, (120.0, 120.0), 5.0, template_mask=np.ones((3, 3), bool))
    with pytest.raises(ValueError, match="template_mask"):
        track(tpl, BASE, (120.0, 120.0), 5.0, template_mask=np.ones(tpl.shape, np.uint8))
    few = np.zeros(tpl.shape, bool)
    few[0, :5] = True
    r = track(tpl, BASE, (120.0, 120.0), 5.0, template_mask=few)
    assert not r.ok and "fewer than 9" in r.reason
