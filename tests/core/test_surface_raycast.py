"""Rays to the measured surface (scipctl.core.surface_raycast): the synthetic stereo scene with exact truth (a ground
plane and a 45 cm box, tests/core/stereo_scenes.py). The stereo pair's left camera is the reference ("prev"); the
rays are a nearer camera's (1 m closer, as the rover closes in), over a window around a target on the ground 15 cm
in front of the box's face, so that the window straddles the box's foot. The plane is the ground's.

First with exact disparities (an analytic stand-in for the dense stereo: the scene's own depth, so the method's
own error is seen alone), then with the real dense stereo of the rendered pair."""

import numpy as np
import pytest

from scipctl.core.camera import cahv_from_intrinsics
from scipctl.core.dense_stereo import dense_stereo
from scipctl.core.surface_raycast import MARCH_SPAN, surface_points
from tests.core.stereo_scenes import rendered
from tests.models import pose


class _Rect:
    def __init__(self, model):
        self.left_model = model


class ExactStereo:
    """The dense stereo's interface over the scene's exact depth seen by ``model`` (``+ bias_px`` of disparity)."""

    def __init__(self, scene, model, fb=112.0, bias_px=0.0, nothing=False):
        self.scene, self.rectified, self.focal_baseline_px_m = scene, _Rect(model), fb
        self.bias_px, self.nothing = bias_px, nothing

    def disparity_at_rect_uv(self, q):
        m = self.rectified.left_model
        if self.nothing:
            return np.full(len(q), np.nan)
        return self.focal_baseline_px_m / ((self.scene.point_at(m, q) - m.C) @ m.A) + self.bias_px


def make_rays():
    scene, left, right, L, R = rendered("CAHV", with_box=True)
    new = cahv_from_intrinsics(560.0, 560.0, 255.5, 191.5, pose(tilt_down_rad=0.75, yaw_rad=0.1, C=(1.4, 0.1, -1.5)))
    X0 = np.array([2.85, 0.0, 0.0])  # the target, on the ground 15 cm in front of the box's face (x = 3.0)
    n = np.array([0.0, 0.0, 1.0])
    c = new.project(X0[None])[0]
    half = 40
    g = np.arange(-half, half + 1, dtype=float)
    uv = np.stack(np.meshgrid(c[0] + g, c[1] + g), -1).reshape(-1, 2)
    o, d = new.unproject(uv)
    t_plane = ((X0 - o) @ n) / (d @ n)
    centre = np.abs(uv - c).max(axis=1) <= half // 4
    truth = scene.point_at(new, uv)
    on_box = truth[:, 2] < -1e-3
    # the reference camera sees the same point (else the measured surface there is another one, the occluder's)
    seen = np.linalg.norm(scene.point_at(left, left.project(truth)) - truth, axis=1) < 1e-6
    # rays within 3 px of the box's outline: the surface jumps there between two march samples
    near_edge = np.zeros(len(uv), bool)
    for du in (-3.0, 0.0, 3.0):
        for dv in (-3.0, 0.0, 3.0):
            near_edge |= (scene.point_at(new, uv + [du, dv])[:, 2] < -1e-3) != on_box
    t_true = np.linalg.norm(truth - o, axis=1)
    in_span = t_true > (1 - MARCH_SPAN) * t_plane * 1.01
    assert not on_box[centre].any()
    return scene, left, right, L, R, o, d, t_plane, centre, truth, on_box, seen, near_edge, in_span


@pytest.fixture(scope="module")
def rays():
    return make_rays()


def test_exact_stereo_points_on_the_plane_are_the_planes_and_the_box_is_found(rays):
    """What matters is where the point falls in the reference image (that pixel is sampled): the box's points land
    on the truth's pixel there, except where the stereo cannot tell the box from the plane (the box's foot, within
    the disparity error bound of the ground), where the plane's point is kept by design."""
    scene, left, right, L, R, o, d, t_plane, centre, truth, on_box, seen, near_edge, in_span = rays
    plane = o + t_plane[:, None] * d
    for bias in (0.0, 0.3):  # a disparity offset common to the window is taken out at the centre (exact)
        st = ExactStereo(scene, left, bias_px=bias)
        P = surface_points(o, d, t_plane, st, centre, 0.45)
        assert P.shape == truth.shape
        ground = ~on_box & seen & ~near_edge
        assert ground.sum() > 1000
        assert np.array_equal(P[ground], plane[ground])  # the stereo agrees with the plane: the plane's point
        own = st.focal_baseline_px_m / ((truth - left.C) @ left.A) - st.focal_baseline_px_m / ((plane - left.C) @ left.A)
        told = np.abs(own) > 0.45  # the stereo tells the box's point from the plane's
        box = on_box & seen & ~near_edge & in_span
        assert (box & told).sum() > 500 and (box & ~told).sum() > 50
        img_err_px = np.linalg.norm(left.project(P) - left.project(truth), axis=1)
        # the crossing is interpolated linearly within one march step (0.6 % of the range); the disparity
        # difference is smooth there: measured 0.0007 px worst; bound 0.01 px
        assert img_err_px[box & told].max() < 0.01, img_err_px[box & told].max()
        assert np.array_equal(P[box & ~told], plane[box & ~told])
        # what the plane would have drawn instead is pixels off
        assert np.median(np.linalg.norm(left.project(plane[box & told]) - left.project(truth[box & told]), axis=1)) > 1.0


def test_exact_stereo_without_level_or_gate_puts_every_point_on_the_surface(rays):
    """The chain's default (no levelling, no gate): every ray's point is its crossing of the measured surface, the
    ground's as well as the box's, each on the truth's pixel in the reference image; a ray with no crossing in the
    march keeps the plane's point."""
    scene, left, right, L, R, o, d, t_plane, centre, truth, on_box, seen, near_edge, in_span = rays
    st = ExactStereo(scene, left)
    P = surface_points(o, d, t_plane, st, np.zeros_like(centre), None)
    pts = seen & ~near_edge & in_span
    assert (pts & on_box).sum() > 500 and (pts & ~on_box).sum() > 1000
    img_err_px = np.linalg.norm(left.project(P[pts]) - left.project(truth[pts]), axis=1)
    # linear interpolation within one march step, as above: measured 0.0008 px worst; bound 0.01 px
    assert img_err_px.max() < 0.01, img_err_px.max()
    none = surface_points(o, d, t_plane, ExactStereo(scene, left, nothing=True), np.zeros_like(centre), None)
    assert np.array_equal(none, o + t_plane[:, None] * d)


def test_no_measurement_keeps_the_plane_and_a_missed_plane_is_nan(rays):
    scene, left, right, L, R, o, d, t_plane, centre, *_ = rays
    t = t_plane.copy()
    t[:3] = np.nan
    t[3:6] = -1.0
    P = surface_points(o, d, t, ExactStereo(scene, left, nothing=True), centre, 0.45)
    assert np.isnan(P[:6]).all()
    assert np.array_equal(P[6:], o[6:] + t[6:, None] * d[6:])


def test_bad_inputs(rays):
    scene, left, right, L, R, o, d, t_plane, centre, *_ = rays
    st = ExactStereo(scene, left)
    with pytest.raises(ValueError, match="reference"):
        surface_points(o, d, t_plane, st, centre.astype(int), 0.45)
    with pytest.raises(ValueError, match="origins_m"):
        surface_points(o[:, :2], d, t_plane, st, centre, 0.45)
    with pytest.raises(ValueError, match="disparity_error_px"):
        surface_points(o, d, t_plane, st, centre, -1.0)
    with pytest.raises(ValueError, match="span"):
        surface_points(o, d, t_plane, st, centre, 0.45, span=1.0)
    with pytest.raises(ValueError, match="samples"):
        surface_points(o, d, t_plane, st, centre, 0.45, samples=1)


def test_real_dense_stereo_finds_the_box(rays):
    """The rendered pair's own dense stereo (half resolution, as the chain's): the box's points fall nearer the
    truth's pixel in the reference image than the plane's; the clear ground stays on the plane."""
    scene, left, right, L, R, o, d, t_plane, centre, truth, on_box, seen, near_edge, in_span = rays
    ds = dense_stereo(L, R, left, right, min_range_m=1.0, max_range_m=30.0, downsample=2)
    P = surface_points(o, d, t_plane, ds, centre, 0.45)
    plane = o + t_plane[:, None] * d
    box = on_box & seen & ~near_edge & in_span
    err_px = np.linalg.norm(left.project(P[box]) - left.project(truth[box]), axis=1)
    plane_err_px = np.linalg.norm(left.project(plane[box]) - left.project(truth[box]), axis=1)
    # measured median 1.69 px (OpenCV 5.0) and 1.95 px (4.14) against the plane's 2.63: ratios 0.64 and 0.74, the
    # same at 1 and 2 threads (SGBM differs between the builds); the stereo at 3 m (half-resolution disparity
    # ~19 px, its error bound 0.45 px is ~7 cm of depth) cannot tell the box's lower part from the ground.
    # Bound 0.85 of the plane's
    assert np.median(err_px) < 0.85 * np.median(plane_err_px), (np.median(err_px), np.median(plane_err_px))
    ground = ~on_box & seen & ~near_edge
    # measured 100 % (both builds, 1 and 2 threads); bound 95 %
    assert np.mean(np.all(P[ground] == plane[ground], axis=1)) > 0.95
