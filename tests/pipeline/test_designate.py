"""Designation: a left pixel -> the 3-D target, its range sigma and surface normal (scipctl/pipeline/designate.py).

Scenes with exact truth from tests/pipeline/scene.py: a 45-degree slab facing the rover (upward normal
``(-1, 0, -1)/sqrt(2)``, site frame z down) on flat ground (upward normal ``(0, 0, -1)``). The pixel given to
:func:`designate` is the target's exact mark (its true projection), so the left ray passes through the true point.

Error model of point stereo (scipctl/core/point_stereo.py): the match along the epipolar curve is uncertain by
``disparity_sigma_px`` = 0.25 px (1 sigma), propagated to ``range_sigma_m``. The 3-D error therefore lies along
the left ray: its component along the ray must stay within 2 ``range_sigma_m`` (0.5 px of disparity), and its
distance from the true left ray is half the rays' miss distance (the point is the midpoint of closest approach).
"""

from dataclasses import replace

import numpy as np
import pytest

from scipctl.core.transforms import RigidTransform
from scipctl.model import InputError
from scipctl.pipeline.designate import designate, parse_pixel, pick_left_product
from tests.pipeline import scene as S

NEAR_FLAT_SITE = np.array([8.9, -0.3, 0.0])  # flat ground beside the slab's foot
N_SLAB_UP = np.array([-1.0, 0.0, -1.0]) / np.sqrt(2.0)
N_GROUND_UP = np.array([0.0, 0.0, -1.0])


@pytest.fixture(scope="module")
def far():
    """(world, downlink): the rover at the site origin, the slab target ~9.3 m from the mast cameras."""
    return S.cached("slab")


@pytest.fixture(scope="module")
def near():
    """(world, downlink): the rover 6.5 m further on, the slab target ~3 m from the mast cameras."""
    w = S.slab_world()
    T_site_rover = RigidTransform(np.eye(3), np.array([6.5, 0.0, 0.0]))
    dl = S.make_downlink(w, pose=T_site_rover, targets={"t_slab": S.TARGET_SLAB_SITE, "t_flat": NEAR_FLAT_SITE})
    return w, dl


def _designate_mark(dl, camera, target_id, **kw):
    """(record, left product, true point in the site frame) for the target's exact mark in the left ``camera``."""
    left = dl.product(f"{camera}_left_1_0")
    mk = dl.target(target_id).mark_in(left.product_id)
    assert mk is not None, f"{target_id} is not marked in {left.product_id}"
    X_site_true = next(t.xyz_site_m for t in dl.truth_targets if t.id == target_id)
    return designate(dl, left, [mk.u, mk.v], **kw), left, np.asarray(X_site_true, float)


def _angle_deg(a, b):
    return float(np.degrees(np.arccos(np.clip(np.dot(a, b) / np.linalg.norm(a) / np.linalg.norm(b), -1.0, 1.0))))


@pytest.mark.parametrize("scene, camera, target_id", [
    ("near", "pancam", "t_slab"), ("near", "navcam", "t_slab"), ("near", "navcam", "t_flat"),
    ("near", "hazcam", "t_slab"), ("near", "hazcam", "t_flat"),
    ("far", "pancam", "t_slab"), ("far", "pancam", "t_flat"), ("far", "navcam", "t_slab"), ("far", "navcam", "t_flat"),
])
def test_point_is_the_truth_within_the_stereo_error_model(scene, camera, target_id, request):
    _, dl = request.getfixturevalue(scene)
    rec, left, X_site_true = _designate_mark(dl, camera, target_id, with_normal=False)
    assert rec["ok"], rec["reason"]
    assert rec["product_id"] == left.product_id and rec["right_product_id"] == f"{camera}_right_1_0"
    T_site_rover = left.pose.T_site_rover
    X_rover = np.array(rec["xyz_rover_m"])
    assert np.allclose(rec["xyz_site_m"], T_site_rover.apply(X_rover), rtol=0, atol=1e-12)
    assert rec["range_m"] == pytest.approx(np.linalg.norm(X_rover - left.camera_model.C), rel=1e-12)
    # the true left ray (rover frame) through the mark
    o, d = left.camera_model.unproject(np.array([rec["pixel_uv"]]))
    o, d = o[0], d[0] / np.linalg.norm(d[0])
    X_rover_true = T_site_rover.inverse().apply(X_site_true)
    assert np.linalg.norm(np.cross(X_rover_true - o, d)) < 1e-6  # the mark is exact: the ray passes through the truth
    err = X_rover - X_rover_true
    along_m = float(err @ d)
    sigma_m = rec["range_sigma_m"]
    assert 0 < sigma_m < np.inf
    assert abs(along_m) < 2.0 * sigma_m, f"{along_m * 1e3:.1f} mm along the ray, sigma {sigma_m * 1e3:.1f} mm"
    off_ray_m = np.linalg.norm(err - along_m * d)
    assert off_ray_m == pytest.approx(rec["ray_miss_m"] / 2, abs=1e-6)


@pytest.mark.parametrize("scene, target_id", [("near", "t_slab"), ("far", "t_slab"), ("far", "t_flat")])
def test_range_sigma_is_a_quarter_pixel_of_disparity(scene, target_id, request):
    """Pancam (CAHV, parallel eyes): ``sigma_r = r^2 / (f B) * 0.25 px / cos(angle between ray and axis)``."""
    _, dl = request.getfixturevalue(scene)
    rec, left, _ = _designate_mark(dl, "pancam", target_id, with_normal=False)
    right = dl.stereo_pair(left)
    m = left.camera_model
    f_px = np.linalg.norm(np.cross(m.A, m.H))
    baseline_m = np.linalg.norm(right.camera_model.C - m.C)
    ray = np.array(rec["xyz_rover_m"]) - m.C
    r = np.linalg.norm(ray)
    expected_m = r**2 / (f_px * baseline_m) * 0.25 / float(ray @ m.A / r)
    assert rec["range_sigma_m"] == pytest.approx(expected_m, rel=0.02)


@pytest.mark.parametrize("scene, target_id, n_true, tol_deg", [
    ("near", "t_slab", N_SLAB_UP, 8.0),  # 3 m: dense stereo on the slanted slab, fit within 6 cm
    ("far", "t_flat", N_GROUND_UP, 4.0),  # 9 m: level ground, fit within 18 cm
])
def test_surface_normal_is_the_plane_of_the_surface(scene, target_id, n_true, tol_deg, request):
    _, dl = request.getfixturevalue(scene)
    rec, left, _ = _designate_mark(dl, "pancam", target_id)
    n = np.array(rec["surface_normal_rover"])
    assert np.linalg.norm(n) == pytest.approx(1.0, abs=1e-12) and n[2] < 0  # unit, oriented up (rover z down)
    assert rec["normal_points"] >= 10
    R_site_rover = left.pose.T_site_rover.R
    assert _angle_deg(R_site_rover @ n, n_true) < tol_deg
    ray = np.array(rec["xyz_rover_m"]) - left.camera_model.C
    assert rec["incidence_deg"] == pytest.approx(_angle_deg(ray, n) if ray @ n > 0 else 180 - _angle_deg(ray, n), abs=1e-9)
    assert not rec["warnings"]


def test_too_few_dense_points_give_no_normal_and_a_warning(near):
    _, dl = near
    rec, _, _ = _designate_mark(dl, "hazcam", "t_slab")  # 256 px hazcam: dense stereo finds nothing near the target
    assert rec["ok"] and rec["surface_normal_rover"] is None and rec["normal_points"] < 10
    assert any(w.startswith("no surface normal") for w in rec["warnings"])
    assert "incidence_deg" not in rec


@pytest.mark.parametrize("uv", [(-0.51, 100.0), (100.0, -0.6), (S.SIZE - 0.49, 100.0), (100.0, S.SIZE + 3.0),
                                (np.nan, 100.0), (100.0, np.inf), (-np.inf, 5.0)])
def test_pixel_outside_the_image_or_not_finite_is_an_input_error(uv, far):
    _, dl = far
    left = dl.product("pancam_left_1_0")
    with pytest.raises(InputError, match="outside"):
        designate(dl, left, uv)


def test_image_edges_are_inside(far):
    _, dl = far
    left = dl.product("pancam_left_1_0")
    rec = designate(dl, left, (-0.5, S.SIZE - 0.5), with_normal=False)  # the corner pixel's outer edge: accepted
    assert "near the image edge" in rec["warnings"]


def test_no_right_eye_is_an_input_error(far):
    _, dl = far
    left = dl.product("navcam_left_1_0")
    alone = replace(dl, images=[im for im in dl.images if im.product_id != "navcam_right_1_0"])
    with pytest.raises(InputError, match="no right-eye navcam"):
        designate(alone, left, (128.0, 128.0))


@pytest.mark.parametrize("text", ["nan,3", "3,inf", "3", "1,2,3", "a,b"])
def test_parse_pixel_rejects_anything_but_two_finite_numbers(text):
    with pytest.raises(InputError):
        parse_pixel(text)
    assert parse_pixel(" 12.5, 7 ").tolist() == [12.5, 7.0]


def test_pick_left_product(far):
    _, dl = far
    assert pick_left_product(dl, None, "navcam").product_id == "navcam_left_1_0"
    assert pick_left_product(dl, "hazcam_left_1_0", None).eye == "left"
    with pytest.raises(InputError, match="left-eye"):
        pick_left_product(dl, "hazcam_right_1_0", None)
    with pytest.raises(InputError, match="no left"):
        pick_left_product(dl, None, "chemcam")
    with pytest.raises(InputError):
        pick_left_product(dl, None, None)
