"""Point and dense stereo on synthetic scenes with exact truth.

The scene is a ground plane (rover frame, z down: the plane z = 0) with an
optional box (a "rock"), textured by an analytic function of the 3-D point.
Images are rendered by intersecting each pixel's ray (2x2 supersampled)
with the scene, so the 3-D point behind every pixel is known exactly.
"""

from functools import lru_cache

import numpy as np
import pytest

from scipctl.core.camera import CameraModel, cahv_from_intrinsics, camera_frame
from scipctl.core.stereo import (
    DEFAULT_BAND_PX,
    default_band_px,
    DenseStereo,
    dense_stereo,
    dense_stereo_coarse,
    epipolar_curve,
    point_stereo,
    triangulate_rays,
)
from scipctl.core.transforms import RigidTransform, axis_angle_to_matrix
from tests.models import pose

W, H = 512, 384
F_PX = 560.0
BASELINE_M = 0.2


class Scene:
    """Ground plane ``z = 0`` plus an optional axis-aligned box; texture ``sum a cos(2 pi k.P + phi)``."""

    def __init__(self, box=None, seed=0, n=48, wavelength_m=(0.04, 0.5)):
        r = np.random.default_rng(seed)
        lam = np.exp(r.uniform(np.log(wavelength_m[0]), np.log(wavelength_m[1]), n))
        dirs = r.normal(size=(n, 3))
        dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
        self.k = dirs / lam[:, None]  # cycles per metre
        self.phase = r.uniform(0, 2 * np.pi, n)
        self.amp = r.uniform(0.5, 1.0, n) * np.sqrt(lam / lam.max())  # less power at short wavelengths
        self.amp /= np.sqrt(0.5 * np.sum(self.amp**2))
        self.box = None if box is None else (np.asarray(box[0], float), np.asarray(box[1], float))

    def texture(self, P):
        """Texture at points ``P`` (N, 3); float32 phases (ample for images), in chunks to bound memory."""
        k = (2 * np.pi * self.k.T).astype(np.float32)
        ph0 = self.phase.astype(np.float32)
        amp = self.amp.astype(np.float32)
        out = np.empty(len(P))
        for i in range(0, len(P), 65536):
            ph = P[i : i + 65536].astype(np.float32) @ k
            ph += ph0
            out[i : i + 65536] = np.cos(ph, out=ph) @ amp
        return out

    def intersect(self, o, d):
        """Nearest hit along rays ``o + t d`` ``(N, 3)`` -> ``(t (N,), P (N, 3))``; NaN for no hit."""
        o = np.broadcast_to(o, d.shape)
        with np.errstate(divide="ignore", invalid="ignore"):
            t = -o[:, 2] / d[:, 2]
        t = np.where(t > 0, t, np.inf)
        if self.box is not None:
            lo, hi = self.box
            with np.errstate(divide="ignore", invalid="ignore"):
                t1 = (lo - o) / d
                t2 = (hi - o) / d
            tn = np.nanmax(np.minimum(t1, t2), axis=1)
            tf = np.nanmin(np.maximum(t1, t2), axis=1)
            hit = (tn <= tf) & (tn > 0)
            t = np.where(hit & (tn < t), tn, t)
        t = np.where(np.isfinite(t), t, np.nan)
        return t, o + t[:, None] * d

    def render(self, model, width=W, height=H, ss=2, gain=20.0, offset=120.0):
        v, u = np.mgrid[0:height, 0:width].astype(float)
        acc = np.zeros((height, width))
        for i in range(ss):
            for j in range(ss):
                uv = np.stack([u + (i + 0.5) / ss - 0.5, v + (j + 0.5) / ss - 0.5], -1).reshape(-1, 2)
                o, d = model.unproject(uv)
                _, P = self.intersect(o, d)
                val = self.texture(np.nan_to_num(P))
                val[~np.isfinite(P[:, 0])] = 0.0
                acc += val.reshape(height, width)
        return offset + gain * acc / (ss * ss)

    def point_at(self, model, uv):
        o, d = model.unproject(np.asarray(uv, float).reshape(-1, 2))
        return self.intersect(o, d)[1]


def _distorted(m: CameraModel, R=(0.0, -0.12, 0.04), tilt=0.004) -> CameraModel:
    T = camera_frame(m)
    o = np.array([np.sin(tilt), -0.5 * np.sin(tilt), 1.0])
    return CameraModel("CAHVOR", m.C, m.A, m.H, m.V, O=T.R @ (o / np.linalg.norm(o)), R=list(R))


def _cahvore(m: CameraModel, tilt=0.004, e=(0.0005, 0.004, -0.002)) -> CameraModel:
    """A wide-angle, non-central CAHVORE (type 3, linearity 0.37) from a CAHV model."""
    T = camera_frame(m)
    o = np.array([np.sin(tilt), -0.5 * np.sin(tilt), 1.0])
    return CameraModel("CAHVORE", m.C, m.A, m.H, m.V, O=T.R @ (o / np.linalg.norm(o)), R=[0.0, -0.02, 0.004],
                       E=list(e), cahvore_type=3, linearity=0.37)


def make_pair(kind="CAHV", f_px=F_PX, width=W, height=H, baseline_m=BASELINE_M, tilt_down_rad=0.5,
              toe_in_rad=0.0, C=(0.4, 0.1, -1.5)):
    """A navcam-like pair in the rover frame: left at ``C``, right ``baseline_m`` along the camera x axis."""
    T_l = pose(tilt_down_rad=tilt_down_rad, yaw_rad=0.1, C=C)
    T_r = T_l @ RigidTransform(axis_angle_to_matrix([0, 1, 0], -toe_in_rad), np.array([baseline_m, 0.0, 0.0]))
    cx, cy = (width - 1) / 2 + 3.7, (height - 1) / 2 - 2.1
    left = cahv_from_intrinsics(f_px, f_px * 1.002, cx, cy, T_l)
    right = cahv_from_intrinsics(f_px * 0.999, f_px * 1.001, cx - 1.3, cy + 0.8, T_r)
    if kind == "CAHVOR":
        left, right = _distorted(left), _distorted(right, R=(0.0, -0.10, 0.03), tilt=-0.003)
    elif kind == "CAHVORE":
        left, right = _cahvore(left), _cahvore(right, tilt=-0.003, e=(0.0004, 0.003, -0.001))
    return left, right


@lru_cache(maxsize=None)
def rendered(kind="CAHV", with_box=False, seed=0):
    box = ((3.0, -0.35, -0.45), (3.5, 0.35, 0.0)) if with_box else None
    scene = Scene(box=box, seed=seed)
    left, right = make_pair(kind, f_px=300.0 if kind == "CAHVORE" else F_PX)  # CAHVORE: hazcam-like wide angle
    return scene, left, right, scene.render(left), scene.render(right)


def _uint8(img):
    assert img.min() > 0 and img.max() < 255
    return np.round(img).astype(np.uint8)


# ------------------------------------------------------------ geometry
def test_triangulate_rays_exact_and_skew():
    rng = np.random.default_rng(0)
    X = rng.uniform(-5, 5, (20, 3))
    o1 = rng.uniform(-1, 1, (20, 3))
    o2 = rng.uniform(-1, 1, (20, 3))
    d1 = (X - o1) * rng.uniform(0.3, 2.0, (20, 1))  # any length
    d2 = X - o2
    mid, miss, t = triangulate_rays(o1, d1, o2, d2)
    assert mid.shape == (20, 3) and miss.shape == (20,) and t.shape == (20, 2)
    assert np.abs(mid - X).max() < 1e-9
    assert miss.max() < 1e-9
    assert np.allclose(o1 + t[:, :1] * d1, X)
    # skew lines: x axis and a line parallel to y at z = 2: distance 2, midpoint (3, 0, 1)
    mid, miss, t = triangulate_rays([0, 0, 0], [1, 0, 0], [3, 5, 2], [0, -1, 0])
    assert miss == pytest.approx(2.0)
    assert np.allclose(mid, [3, 0, 1])
    assert np.allclose(t, [3, 5])
    # parallel rays: NaN
    mid, miss, t = triangulate_rays([0, 0, 0], [0, 0, 1], [1, 0, 0], [0, 0, 2])
    assert np.all(np.isnan(mid)) and np.all(np.isnan(t))
    with pytest.raises(ValueError):
        triangulate_rays(np.zeros(2), np.ones(3), np.zeros(3), np.ones(3))


@pytest.mark.parametrize("kind", ["CAHV", "CAHVOR"])
def test_epipolar_curve_points_lie_on_the_left_ray(kind):
    left, right = make_pair(kind)
    uv = np.array([200.3, 250.8])
    curve, r = epipolar_curve(left, right, uv, 0.5, 50.0)
    assert len(curve) > 10
    assert np.max(np.linalg.norm(np.diff(curve, axis=0), axis=1)) <= 0.5
    o1, d1 = left.unproject(uv[None])
    o2, d2 = right.unproject(curve)
    mid, miss, t = triangulate_rays(o1, d1, o2, d2)
    assert miss.max() < 1e-9 * r.max()
    assert np.allclose(t[:, 0], r, rtol=1e-9)
    # CAHV: a straight line; CAHVOR: a curve (bowed by the radial distortion)
    a, b = curve[0], curve[-1]
    n = np.array([-(b - a)[1], (b - a)[0]]) / np.linalg.norm(b - a)
    bow = np.abs((curve - a) @ n).max()
    if kind == "CAHV":
        assert bow < 1e-6
    else:
        assert bow > 0.1


def test_default_band():
    assert default_band_px("pancam") >= 4.0  # the paper saw up to 4 px off the epipolar line on pancams
    assert default_band_px("navcam") == DEFAULT_BAND_PX["navcam"]
    assert default_band_px("something") == 6.0


# --------------------------------------------------------- point stereo
POINTS = [(256.0, 300.0), (100.4, 350.2), (420.7, 330.9), (300.2, 220.6), (150.0, 200.0)]


@pytest.mark.parametrize("kind", ["CAHV", "CAHVOR", "CAHVORE"])
def test_point_stereo_recovers_3d_point(kind):
    scene, left, right, L, R = rendered(kind)
    for uv in POINTS:
        X_true = scene.point_at(left, uv)[0]
        res = point_stereo(_uint8(L), _uint8(R), left, right, uv, band_px=3.0)
        assert res.ok, (uv, res.reason)
        r_true = np.linalg.norm(X_true - left.C)
        err = np.linalg.norm(res.xyz - X_true)
        # the error is within the range uncertainty propagated from 0.25 px of disparity error
        assert err < res.range_sigma_m, f"{kind} {uv}: error {err * 1000:.1f} mm at {r_true:.2f} m (sigma {res.range_sigma_m * 1000:.1f} mm)"
        assert res.range_m == pytest.approx(np.linalg.norm(res.xyz - left.C))
        assert abs(res.epipolar_offset_px) < 0.1
        assert res.miss_distance_m < 1e-3
        assert res.score > 0.9
        uv_r_true = right.project(X_true)
        # the window is sheared between the views of the slanted ground: allow the assumed 0.25 px sigma
        assert np.abs(res.uv_right - uv_r_true).max() < 0.25


def test_range_sigma_matches_disparity_formula():
    """Fronto-parallel CAHV pair: range ~ f B / d, so d(range)/d(d) = r^2 / (f B)."""
    scene, left, right, L, R = rendered("CAHV")
    uv = (256.0, 300.0)
    res = point_stereo(L, R, left, right, uv, disparity_sigma_px=0.25)
    assert res.ok
    r = res.range_m
    # depth along A vs range: the pixel ray makes a small angle with A, correct for it
    o, d = left.unproject(np.array([uv]))
    expected = r**2 / (F_PX * BASELINE_M) * 0.25 / np.dot(d[0], left.A)
    assert res.range_sigma_m == pytest.approx(expected, rel=0.05)


@pytest.mark.parametrize("pitch_px", [3.0, -2.0])
def test_epipolar_offset_measures_misaligned_right_model(pitch_px):
    """Rotate the right model about its x axis by ``pitch_px`` pixels: the match sits that far off the curve."""
    scene, left, right, L, R = rendered("CAHV")
    T = camera_frame(right)
    ang = pitch_px / F_PX
    rot = RigidTransform.rotation_about_line(T.R[:, 0], right.C, ang)
    right_bad = right.transformed(rot)
    uv = (300.2, 280.6)
    X = scene.point_at(left, uv)[0]
    # truth: the real match is at right.project(X); the (wrong) curve passes through right_bad.project(X)
    expected = float(right.project(X)[1] - right_bad.project(X)[1])
    assert abs(expected) > 1.5
    res = point_stereo(L, R, left, right_bad, uv, band_px=6.0)
    assert res.ok, res.reason
    assert res.epipolar_offset_px == pytest.approx(expected, abs=0.15)
    narrow = point_stereo(L, R, left, right_bad, uv, band_px=1.0)
    assert not narrow.ok
    assert "edge of the epipolar band" in narrow.reason


def test_point_stereo_near_image_border():
    scene, left, right, L, R = rendered("CAHV")
    uv = (W - 4.2, 300.4)  # the window is clipped by the right border of the left image
    X_true = scene.point_at(left, uv)[0]
    res = point_stereo(L, R, left, right, uv, band_px=3.0)
    assert res.ok, res.reason
    assert np.linalg.norm(res.xyz - X_true) < res.range_sigma_m


def test_point_stereo_failures():
    scene, left, right, L, R = rendered("CAHV")
    L8, R8 = _uint8(L), _uint8(R)
    uv = (256.0, 300.0)
    assert point_stereo(L8, R8, left, right, (-3.0, 10.0)).reason == "pixel outside image"
    assert point_stereo(L8, R8, left, right, (100.0, H + 1.0)).reason == "pixel outside image"
    sat = L8.copy()
    sat[280:321, 236:277] = 255
    r = point_stereo(sat, R8, left, right, uv)
    assert not r.ok and r.reason.startswith("saturated window")
    flat = L8.copy()
    flat[280:321, 236:277] = 90
    r = point_stereo(flat, R8, left, right, uv)
    assert not r.ok and r.reason.startswith("textureless window")
    # a right image that shows something else (fine noise): nothing correlates
    rng = np.random.default_rng(5)
    other = np.clip(rng.normal(120.0, 30.0, (H, W)), 0, 255).astype(np.uint8)
    r = point_stereo(L8, other, left, right, uv)
    assert not r.ok and r.reason.startswith("no match above threshold")
    assert r.score < 0.6


def test_point_stereo_behind_camera():
    """A right image shifted the wrong way (negative disparity): the rays meet behind the cameras."""
    scene, left, right, L, R = rendered("CAHV")
    v, u = np.mgrid[0:H, 0:W].astype(float)
    wrong = L[:, np.clip(np.arange(W) - 3, 0, W - 1)]  # content moves right by 3 px
    res = point_stereo(L, wrong, left, right, (256.0, 150.0), band_px=6.0, max_range_m=1e4)
    assert not res.ok
    assert res.reason in ("intersection behind a camera", "rays do not converge")


def test_point_stereo_gain_difference():
    """Left and right cameras with different gain and offset give the same match."""
    scene, left, right, L, R = rendered("CAHV")
    uv = (300.2, 220.6)
    a = point_stereo(L, R, left, right, uv)
    b = point_stereo(L, 0.45 * R + 60.0, left, right, uv)
    assert a.ok and b.ok
    assert np.abs(a.uv_right - b.uv_right).max() < 1e-3


def test_point_stereo_bad_inputs_raise():
    scene, left, right, L, R = rendered("CAHV")
    with pytest.raises(ValueError):
        point_stereo(L, R, left, right, (1.0, 2.0, 3.0))
    with pytest.raises(ValueError):
        point_stereo(L[..., None], R, left, right, (1.0, 2.0))
    with pytest.raises(ValueError):
        point_stereo(L, R, left, right, (10.0, 20.0), min_range_m=5.0, max_range_m=1.0)
    with pytest.raises(ValueError):
        point_stereo(L, R, left, "not a model", (10.0, 20.0))


# --------------------------------------------------------- dense stereo
def _rect_truth(ds, scene):
    """True disparity on the rectified-left grid (NaN where the scene is not hit)."""
    rp = ds.rectified
    h, w = ds.disparity_px.shape
    v, u = np.mgrid[0:h, 0:w].astype(float)
    uv = np.stack([u, v], -1).reshape(-1, 2) * 1.0
    o, d = rp.left_model.unproject(uv)
    _, P = scene.intersect(o, d)
    lm, rm = rp.left_model, rp.right_model
    d_true = lm.project(P)[:, 0] - rm.project(P)[:, 0]
    return d_true.reshape(h, w), P.reshape(h, w, 3)


@pytest.mark.parametrize("coarse_to_fine", [True, False], ids=["bands", "single-pass"])
@pytest.mark.parametrize("kind", ["CAHV", "CAHVOR", "CAHVORE"])
def test_dense_stereo_plane(kind, coarse_to_fine):
    scene, left, right, L, R = rendered(kind)
    ds = dense_stereo(_uint8(L), _uint8(R), left, right, min_range_m=1.0, max_range_m=30.0,
                      coarse_to_fine=coarse_to_fine)
    d_true, P_true = _rect_truth(ds, scene)
    near = np.isfinite(d_true) & (np.linalg.norm(P_true - left.C, axis=-1) < 6.0)
    valid = ds.valid & near
    assert valid.sum() > 0.8 * near.sum(), f"coverage {valid.sum() / near.sum():.2f}"
    err = np.abs(ds.disparity_px - d_true)[valid]
    # SGBM's sub-pixel (1/16 px, parabola-interpolated) disparities are good to ~0.1-0.2 px
    assert np.median(err) < 0.2, f"median disparity error {np.median(err):.3f} px"
    assert np.percentile(err, 99) < 1.0
    # xyz agrees with the plane up to exactly the disparity error: the estimate and the truth lie on the same
    # rectified ray, at depths f B / d and f B / d_true
    lm, rm = ds.rectified.left_model, ds.rectified.right_model
    fb = lm.hs * np.dot(rm.C - lm.C, lm.h_axis)
    P = P_true[valid]
    Z_true = (P - lm.C) @ lm.A
    ray = (P - lm.C) / Z_true[:, None]
    Z_est = fb / ds.disparity_px[valid].astype(float)
    expected = np.abs(Z_est - Z_true) * np.linalg.norm(ray, axis=1)
    assert np.allclose(np.linalg.norm(ds.xyz[valid] - P, axis=1), expected, rtol=1e-5, atol=1e-9)
    assert np.median(np.abs(ds.xyz[valid][:, 2])) < 0.01  # ground plane z = 0, 1 cm at <= 6 m
    assert np.allclose(ds.range_m[ds.valid], np.linalg.norm(ds.xyz[ds.valid] - left.C, axis=-1))
    assert np.all(np.isnan(ds.xyz[~ds.valid]))
    assert np.all(np.isnan(ds.disparity_px[~ds.valid]))


def _occluded_in_right(ds, scene, P_true, near):
    """Rectified-left pixels whose scene point is hidden from the right camera (the right ray hits earlier)."""
    rm = ds.rectified.right_model
    occl = np.zeros_like(near)
    pts = P_true[near]
    dirs = pts - rm.C
    dist = np.linalg.norm(dirs, axis=1)
    t, _ = scene.intersect(np.broadcast_to(rm.C, pts.shape), dirs / dist[:, None])
    occl[near] = t < dist - 1e-3
    return occl


@pytest.mark.parametrize("coarse_to_fine", [True, False], ids=["bands", "single-pass"])
def test_dense_stereo_box_occlusions_are_rejected(coarse_to_fine):
    scene, left, right, L, R = rendered("CAHV", with_box=True)
    stats = {}
    for lr in ("flip", "none"):
        ds = dense_stereo(L, R, left, right, min_range_m=1.0, max_range_m=30.0, lr_check=lr,
                          coarse_to_fine=coarse_to_fine)
        d_true, P_true = _rect_truth(ds, scene)
        near = np.isfinite(d_true) & (np.linalg.norm(P_true - left.C, axis=-1) < 6.0)
        valid = ds.valid & near
        err = np.abs(ds.disparity_px - d_true)[valid]
        occl = _occluded_in_right(ds, scene, P_true, near)
        wrong = np.abs(ds.disparity_px - d_true) > 1.0
        stats[lr] = dict(coverage=valid.sum() / near.sum(), gross=np.mean(err > 2.0),
                         occl_wrong=np.mean(ds.valid[occl] & wrong[occl]), n_occl=occl.sum())
    s = stats["flip"]
    assert s["n_occl"] > 200  # the box hides some ground from the right camera
    assert s["coverage"] > 0.75
    assert s["gross"] < 0.005, f"{100 * s['gross']:.2f}% gross errors"
    # occluded pixels that keep a wrong disparity: the check removes about half of them; the rest are
    # "foreground fattening" next to the box (a left-right check cannot see those)
    assert s["occl_wrong"] < 0.2, f"{100 * s['occl_wrong']:.0f}% of occluded pixels valid and wrong"
    assert stats["none"]["gross"] > 2 * s["gross"]
    assert s["occl_wrong"] < 0.6 * stats["none"]["occl_wrong"]


def test_dense_stereo_bands_agree_with_single_pass_and_search_less():
    """Coarse-to-fine (per-row-band intervals from a half-resolution pass) against one full-interval pass:
    same disparities where both are valid, same coverage, and a much smaller total search."""
    scene, left, right, L, R = rendered("CAHVOR", with_box=True)
    one = dense_stereo(L, R, left, right, min_range_m=0.5, max_range_m=30.0, coarse_to_fine=False)
    log = []
    import scipctl.core.stereo as stereo_mod

    orig = stereo_mod._lr_disparity

    def spy(L8, R8, d_lo, nd, *a):
        log.append((L8.shape, d_lo, nd))
        return orig(L8, R8, d_lo, nd, *a)

    stereo_mod._lr_disparity = spy
    try:
        bands = dense_stereo(L, R, left, right, min_range_m=0.5, max_range_m=30.0, band_rows=96)
    finally:
        stereo_mod._lr_disparity = orig
    both = one.valid & bands.valid
    assert abs(bands.valid.mean() - one.valid.mean()) < 0.01
    assert both.sum() > 0.97 * one.valid.sum()
    diff = np.abs(one.disparity_px - bands.disparity_px)[both]
    assert np.mean(diff > 0.5) < 0.003, f"{100 * np.mean(diff > 0.5):.2f}% differ by > 0.5 px"
    # rows x disparities searched: the fine bands (after the half-res pass) search far fewer than one pass
    fine = [(shape[0], nd) for shape, _, nd in log if shape[1] == W]  # the full-resolution bands
    assert len(fine) == int(np.ceil(H / 96))
    assert all(nd % 16 == 0 for _, nd in fine)
    assert sum(r * nd for r, nd in fine) < 0.5 * H * one.num_disparities


def test_dense_stereo_ground_nearer_than_min_range_is_not_clamped():
    """Ground whose true disparity lies beyond the searched interval (nearer than ``min_range_m`` along the
    rectified axis) must come out invalid, not as a disparity at the interval's end. The coarse pass searches
    1.5x further and rejects it; one full-interval pass cannot tell (it keeps ~14 % of these pixels, wrong)."""
    scene, left, right, L, R = rendered("CAHV")
    frac = {}
    for c2f in (True, False):
        ds = dense_stereo(L, R, left, right, min_range_m=2.5, max_range_m=30.0, coarse_to_fine=c2f)
        d_true, P_true = _rect_truth(ds, scene)
        top = ds.min_disparity + ds.num_disparities - 1
        beyond = np.isfinite(d_true) & (d_true > top + 1)
        assert beyond.sum() > 10000  # the lower part of the view
        assert np.all(ds.disparity_px[ds.valid] <= top - 1)  # interval ends are rejected
        frac[c2f] = ds.valid[beyond].mean()
        ok = np.isfinite(d_true) & (d_true < top - 2) & (np.linalg.norm(P_true - left.C, axis=-1) > 2.7)
        assert ds.valid[ok].mean() > 0.9
    assert frac[True] < 0.01, f"{100 * frac[True]:.1f}% valid beyond the interval"
    assert frac[True] < 0.2 * frac[False]


def test_dense_stereo_reuses_a_given_coarse_pass():
    scene, left, right, L, R = rendered("CAHVOR")
    coarse = dense_stereo_coarse(L, R, left, right, min_range_m=1.0 / 1.5, max_range_m=30.0)
    assert isinstance(coarse, DenseStereo) and coarse.downsample == 2
    a = dense_stereo(L, R, left, right, min_range_m=1.0, max_range_m=30.0, coarse=coarse)
    b = dense_stereo(L, R, left, right, min_range_m=1.0, max_range_m=30.0)  # computes the same coarse pass
    assert np.array_equal(a.valid, b.valid)
    assert np.array_equal(a.disparity_px[a.valid], b.disparity_px[b.valid])
    with pytest.raises(ValueError):
        dense_stereo(L, R, left, right, coarse="not a DenseStereo")


def test_dense_stereo_downsample_and_xyz_at_left_uv():
    scene, left, right, L, R = rendered("CAHVOR")
    ds2 = dense_stereo(L, R, left, right, min_range_m=1.0, max_range_m=30.0, downsample=2)
    assert ds2.disparity_px.shape == (H // 2, W // 2)
    d_true, P_true = _rect_truth(ds2, scene)
    near = np.isfinite(d_true) & (np.linalg.norm(P_true - left.C, axis=-1) < 6.0)
    valid = ds2.valid & near
    assert valid.sum() > 0.8 * near.sum()
    err = np.abs(ds2.disparity_px - d_true)[valid]
    assert np.median(err) < 0.2
    # sample 3-D at original left pixels: on the pixel's ray, close to the truth
    rng = np.random.default_rng(3)
    uv = np.stack([rng.uniform(40, W - 40, 200), rng.uniform(200, H - 20, 200)], 1)
    X = ds2.xyz_at_left_uv(uv)
    X_true = scene.point_at(left, uv)
    ok = np.all(np.isfinite(X), axis=1)
    assert ok.mean() > 0.9
    o, d = left.unproject(uv[ok])
    off = X[ok] - o
    perp = off - np.sum(off * d, 1)[:, None] * d
    assert np.abs(perp).max() < 1e-9
    r_true = np.linalg.norm(X_true[ok] - left.C, axis=1)
    f_half = ds2.rectified.left_model.hs
    tol = r_true**2 / (f_half * BASELINE_M) * 0.5  # 0.5 half-res px of disparity
    within = np.linalg.norm(X[ok] - X_true[ok], axis=1) < tol
    assert within.mean() > 0.97, f"{100 * within.mean():.1f}% within 0.5 px of disparity"
    # outside the image: NaN
    assert np.all(np.isnan(ds2.xyz_at_left_uv(np.array([[-50.0, 10.0]]))))
    pts, vals = ds2.point_cloud()
    assert pts.shape == (ds2.valid.sum(), 3) and vals.shape == (ds2.valid.sum(),)
    assert np.allclose(vals, ds2.left_rect[ds2.valid])


def test_dense_stereo_bad_inputs_raise():
    scene, left, right, L, R = rendered("CAHV")
    with pytest.raises(ValueError):
        dense_stereo(L, R[:-1], left, right)
    with pytest.raises(ValueError):
        dense_stereo(L, R, left, right, downsample=3)
    with pytest.raises(ValueError):
        dense_stereo(L, R, left, right, lr_check="both")
    with pytest.raises(ValueError):
        dense_stereo(L, R, left, right, min_range_m=0.0)
    with pytest.raises(ValueError):
        dense_stereo(L, R, left, right, band_rows=4)
