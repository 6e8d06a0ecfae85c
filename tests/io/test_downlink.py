"""Reading and writing both downlink containers; round trips; producer variations the contract allows."""

import base64
import hashlib
import json

import numpy as np
import pytest
import yaml

from scipctl.io.cmodfile import write_cmod
from scipctl.io.downlink import downlink_differences, read_downlink, write_downlink
from scipctl.io.downlink_dir import image_file_name
from scipctl.io.downlink_mcap import SCHEMAS, TOPIC_SCHEMAS, mcap_bytes
from scipctl.io.images import encode_png
from scipctl.model import InputError
from tests.io.builders import make_small_downlink, plain_records, write_raw_mcap


def _mcap_messages(path):
    from mcap.reader import make_reader

    with open(path, "rb") as f:
        r = make_reader(f)
        msgs = [(s, c, m) for s, c, m in r.iter_messages()]
        with open(path, "rb") as f2:
            meta = list(make_reader(f2).iter_metadata())
    return msgs, meta


def _assert_poses_close(a, b, tol=1e-14):
    for ia, ib in zip(a.images, b.images):
        assert np.allclose(ia.pose.T_site_rover.R, ib.pose.T_site_rover.R, atol=tol, rtol=0)
        assert np.array_equal(ia.pose.T_site_rover.t, ib.pose.T_site_rover.t)


def test_builder_downlink_survives_mcap(tmp_path):
    dl = make_small_downlink()
    write_downlink(dl, tmp_path / "a.mcap")
    a = read_downlink(tmp_path / "a.mcap")
    # everything but the rotation matrices is bit-identical; rotations pass through a quaternion (ulp-level)
    diffs = [d for d in downlink_differences(dl, a) if ".pose.R" not in d]
    assert diffs == []
    _assert_poses_close(dl, a)
    assert [im.png for im in a.images] == [im.png for im in dl.images]


@pytest.mark.parametrize("bit_depth", [8, 16])
def test_mcap_dir_mcap_is_lossless(tmp_path, bit_depth):
    write_downlink(make_small_downlink(bit_depth=bit_depth), tmp_path / "a.mcap")
    a = read_downlink(tmp_path / "a.mcap")
    write_downlink(a, tmp_path / "b", container="dir")
    b = read_downlink(tmp_path / "b")
    write_downlink(b, tmp_path / "c.mcap")
    c = read_downlink(tmp_path / "c.mcap")
    assert downlink_differences(a, b) == []
    assert downlink_differences(a, c) == []
    for x, y in zip(a.images, c.images):
        assert x.png == y.png  # PNG bytes identical
        for k in "CAHVORE":
            va, vc = getattr(x.camera_model, k), getattr(y.camera_model, k)
            assert (va is None and vc is None) or va.tobytes() == vc.tobytes()
        assert x.pose.T_site_rover.R.tobytes() == y.pose.T_site_rover.R.tobytes()
        assert x.pixels.dtype == (np.uint8 if bit_depth == 8 else np.uint16)
    # same content, same file bytes
    assert (tmp_path / "a.mcap").read_bytes() == (tmp_path / "c.mcap").read_bytes()


def test_source_and_hash_are_set(tmp_path):
    write_downlink(make_small_downlink(), tmp_path / "a.mcap")
    a = read_downlink(tmp_path / "a.mcap")
    assert a.source == str(tmp_path / "a.mcap")
    assert a.source_sha256 == hashlib.sha256((tmp_path / "a.mcap").read_bytes()).hexdigest()
    write_downlink(a, tmp_path / "d", container="dir")
    d = read_downlink(tmp_path / "d")
    assert d.source == str(tmp_path / "d") and len(d.source_sha256) == 64
    (tmp_path / "d" / "images" / image_file_name(a.images[0].product_id)).write_bytes(
        encode_png(np.full((48, 64), 7, np.uint8)))
    assert read_downlink(tmp_path / "d").source_sha256 != d.source_sha256


def test_mcap_layout_follows_the_contract(tmp_path):
    dl = make_small_downlink()
    write_downlink(dl, tmp_path / "a.mcap")
    msgs, meta = _mcap_messages(tmp_path / "a.mcap")
    md = [m for m in meta if m.name == "scip.downlink"]
    assert len(md) == 1 and md[0].metadata == {"format_version": "1", "mission": "test", "sol": "42"}
    by_topic = {}
    for schema, channel, message in msgs:
        assert channel.message_encoding == "json" and schema.encoding == "jsonschema"
        assert schema.name == TOPIC_SCHEMAS[channel.topic]
        by_topic.setdefault(channel.topic, []).append((schema, message))
    assert len(by_topic["/downlink/rover_config"]) == 1
    images = by_topic["/downlink/image"]
    assert len(images) == len(dl.images)
    for _, message in images:
        d = json.loads(message.data)
        assert message.log_time == round(d["time_s"] * 1e9)
        assert d["image"]["format"] == "png"
        assert base64.b64decode(d["image"]["data"]) == dl.product(d["product_id"]).png
    assert len(by_topic["/truth/image"]) == len(dl.truth_images)
    assert len(by_topic["/truth/targets"]) == len(dl.targets)


def test_messages_conform_to_the_written_schemas(tmp_path):
    jsonschema = pytest.importorskip("jsonschema")
    write_downlink(make_small_downlink(), tmp_path / "a.mcap")
    msgs, _ = _mcap_messages(tmp_path / "a.mcap")
    for schema, channel, message in msgs:
        sch = json.loads(schema.data)
        assert sch == json.loads(json.dumps(SCHEMAS[schema.name]))
        jsonschema.validate(json.loads(message.data), sch)


def test_dir_container_layout(tmp_path):
    dl = make_small_downlink()
    write_downlink(dl, tmp_path / "d", container="dir")
    doc = yaml.safe_load((tmp_path / "d" / "downlink.yaml").read_text())
    assert doc["format_version"] == 1 and doc["sol"] == 42 and doc["mission"] == "test"
    for rec, im in zip(doc["images"], dl.images):
        assert rec["image"] == f"images/{im.product_id}.png"
        assert (tmp_path / "d" / rec["image"]).read_bytes() == im.png
    assert set(doc["truth"]) == {"images", "targets"}


def test_writing_is_deterministic_and_atomic(tmp_path):
    dl = make_small_downlink()
    assert mcap_bytes(dl) == mcap_bytes(dl)
    write_downlink(dl, tmp_path / "d", container="dir")
    before = sorted(p.name for p in tmp_path.iterdir())
    bad = make_small_downlink()
    bad.images[1].product_id = bad.images[0].product_id
    with pytest.raises(InputError):
        write_downlink(bad, tmp_path / "d", container="dir")
    with pytest.raises(InputError):
        write_downlink(bad, tmp_path / "x.mcap")
    assert sorted(p.name for p in tmp_path.iterdir()) == before  # nothing half-written, old output intact
    assert read_downlink(tmp_path / "d").images[1].product_id == dl.images[1].product_id


def test_refuses_to_replace_an_unrelated_directory(tmp_path):
    (tmp_path / "home").mkdir()
    (tmp_path / "home" / "notes.txt").write_text("precious")
    with pytest.raises(InputError) as ei:
        write_downlink(make_small_downlink(), tmp_path / "home", container="dir")
    assert ei.value.field == "output"
    assert (tmp_path / "home" / "notes.txt").read_text() == "precious"


def test_unsafe_product_ids_get_safe_file_names(tmp_path):
    dl = make_small_downlink(n_positions=1, with_targets=False, with_truth=False)
    dl.images[0].product_id = "../escape/ok?"
    dl.images[1].product_id = ".hidden"
    write_downlink(dl, tmp_path / "d", container="dir")
    names = sorted(p.name for p in (tmp_path / "d" / "images").iterdir())
    assert all("/" not in n and not n.startswith(".") for n in names)
    assert not (tmp_path / "escape").exists()
    back = read_downlink(tmp_path / "d")
    assert [d for d in downlink_differences(dl, back) if ".pose.R" not in d] == []
    assert back.images[0].product_id == "../escape/ok?" and back.images[0].png == dl.images[0].png


# --------------------------------------------------------------------------- producer variations
META = {"format_version": "1", "mission": "test", "sol": "42"}


def test_extra_topics_and_keys_are_ignored(tmp_path):
    dl = make_small_downlink()
    topics = plain_records(dl)
    for rec in topics["/downlink/image"]:
        rec["producer_note"] = {"nested": [1, 2, 3]}
        rec["pose"]["covariance"] = [0.0] * 36
        rec["camera_model"]["S"] = "whatever"
    topics["/downlink/rover_config"][0]["cameras"]["hazcam"]["left"]["serial"] = "HZ-L-7"
    topics["/downlink/rover_config"][0]["cameras"]["microscope"] = topics["/downlink/rover_config"][0]["cameras"]["pancam"]
    write_raw_mcap(tmp_path / "x.mcap", dict(META, producer="gds 3.1"), topics,
                    extra_topics={"/tf": [{"anything": 1}], "/downlink/image_thumbnails": [b"\x00\x01 not json"]})
    got = read_downlink(tmp_path / "x.mcap")
    assert [im.product_id for im in got.images] == [im.product_id for im in dl.images]
    assert "microscope" in got.rover_config.cameras
    assert [d for d in downlink_differences(dl, got) if ".pose.R" not in d and "microscope" not in d] == []


def test_non_unit_joint_axes_round_trip_exactly(tmp_path):
    """The reader normalises joint axes; normalising the written unit axis again may change its last bits
    (it did for these two), so the writer writes the axis it read."""
    topics = plain_records(make_small_downlink(n_positions=1))
    mast = topics["/downlink/rover_config"][0]["mast"]
    mast["pan"]["axis"] = [687.1907331094725, 0.0, 1.0]
    mast["tilt"]["axis"] = [0.0, 1.0, 1.580343551617133e-05]
    for j in ("pan", "tilt"):
        u = np.array(mast[j]["axis"]) / np.linalg.norm(mast[j]["axis"])
        assert (u / np.linalg.norm(u)).tobytes() != u.tobytes()  # the case this test is about
    write_raw_mcap(tmp_path / "x.mcap", META, topics)
    a = read_downlink(tmp_path / "x.mcap")
    write_downlink(a, tmp_path / "b", container="dir")
    write_downlink(read_downlink(tmp_path / "b"), tmp_path / "c.mcap")
    c = read_downlink(tmp_path / "c.mcap")
    assert downlink_differences(a, c) == []
    for j in ("pan", "tilt"):
        assert getattr(a.rover_config.mast, j).axis.tobytes() == getattr(c.rover_config.mast, j).axis.tobytes()


def test_quaternion_sign_and_mast_on_body_camera(tmp_path):
    dl = make_small_downlink(n_positions=1)
    topics = plain_records(dl)
    for rec in topics["/downlink/image"]:
        rec["pose"]["orientation_wxyz"] = [-q for q in rec["pose"]["orientation_wxyz"]]
        if rec["camera"] == "hazcam":
            rec["mast"] = {"pan_rad": 1.0, "tilt_rad": 2.0}  # allowed and ignored on body cameras
    write_raw_mcap(tmp_path / "x.mcap", META, topics)
    got = read_downlink(tmp_path / "x.mcap")
    _assert_poses_close(dl, got)
    assert all(im.mast is None for im in got.images if im.camera == "hazcam")


def test_unknown_camera_names_are_carried(tmp_path):
    dl = make_small_downlink(n_positions=1, with_targets=False, with_truth=False)
    dl.images[-1].camera = "mastcam_z"  # not in the rover configuration: no mount, no size rule
    dl.images[-1].mast = None
    write_downlink(dl, tmp_path / "x.mcap")
    assert read_downlink(tmp_path / "x.mcap").images[-1].camera == "mastcam_z"


_HAND_YAML = """\
# hand-written: anchors, aliases, cmod files, 1e-3 style floats, rover_config in its own file
format_version: 1
mission: test
sol: 42
rover_config: config/rover.yaml
common_pose: &pose0
  position_m: [0.0, 0.0, 0.0]
  orientation_wxyz: [1.0, 0.0, 0.0, 0.0]
  source: wheel_odometry
  sigma_position_m: 5e-2
images:
  - &img
    product_id: hazcam_left_1_0
    camera: hazcam
    eye: left
    time_s: 1000.0
    position: {site: 1, drive: 0}
    pose: *pose0
    camera_model_file: models/hazcam_left.cahvore
    width: 64
    height: 48
    image: images/hazcam_left_1_0.png
  - <<: *img
    product_id: hazcam_right_1_0
    eye: right
    time_s: 1000.25
    camera_model_file: models/hazcam_right.cahvore
    image: images/hazcam_right_1_0.png
targets:
  - id: t1
    kind: flat
    marks:
      - {product_id: hazcam_left_1_0, u: 10.5, v: 20.25, sigma_px: 1e-3}
"""

_ROVER_YAML = """\
name: hand-rover
mast:
  pan:  {origin_m: [0.3, 0, -1.0], axis: [0, 0, 1]}
  tilt: {origin_m: [0.3, 0, -1.5], axis: [0, 1, 0]}
cameras:
  hazcam:
    mount: body
    left:  {camera_model_file: ../models/hazcam_left.cahvore, width: 64, height: 48}
    right: {camera_model_file: ../models/hazcam_right.cahvore, width: 64, height: 48}
"""


def _hand_dir(tmp_path):
    dl = make_small_downlink(n_positions=1)
    root = tmp_path / "hand"
    (root / "images").mkdir(parents=True)
    (root / "models").mkdir()
    (root / "config").mkdir()
    for eye in ("left", "right"):
        spec = dl.rover_config.cameras["hazcam"].left if eye == "left" else dl.rover_config.cameras["hazcam"].right
        write_cmod(root / "models" / f"hazcam_{eye}.cahvore", spec.model, 64, 48)
        (root / "images" / f"hazcam_{eye}_1_0.png").write_bytes(dl.product(f"hazcam_{eye}_1_0").png)
    (root / "downlink.yaml").write_text(_HAND_YAML)
    (root / "config" / "rover.yaml").write_text(_ROVER_YAML)
    return dl, root


def test_hand_written_directory_with_anchors_cmod_files_and_external_config(tmp_path):
    dl, root = _hand_dir(tmp_path)
    got = read_downlink(root)
    assert [im.product_id for im in got.images] == ["hazcam_left_1_0", "hazcam_right_1_0"]
    right = got.product("hazcam_right_1_0")
    assert right.camera == "hazcam" and right.time_s == 1000.25  # merged from the anchor, then overridden
    ref = dl.rover_config.cameras["hazcam"].right.model
    assert right.camera_model.H.tobytes() == ref.H.tobytes() and right.camera_model.linearity == 0.37
    assert got.rover_config.name == "hand-rover"
    assert got.rover_config.cameras["hazcam"].left.model.E.tobytes() == dl.rover_config.cameras["hazcam"].left.model.E.tobytes()
    assert right.pose.sigma_position_m == 0.05  # "5e-2" is a number, not a string
    assert got.targets[0].marks[0].sigma_px == 1e-3
    # and it converts to MCAP and back without loss
    write_downlink(got, tmp_path / "h.mcap")
    assert downlink_differences(got, read_downlink(tmp_path / "h.mcap")) == []


def test_camera_model_file_dimensions_must_match(tmp_path):
    dl, root = _hand_dir(tmp_path)
    write_cmod(root / "models" / "hazcam_right.cahvore", dl.rover_config.cameras["hazcam"].right.model, 32, 24)
    with pytest.raises(InputError) as ei:
        read_downlink(root)
    assert ei.value.field.endswith("camera_model_file") and "32x24" in ei.value.message


def test_reading_through_downlink_yaml_path(tmp_path):
    dl = make_small_downlink(n_positions=1)
    write_downlink(dl, tmp_path / "d", container="dir")
    assert len(read_downlink(tmp_path / "d" / "downlink.yaml").images) == len(dl.images)


def test_benchmark_read_30_megapixel_images(benchmark, tmp_path):
    """Speed target: ~30 1024x1024 PNGs read and validated in a second or two (pytest --benchmark-enable)."""
    import dataclasses

    one = make_small_downlink(width=1024, height=1024, n_positions=1, with_targets=False, with_truth=False)
    dl = dataclasses.replace(one, images=[])
    for site in range(1, 6):  # the same six stereo images at five sites (decoding cost is per product)
        dl.images += [dataclasses.replace(im, product_id=f"{im.product_id}_s{site}", site=site, time_s=im.time_s + 1000 * site)
                      for im in one.images]
    assert len(dl.images) == 30
    write_downlink(dl, tmp_path / "big.mcap")
    got = benchmark(read_downlink, tmp_path / "big.mcap")
    assert len(got.images) == 30 and all(im._pixels is not None for im in got.images)
