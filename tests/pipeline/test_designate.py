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
from scipctl.pipeline.designate import Designation, designate, designations_from_doc, parse_pixel, pick_left_product
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
    assert rec.ok, rec.reason
    assert rec.product_id == left.product_id and rec.right_product_id == f"{camera}_right_1_0"
    T_site_rover = left.pose.T_site_rover
    X_rover = np.array(rec.xyz_rover_m)
    assert np.allclose(rec.xyz_site_m, T_site_rover.apply(X_rover), rtol=0, atol=1e-12)
    assert rec.range_m == pytest.approx(np.linalg.norm(X_rover - left.camera_model.C), rel=1e-12)
    # the true left ray (rover frame) through the mark
    o, d = left.camera_model.unproject(np.array([rec.pixel_uv]))
    o, d = o[0], d[0] / np.linalg.norm(d[0])
    X_rover_true = T_site_rover.inverse().apply(X_site_true)
    assert np.linalg.norm(np.cross(X_rover_true - o, d)) < 1e-6  # the mark is exact: the ray passes through the truth
    err = X_rover - X_rover_true
    along_m = float(err @ d)
    sigma_m = rec.range_sigma_m
    assert 0 < sigma_m < np.inf
    assert abs(along_m) < 2.0 * sigma_m, f"{along_m * 1e3:.1f} mm along the ray, sigma {sigma_m * 1e3:.1f} mm"
    off_ray_m = np.linalg.norm(err - along_m * d)
    assert off_ray_m == pytest.approx(rec.ray_miss_m / 2, abs=1e-6)


@pytest.mark.parametrize("scene, target_id", [("near", "t_slab"), ("far", "t_slab"), ("far", "t_flat")])
def test_range_sigma_is_a_quarter_pixel_of_disparity(scene, target_id, request):
    """Pancam (CAHV, parallel eyes): ``sigma_r = r^2 / (f B) * 0.25 px / cos(angle between ray and axis)``."""
    _, dl = request.getfixturevalue(scene)
    rec, left, _ = _designate_mark(dl, "pancam", target_id, with_normal=False)
    right = dl.stereo_pair(left)
    m = left.camera_model
    f_px = np.linalg.norm(np.cross(m.A, m.H))
    baseline_m = np.linalg.norm(right.camera_model.C - m.C)
    ray = np.array(rec.xyz_rover_m) - m.C
    r = np.linalg.norm(ray)
    expected_m = r**2 / (f_px * baseline_m) * 0.25 / float(ray @ m.A / r)
    assert rec.range_sigma_m == pytest.approx(expected_m, rel=0.02)


@pytest.mark.parametrize("scene, target_id, n_true, tol_deg", [
    ("near", "t_slab", N_SLAB_UP, 8.0),  # 3 m: dense stereo on the slanted slab, fit within 6 cm
    ("far", "t_flat", N_GROUND_UP, 4.0),  # 9 m: level ground, fit within 18 cm
])
def test_surface_normal_is_the_plane_of_the_surface(scene, target_id, n_true, tol_deg, request):
    _, dl = request.getfixturevalue(scene)
    rec, left, _ = _designate_mark(dl, "pancam", target_id)
    n = np.array(rec.surface_normal_rover)
    assert np.linalg.norm(n) == pytest.approx(1.0, abs=1e-12) and n[2] < 0  # unit, oriented up (rover z down)
    assert rec.normal_points >= 10
    R_site_rover = left.pose.T_site_rover.R
    assert _angle_deg(R_site_rover @ n, n_true) < tol_deg
    ray = np.array(rec.xyz_rover_m) - left.camera_model.C
    assert rec.incidence_deg == pytest.approx(_angle_deg(ray, n) if ray @ n > 0 else 180 - _angle_deg(ray, n), abs=1e-9)
    assert not rec.warnings


@pytest.mark.parametrize("camera, target_id", [("pancam", "t_slab"), ("pancam", "t_flat"), ("navcam", "t_slab"),
                                                ("navcam", "t_flat")])
def test_window_range_gap_is_small_where_the_window_is_one_surface(far, camera, target_id):
    """On one plane the window's median dense range is the centre's (range is monotonic along the window's rows or
    columns), so the gap is the two stereo methods' errors: point stereo within 0.5 px of disparity (2 sigma, the
    module's error model) plus dense stereo's sub-pixel interpolation bias, at most 0.5 px (SGBM's parabola fit
    locks to within half a pixel). 1 px of disparity is 4 ``range_sigma_m`` (a quarter pixel each), in % of the range.
    Measured here: 0.45-1.33 % at pancam (0.13-0.40 px), 1.9-3.0 % at navcam (0.13-0.2 px). Without a dense range
    (a failed dense stereo) the record has none and does not write the key."""
    _, dl = far
    rec, _, _ = _designate_mark(dl, camera, target_id, with_normal=False)
    assert rec.ok and rec.window_range_gap_pct is not None
    one_px_pct = 4.0 * 100.0 * rec.range_sigma_m / rec.range_m
    assert 0.0 <= rec.window_range_gap_pct <= one_px_pct
    assert rec.to_dict()["window_range_gap_pct"] == rec.window_range_gap_pct
    assert "window_range_gap_pct" not in replace(rec, window_range_gap_pct=None).to_dict()


def test_a_pair_off_its_epipolar_geometry_is_realigned_at_the_match_for_the_window_gap(far):
    """The right pancam image moved down 3 rows (a pair whose downlinked models are off by 3 px across the rows, as
    the paper saw up to ~4 px on pancams): point stereo still matches within its 6 px band, 3 px off the curve;
    dense stereo of the pair as downlinked has no range in the window (SGBM searches along rectified rows that no
    longer meet); re-aligned at the match it has, and the gap is the one-surface gap within the same bound as an
    aligned pair's (1 px of disparity, see the test above)."""
    from scipctl.io.images import encode_png
    from scipctl.pipeline.designate import designation_dense_stereo, window_range_gap_pct

    _, dl = far
    rid = "pancam_right_1_0"
    out = []
    for im in dl.images:
        if im.product_id == rid:
            px = np.concatenate([np.repeat(im.pixels[:1], 3, axis=0), im.pixels[:-3]])  # content 3 rows lower
            im = replace(im, png=encode_png(px), _pixels=px)
        out.append(im)
    moved = replace(dl, images=out)
    rec, left, _ = _designate_mark(moved, "pancam", "t_flat", with_normal=False)
    assert rec.ok and 2.5 <= abs(rec.epipolar_offset_px) <= 3.5
    right = moved.product(rid)
    as_downlinked = designation_dense_stereo(left.pixels_float(), right.pixels_float(), left, right, rec.range_m)
    assert window_range_gap_pct(as_downlinked, left, rec.pixel_uv, 21, rec.range_m) is None
    assert rec.window_range_gap_pct is not None
    assert rec.window_range_gap_pct <= 4.0 * 100.0 * rec.range_sigma_m / rec.range_m


def test_too_few_dense_points_give_no_normal_and_a_warning(near):
    _, dl = near
    rec, _, _ = _designate_mark(dl, "hazcam", "t_slab")  # 256 px hazcam: dense stereo finds nothing near the target
    assert rec.ok and rec.surface_normal_rover is None and rec.normal_points < 10
    assert any(w.startswith("no surface normal") for w in rec.warnings)
    assert rec.incidence_deg is None and "incidence_deg" not in rec.to_dict()


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
    assert "near the image edge" in rec.warnings


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


# ----------------------------------------------------------------------------- the record in targets.json
def _json_round_trip(rec):
    """``rec`` written as scipctl writes targets.json (sorted keys) and read back."""
    import json

    from scipctl.io.workspace import dumps

    text = dumps({"targets": [rec.to_dict()]})
    return text, designations_from_doc(json.loads(text))


@pytest.mark.parametrize("camera, with_normal", [("pancam", True), ("navcam", False)])
def test_a_designation_reads_back_to_the_same_record_and_bytes(far, camera, with_normal):
    from scipctl.io.workspace import dumps

    _, dl = far
    rec, _, _ = _designate_mark(dl, camera, "t_slab", with_normal=with_normal)
    rec = replace(rec, provenance={"tool": "scipctl", "inputs": {}})
    text, (back,) = _json_round_trip(rec)
    assert back == rec
    assert dumps({"targets": [back.to_dict()]}) == text
    # the optional keys are written only when present
    d = rec.to_dict()
    assert ("normal_points" in d) == with_normal and "designated_from" not in d and d["provenance"]


def test_a_failed_designation_has_no_stereo_keys_and_reads_back():
    rec = Designation(id="d2", product_id="p", camera="pancam", pixel_uv=(3.0, 4.0), ok=False, right_product_id="q",
                      position=(1, 0), band_px=6.0, reason="textureless window", warnings=("low texture",))
    d = rec.to_dict()
    assert not ({"xyz_site_m", "xyz_rover_m", "range_m", "pose", "normal_points"} & set(d)) and not rec.has_position
    assert d["position"] == {"site": 1, "drive": 0} and d["warnings"] == ["low texture"]
    _, (back,) = _json_round_trip(rec)
    assert back == rec


def test_unknown_keys_of_a_read_record_are_kept():
    d = {"id": "x", "product_id": "p", "camera": "navcam", "pixel_uv": [1.5, 2], "ok": True, "note": "by hand"}
    rec = Designation.from_dict(d)
    assert rec.extra == {"note": "by hand"} and rec.to_dict()["note"] == "by hand"
    assert rec.pixel_uv == (1.5, 2) and rec.to_dict()["pixel_uv"] == [1.5, 2]  # values as read


GOOD = {"id": "d1", "product_id": "p", "camera": "pancam", "pixel_uv": [10.0, 20.0], "ok": True,
        "xyz_site_m": [1.0, 2.0, 3.0], "warnings": []}


@pytest.mark.parametrize("change, field", [
    ({"pixel_uv": [1.0]}, "targets[1].pixel_uv"),
    ({"pixel_uv": [1.0, float("nan")]}, "targets[1].pixel_uv"),
    ({"pixel_uv": None}, "targets[1].pixel_uv"),
    ({"id": ""}, "targets[1].id"),
    ({"id": 7}, "targets[1].id"),
    ({"camera": None}, "targets[1].camera"),
    ({"ok": "yes"}, "targets[1].ok"),
    ({"xyz_site_m": [1.0, 2.0, "3"]}, "targets[1].xyz_site_m"),
    ({"range_m": float("inf")}, "targets[1].range_m"),
    ({"warnings": "none"}, "targets[1].warnings"),
    ({"position": {"site": 1}}, "targets[1].position"),
    ({"normal_points": -1}, "targets[1].normal_points"),
    ({"pose": [1, 2]}, "targets[1].pose"),
])
def test_a_bad_field_is_one_input_error_naming_targets_json_and_the_field(change, field):
    bad = dict(GOOD, **change)
    with pytest.raises(InputError) as e:
        designations_from_doc({"targets": [GOOD, bad]})
    msg = str(e.value)
    assert msg.startswith(f"targets.json: {field}: ") and "\n" not in msg, msg
    assert e.value.product == "targets.json" and e.value.field == field


@pytest.mark.parametrize("missing", ["id", "product_id", "camera", "pixel_uv"])
def test_a_missing_required_field_is_named(missing):
    bad = {k: v for k, v in GOOD.items() if k != missing}
    with pytest.raises(InputError, match=rf"^targets.json: targets\[0\]\.{missing}: .*missing"):
        designations_from_doc({"targets": [bad]})


@pytest.mark.parametrize("doc", [[], "x", {"targets": "d1"}, {"targets": [["d1"]]}])
def test_a_malformed_document_is_an_input_error(doc):
    with pytest.raises(InputError, match=r"^targets.json: targets"):
        designations_from_doc(doc)
    assert designations_from_doc(None) == [] and designations_from_doc({"provenance": {}}) == []


def _as_12_bit_words(dl, replicate: bool):
    """``dl`` with every 8-bit image re-quantised to 12 bits (``round(v * 4095 / 255)``) in 16-bit words: as real
    MER/MSL EDRs store them (``replicate`` False: 0..4095) or bit-replicated to full 16-bit scale as the simulator
    writes them (``v << 4 | v >> 8``)."""
    from scipctl.io.images import encode_png

    out = []
    for im in dl.images:
        v12 = np.rint(im.pixels.astype(np.float64) * 4095.0 / 255.0).astype(np.uint16)
        px = (v12 << 4) | (v12 >> 8) if replicate else v12
        out.append(replace(im, png=encode_png(px), _pixels=px))
    return replace(dl, images=out)


@pytest.mark.parametrize("camera, target_id", [("pancam", "t_slab"), ("navcam", "t_flat")])
def test_12_bit_data_in_16_bit_words_designates_as_its_bit_replicated_copy(far, camera, target_id):
    # Real EDRs keep 12-bit samples in 16-bit words. Judged against 65535 every window looked 16 times flatter and
    # every real designation was vetoed "no texture"; judged against the data's own full scale (4095) the two
    # encodings of the same samples are the same image to within one 12-bit step, and designate alike.
    _, dl = far
    raw, rep = _as_12_bit_words(dl, replicate=False), _as_12_bit_words(dl, replicate=True)
    pid = f"{camera}_left_1_0"
    assert raw.product(pid).full_scale == 4095.0 and rep.product(pid).full_scale == 65535.0
    # bit replication is v * 65535 / 4095 to within 1/4096 of v: the floats differ by less than one 12-bit step
    assert np.max(np.abs(raw.product(pid).pixels_float() - rep.product(pid).pixels_float())) < 1.0 / 4095
    a, _, X_true = _designate_mark(raw, camera, target_id)
    b, _, _ = _designate_mark(rep, camera, target_id)
    assert a.ok and b.ok
    assert a.warnings == b.warnings
    assert not any("texture" in w or "saturated" in w for w in a.warnings)
    # the same match: the two points agree within the stereo error model's 0.5 px of disparity (2 range sigmas)
    assert np.linalg.norm(np.subtract(a.xyz_site_m, b.xyz_site_m)) <= 2.0 * max(a.range_sigma_m, b.range_sigma_m)


def test_a_position_only_pose_warns_that_the_site_point_has_no_heading(far):
    # Mars 2020 raw JSON products carry position only: identity orientation with sigma_yaw pi. The rover-frame
    # point is still measured; the site-frame one rests on a heading nobody knows, and the record says so.
    from scipctl.core.kinematics import RoverPose
    from scipctl.pipeline.designate import UNKNOWN_HEADING_WARNING

    _, dl = far
    rec, left, _ = _designate_mark(dl, "pancam", "t_slab")
    assert rec.ok and UNKNOWN_HEADING_WARNING not in rec.warnings
    p = left.pose
    no_heading = RoverPose(p.T_site_rover, "m2020-raw-json (position only)", p.sigma_position_m, float(np.pi))
    dl2 = replace(dl, images=[replace(im, pose=no_heading) if im.position == left.position else im
                              for im in dl.images])
    rec2, _, _ = _designate_mark(dl2, "pancam", "t_slab")
    assert rec2.ok and UNKNOWN_HEADING_WARNING in rec2.warnings
    assert rec2.xyz_rover_m == rec.xyz_rover_m  # the measurement itself does not change


@pytest.mark.parametrize("camera", ["pancam", "navcam", "hazcam"])
def test_a_camera_the_trust_model_was_not_fitted_on_is_warned_about(camera, near):
    # a hazcam designation got a calibrated-looking p_ok and GO from a model fitted on pancam and navcam
    # designations only (scored as if it were a pancam's), with no word of it
    from scipctl.io.trust_model import PACKAGED_DESIGNATION, load_packaged_trust_model
    from scipctl.pipeline.designation_trust import FITTED_CAMERAS

    _, dl = near
    rec, _, _ = _designate_mark(dl, camera, "t_slab", with_normal=False,
                                trust=load_packaged_trust_model(PACKAGED_DESIGNATION))
    assert rec.p_ok is not None
    warned = [w for w in rec.warnings if "outside its data" in w]
    if camera in FITTED_CAMERAS:
        assert warned == []
    else:
        assert len(warned) == 1 and f"for a {camera} designation" in warned[0]
