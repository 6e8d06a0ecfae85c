"""The planes the chain's feature step renders through (pipeline/plane_warp.render_planes); the rendering itself is
tested through the chain (test_chain.py) and the feature step (test_feature_track.py)."""

from types import SimpleNamespace

import numpy as np

from scipctl.core.transforms import RigidTransform
from scipctl.pipeline.plane_warp import GROUND_PLANE_MIN_DEG, render_planes


def _prod(yaw_rad=0.0, roll_rad=0.0):
    """A stand-in image product: only its pose estimate is read (site <- rover, rotation about x then z)."""
    cx, sx, cz, sz = np.cos(roll_rad), np.sin(roll_rad), np.cos(yaw_rad), np.sin(yaw_rad)
    R_site_rover = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1.0]]) @ np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    M = np.eye(4)
    M[:3, :3], M[:3, 3] = R_site_rover, [3.0, -2.0, 0.5]
    return SimpleNamespace(pose=SimpleNamespace(T_site_rover=RigidTransform.from_matrix(M)))


def _tilted(deg):
    """A unit normal ``deg`` degrees from site -z (the ground's up in the rover frames: +z is down)."""
    a = np.radians(deg)
    return np.array([np.sin(a), 0.0, -np.cos(a)])


def test_the_target_surface_first_and_the_ground_when_it_differs():
    prod = _prod(0.3)
    own, ground = _tilted(30.0), _tilted(2.0)
    planes, n_view = render_planes(prod, own, ground)
    assert n_view is own and len(planes) == 2 and planes[0] is own and planes[1] is ground
    # within GROUND_PLANE_MIN_DEG of each other: one plane (28 deg apart above, 4 deg here)
    planes, n_view = render_planes(prod, _tilted(6.0), ground)
    assert GROUND_PLANE_MIN_DEG == 5.0 and len(planes) == 1 and np.allclose(planes[0], _tilted(6.0))


def test_without_a_local_normal_the_ground_then_the_rover_down_axis():
    prod = _prod(0.3, roll_rad=0.2)
    ground = _tilted(10.0)
    planes, n_view = render_planes(prod, None, ground)
    assert n_view is ground and len(planes) == 1
    planes, n_view = render_planes(prod, None, None)
    # the rover's up (-z, rover frame) in the site frame: tilted by the roll, then turned by the yaw
    tilted = np.array([0.0, np.sin(0.2), -np.cos(0.2)])
    expected = np.array([-np.sin(0.3) * tilted[1], np.cos(0.3) * tilted[1], tilted[2]])
    assert len(planes) == 1 and np.allclose(n_view, expected, atol=1e-12)


def _image(model, img):
    """A stand-in image product at the site origin (rover frame = site frame): its model, pose and pixels."""
    return SimpleNamespace(camera_model=model, pose=SimpleNamespace(T_site_rover=RigidTransform.identity()),
                           pixels_float=lambda: np.asarray(img, np.float32))


def test_render_through_surface_draws_the_box_where_the_new_camera_sees_it():
    """The ground-and-box scene with exact truth (tests/core/stereo_scenes.py): the reference image is the stereo
    pair's left, the new camera 1 m nearer; a window straddling the box's foot. Through the measured surface
    (exact disparities, tests/core/test_surface_raycast.ExactStereo) the drawn window matches what the new camera
    sees far better than through the ground plane; a window of clear ground is drawn exactly as the plane draws it."""
    from scipctl.core.camera import cahv_from_intrinsics
    from scipctl.pipeline.plane_warp import render_through_plane, render_through_surface
    from tests.core.stereo_scenes import rendered
    from tests.core.test_surface_raycast import ExactStereo
    from tests.models import pose

    scene, left, right, L, R = rendered("CAHV", with_box=True)
    new = cahv_from_intrinsics(560.0, 560.0, 255.5, 191.5, pose(tilt_down_rad=0.75, yaw_rad=0.1, C=(1.4, 0.1, -1.5)))
    prev, prod = _image(left, L), _image(new, scene.render(new))
    n = np.array([0.0, 0.0, 1.0])
    stereo = ExactStereo(scene, left)

    def window(X0, half=40):
        c = np.round(new.project(np.asarray(X0, float)[None])[0])
        g = np.arange(-half, half + 1, dtype=float)
        return np.stack(np.meshgrid(c[0] + g, c[1] + g), -1)

    def ncc(a, b):
        a, b = a - a.mean(), b - b.mean()
        return float((a * b).sum() / np.sqrt((a * a).sum() * (b * b).sum()))

    X0 = np.array([2.85, 0.0, 0.0])  # on the ground 15 cm in front of the box's face
    uv = window(X0)
    seen = prod.pixels_float()[uv[..., 1].astype(int), uv[..., 0].astype(int)]
    surf = render_through_surface(prev, prod, X0, n, stereo, uv, 0.45, level=True)
    flat = render_through_plane(prev, prod, X0, n, uv)
    assert surf.shape == uv.shape[:2] and np.isfinite(surf).all() and np.isfinite(flat).all()
    box = scene.point_at(new, uv.reshape(-1, 2))[:, 2].reshape(uv.shape[:2]) < -1e-3
    assert box.sum() > 800 and (~box).sum() > 800

    def rms(a, where):
        return float(np.sqrt(np.mean((a - seen)[where] ** 2)))

    # the box's pixels (grey levels; their spread is 13.7): measured 1.66 through the surface (its foot, which the
    # stereo cannot tell from the ground within 0.45 px of disparity, keeps the plane's drawing by design; the rest
    # is resampling of the reference image) against 10.16 through the plane (the ground behind the box drawn on
    # it). No OpenCV step: the same on every build. Bounds 3 and 6
    assert rms(surf, box) < 3.0 and rms(flat, box) > 6.0, (rms(surf, box), rms(flat, box))
    assert rms(surf, ~box) == rms(flat, ~box)  # the ground around it: the plane's drawing
    # clear ground, 1 m in front of the box: the plane's own drawing, bit for bit
    X1 = np.array([2.0, -0.2, 0.0])
    uv1 = window(X1)
    assert np.array_equal(render_through_surface(prev, prod, X1, n, stereo, uv1, 0.45, level=True),
                          render_through_plane(prev, prod, X1, n, uv1))
    # without the gate (the default) every ray takes the measured surface's point, the box's foot too: measured
    # 0.19 grey levels RMS on the box (bound 0.5), the ground 0.02 from the plane's drawing (bound 0.1)
    raw = render_through_surface(prev, prod, X0, n, stereo, uv)
    assert rms(raw, box) < 0.5, rms(raw, box)
    assert float(np.sqrt(np.mean((raw - flat)[~box] ** 2))) < 0.1
    # a stereo whose disparities are all 0.3 px off: unlevelled, the whole surface moves (measured 4.53 on the box,
    # 3.07 on the ground); levelled at the centre, as exact as before (0.19)
    biased = ExactStereo(scene, left, bias_px=0.3)
    assert rms(render_through_surface(prev, prod, X0, n, biased, uv), box) > 3.0
    assert rms(render_through_surface(prev, prod, X0, n, biased, uv, level=True), box) < 0.5
