"""Reading real rover products (PDS3, VICAR, PDS4, Mars 2020 raw JSON) into a downlink (issue #16, parts 1-3, 6).

Real files are read where they are (``shared/real`` beside the checkout; the
tests skip with the reason when absent). The expected values come from an
independent reader of the same text: ``pvl`` for PDS3 labels, ``pdr``'s PDS4
metadata, the raw JSON string split by hand, raw bytes at the label's
pointer for pixels. Label edge cases use small products written in tmp_path
(tests/io/pds_builders.py).
"""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest
from typer.testing import CliRunner

from scipctl.cli import app
from scipctl.core.transforms import RigidTransform, quat_wxyz_to_matrix
from scipctl.io.downlink import product_to_plain, read_downlink, write_downlink
from scipctl.io.pds_products import read_products
from scipctl.model import InputError
from tests.io.pds_builders import pds3_product
from tests.io.real_data import real
from tests.models import all_models

runner = CliRunner()
MODELS = all_models()
GROUP_SPELLINGS = {
    "model": ("GEOMETRIC_CAMERA_MODEL", "GEOMETRIC_CAMERA_MODEL_PARMS"),
    "rover": ("ROVER_COORDINATE_SYSTEM", "ROVER_COORD_SYSTEM_PARMS", "ROVER_COORDINATE_SYSTEM_PARMS"),
    "rsm": ("RSM_ARTICULATION_STATE", "RSM_ARTICULATION_STATE_PARMS"),
}


def _group(label, which):
    for name in GROUP_SPELLINGS[which]:
        if name in label:
            return label[name]
    raise AssertionError(f"no {which} group")


def _val(x):
    return float(getattr(x, "value", x))


def _pvl_expectations(path):
    """What an independent PDS3 parser (pvl) reads from the label: model components, pose, mast, size."""
    import pvl

    lab = pvl.load(str(path))
    g = _group(lab, "model")
    ids = list(g["MODEL_COMPONENT_ID"])
    comps = {cid: g[f"MODEL_COMPONENT_{i}"] for i, cid in enumerate(ids, start=1)}
    r = _group(lab, "rover")
    rsm = _group(lab, "rsm")
    angles = dict(zip(rsm["ARTICULATION_DEVICE_ANGLE_NAME"], [_val(a) for a in rsm["ARTICULATION_DEVICE_ANGLE"]]))
    return {
        "type": str(g["MODEL_TYPE"]), "comps": comps, "frame": str(g["REFERENCE_COORD_SYSTEM_NAME"]),
        "offset": [float(x) for x in r["ORIGIN_OFFSET_VECTOR"]], "quat": [float(x) for x in r["ORIGIN_ROTATION_QUATERNION"]],
        "index": tuple(int(x) for x in r["COORDINATE_SYSTEM_INDEX"]), "angles": angles,
        "lines": int(lab["IMAGE"]["LINES"]), "samples": int(lab["IMAGE"]["LINE_SAMPLES"]),
        "frame_id": str(lab["FRAME_ID"]), "label": lab,
    }


def _assert_model_equals_label(model_dict, exp):
    assert model_dict["type"] == exp["type"]
    for cid, v in exp["comps"].items():
        if cid == "T":
            assert model_dict["cahvore_type"] == int(v)
        elif cid == "P":
            assert model_dict["linearity"] == float(v)
        else:  # the same printed decimals parse to the same doubles: equal to every printed digit
            assert model_dict[cid] == [float(x) for x in v], cid


def _real_pds3_files():
    out = []
    for sub, pat in (("01_", "*.IMG"), ("05_", "*.IMG"), ("05_", "*.LBL"), ("09_", "*.LBL")):
        d = real(sub)
        out += sorted(d.glob(pat))
    return out


# --------------------------------------------------------------------------- real PDS3 (MSL): attached and detached
def test_every_real_pds3_product_reads_with_the_labels_model_pose_and_mast():
    files = _real_pds3_files()
    assert len(files) == 1 + 2 + 2 + 13
    for f in files:
        exp = _pvl_expectations(f)
        dl = read_products(f)
        assert len(dl.images) == 1
        im = dl.images[0]
        rec = product_to_plain(im)
        assert exp["frame"] == "ROVER_NAV_FRAME"  # all real models are given in the rover frame: no transform
        _assert_model_equals_label(rec["camera_model"], exp)
        assert rec["pose"]["position_m"] == exp["offset"]
        assert rec["pose"]["orientation_wxyz"] == exp["quat"]  # the label's quaternion digits are kept
        assert (im.site, im.drive) == exp["index"][:2]
        assert (im.width, im.height) == (exp["samples"], exp["lines"])
        assert im.eye == exp["frame_id"].lower()
        if im.camera == "navcam":
            assert (im.mast.pan_rad, im.mast.tilt_rad) == (exp["angles"]["AZIMUTH-MEASURED"],
                                                          exp["angles"]["ELEVATION-MEASURED"])
        else:
            assert im.camera == "hazcam" and im.mast is None


def test_real_edr_pixels_are_the_16_bit_words_at_the_labels_pointer():
    """12-bit data in 16-bit MSB words stays 16-bit; the pixels are the raw words at ``(^IMAGE - 1) * RECORD_BYTES``."""
    for f in sorted(real("01_").glob("*.IMG")) + sorted(real("05_").glob("*.IMG")):
        exp = _pvl_expectations(f)
        lab = exp["label"]
        ptr = lab["^IMAGE"]
        rec = ptr[1] if isinstance(ptr, (list, tuple)) else ptr
        start = (int(rec) - 1) * int(lab["RECORD_BYTES"])
        n = exp["lines"] * exp["samples"]
        raw = np.frombuffer(f.read_bytes()[start:start + 2 * n], dtype=">i2").reshape(exp["lines"], exp["samples"])
        im = read_products(f).images[0]
        assert im.pixels.dtype == np.uint16
        assert np.array_equal(im.pixels, raw.astype(np.uint16))
        assert int(im.pixels.max()) <= 4095  # 12-bit data
        # ... whose full scale is 4095, not the 16-bit word's 65535 (every texture, saturation and brightness
        # threshold reads pixels_float; against 65535 a real EDR looked 16 times darker and textureless)
        assert im.full_scale == 4095.0
        assert np.array_equal(im.pixels_float(), raw.astype(np.float32) / np.float32(4095))


def test_attached_and_detached_labels_of_one_real_product_agree():
    d = real("05_")
    for img in sorted(d.glob("*.IMG")):
        a = read_products(img).images[0]
        b = read_products(img.with_suffix(".LBL")).images[0]
        assert product_to_plain(a) == product_to_plain(b)
        assert np.array_equal(a.pixels, b.pixels)


def test_a_real_directory_reads_each_product_once_and_validates():
    d05 = read_downlink(real("05_"))  # .IMG + .LBL of two products: two products
    assert sorted(im.product_id for im in d05.images) == sorted(p.stem for p in real("05_").glob("*.IMG"))
    assert d05.mission == "MSL" and d05.sol == min(1343, 1347)
    d09 = read_downlink(real("09_"))  # 13 detached labels, data absent, gallery browse JPEGs beside them
    assert len(d09.images) == len(list(real("09_").glob("*.LBL")))
    drives = [im.drive for im in sorted(d09.images, key=lambda i: i.time_s)]
    assert drives == sorted(drives) and len(set(drives)) == len(drives)  # one drive step per frame
    assert {im.pixels.dtype for im in d09.images} == {np.dtype(np.uint8)}  # lossy 8-bit browse, label size 256x256
    assert {(im.width, im.height) for im in d09.images} == {(256, 256)}


def _plain_vicar(tmp_path):
    """The VICAR part of the real PDS3-wrapped MSL EDR, written as a plain VICAR file."""
    img = sorted(real("01_").glob("*.IMG"))[0]
    lab = _pvl_expectations(img)["label"]
    start = (int(lab["^IMAGE_HEADER"]) - 1) * int(lab["RECORD_BYTES"])
    vic = tmp_path / (img.stem + ".VIC")
    vic.write_bytes(img.read_bytes()[start:])
    return img, vic


def test_plain_vicar_without_the_optional_reader_is_a_clear_input_error(tmp_path, monkeypatch):
    import sys

    _, vic = _plain_vicar(tmp_path)
    monkeypatch.setitem(sys.modules, "vicar", None)  # import vicar -> ImportError
    with pytest.raises(InputError) as ei:
        read_products(vic)
    assert ei.value.field == "format" and "rms-vicar" in ei.value.message and "\n" not in str(ei.value)


def test_real_vicar_file_reads_like_its_pds3_wrapper(tmp_path):
    """The VICAR part of a PDS3-wrapped EDR, as a plain VICAR file (read by rms-vicar), gives the same product."""
    pytest.importorskip("vicar", reason="rms-vicar is the optional 'vicar' extra (not in the locked stack)")
    img = sorted(real("01_").glob("*.IMG"))[0]
    lab = _pvl_expectations(img)["label"]
    start = (int(lab["^IMAGE_HEADER"]) - 1) * int(lab["RECORD_BYTES"])
    vic = tmp_path / (img.stem + ".VIC")
    vic.write_bytes(img.read_bytes()[start:])
    a, b = read_products(img).images[0], read_products(vic).images[0]
    ra, rb = product_to_plain(a), product_to_plain(b)
    ra["pose"].pop("source"), rb["pose"].pop("source")
    assert ra == rb
    assert np.array_equal(a.pixels, b.pixels)


# --------------------------------------------------------------------------- real Mars 2020: raw JSON and PDS4
def test_real_m2020_raw_json_models_equal_the_json_string():
    d = real("07_")
    dl = read_downlink(d)
    jsons = sorted(d.glob("*-metadata.json"))
    assert len(dl.images) == len(jsons)  # the unlabelled MSL JPEG is not a product
    for jf in jsons:
        meta = json.loads(jf.read_text())
        im = dl.product(jf.name[: -len("-metadata.json")])
        parts = meta["camera_model_component_list"].split(";")
        rec = product_to_plain(im)["camera_model"]
        for cid, text in zip("CAHVORE", parts[:7]):
            assert rec[cid] == [float(x) for x in text.strip("()").split(",")]
        assert (rec["cahvore_type"], rec["linearity"]) == (int(parts[7]), float(parts[8]))
        x0, y0, w_full, h_full = meta["subframe_rect"]
        s = meta["scale_factor"]
        assert (im.width, im.height) == (w_full / s, h_full / s)
        assert (im.site, im.drive, im.time_s) == (meta["site"], meta["drive"], meta["sclk"])
        assert im.camera == "navcam" and im.eye == meta["instrument"].split("_")[-1].lower()
        assert im.pose.position_m.tolist() == [float(x) for x in meta["xyz"].strip("()").split(",")]
        assert im.pose.sigma_yaw_rad == pytest.approx(np.pi)  # the JSON has no attitude: heading unknown


def _pdr_pds4_model(xml):
    import pdr

    m = pdr.read(str(xml)).metadata
    vec = lambda name, keys: [float(m.metaget_(name)[f"geom:{k}"]) for k in keys]  # noqa: E731
    xyz_p, xyz_u, xyz_px = ("x_position", "y_position", "z_position"), ("x_unit", "y_unit", "z_unit"), (
        "x_pixel", "y_pixel", "z_pixel")
    cahvore = m.metaget_("geom:CAHVORE_Model")
    return {
        "C": vec("geom:Vector_Center", xyz_p), "A": vec("geom:Vector_Axis", xyz_u),
        "H": vec("geom:Vector_Horizontal", xyz_px), "V": vec("geom:Vector_Vertical", xyz_px),
        "O": vec("geom:Vector_Optical", xyz_u),
        "R": [float(cahvore["geom:Radial_Terms"][f"geom:c{i}"]) for i in range(3)],
        "E": [float(cahvore["geom:Entrance_Terms"][f"geom:c{i}"]) for i in range(3)],
        "cahvore_type": int(cahvore["geom:cahvore_model_type"]),
        "linearity": float(cahvore["geom:cahvore_model_parameter"]),
    }


def test_real_pds4_label_alone_is_exit_2_naming_the_data_file(tmp_path):
    xml = sorted(real("11_").glob("*.xml"))[0]
    r = runner.invoke(app, ["ingest", str(xml), "-o", str(tmp_path / "ws")])
    assert r.exit_code == 2
    assert r.stderr.count("\n") == 1 and "NLF_0629" in r.stderr and "File_Area_Observational.File.file_name" in r.stderr
    assert not (tmp_path / "ws").exists()


def test_real_pds4_label_with_a_data_file_reads_model_pose_and_mast(tmp_path):
    """The real PDS4 label with a synthetic data file at its offset: pixels via pdr, geometry from the label."""
    import cv2

    xml = sorted(real("11_").glob("*.xml"))[0]
    shutil.copy(xml, tmp_path / xml.name)
    text = xml.read_text()
    offset = int(text.split("<Array_3D_Image>")[1].split("<offset unit=\"byte\">")[1].split("<")[0]) \
        if "<offset unit=\"byte\">" in text.split("<Array_3D_Image>")[1] else 46656
    rng = np.random.default_rng(3)
    bands = rng.integers(0, 256, (3, 976, 1296), dtype=np.uint8)
    data_name = text.split("<file_name>")[1].split("<")[0]
    (tmp_path / data_name).write_bytes(b"\0" * offset + bands.tobytes())
    im = read_downlink(tmp_path / xml.name).images[0]
    gray = cv2.cvtColor(np.ascontiguousarray(np.moveaxis(bands, 0, -1)), cv2.COLOR_RGB2GRAY)
    assert np.array_equal(im.pixels, gray)
    rec = product_to_plain(im)["camera_model"]
    exp = _pdr_pds4_model(xml)
    for k, v in exp.items():
        assert rec[k] == v, k
    assert (im.site, im.drive, im.width, im.height) == (30, 1344, 1296, 976)
    assert im.time_s == float(text.split("<msn:spacecraft_clock_start>")[1].split("<")[0])
    # rover pose: the ROVER_NAV_FRAME definition (pdr's parse)
    import pdr

    md = pdr.read(str(xml)).metadata
    geo = md["Product_Observational"]["Observation_Area"]["Discipline_Area"]["geom:Geometry"]
    defs = geo.getall("geom:Geometry_Lander")[0].getall("geom:Coordinate_Space_Definition")
    rover = next(d for d in defs if d.getall("local_identifier")[0].startswith("ROVER_NAV_FRAME"))
    off = [float(rover["geom:Vector_Origin_Offset"][f"geom:{k}"]) for k in ("x_position", "y_position", "z_position")]
    q = [float(rover["geom:Quaternion_Plus_Direction"][f"geom:{k}"]) for k in ("qcos", "qsin1", "qsin2", "qsin3")]
    assert product_to_plain(im)["pose"]["position_m"] == off
    assert product_to_plain(im)["pose"]["orientation_wxyz"] == q
    assert im.mast is not None and im.exposure_ms == 11.111


def test_info_json_lists_full_models_poses_and_positions_for_real_and_mcap(tmp_path):
    from tests.io.builders import make_small_downlink

    write_downlink(make_small_downlink(n_positions=1), tmp_path / "x.mcap")
    docs = []
    for src in (tmp_path / "x.mcap", real("05_")):
        r = runner.invoke(app, ["info", str(src), "--json"])
        assert r.exit_code == 0, r.stderr
        docs.append(json.loads(r.stdout))
    keys = [{frozenset(im) for im in d["images"]} for d in docs]
    assert keys[0] == keys[1] and len(keys[0]) == 1  # one record structure, the same for both
    dl = read_downlink(real("05_"))
    for rec in docs[1]["images"]:
        im = dl.product(rec["product_id"])
        assert rec["camera_model"] == im.camera_model.to_dict()
        assert rec["position"] == {"site": im.site, "drive": im.drive}
        assert rec["pose"] == product_to_plain(im)["pose"]
    assert not list(real("05_").glob("*.scipctl"))  # info writes nothing


def test_info_says_a_position_only_pose_has_an_unknown_heading():
    # the Mars 2020 raw JSON gives position only (identity orientation, sigma_yaw pi): its yaw is not 0.00
    src = sorted(real("07_").glob("*-metadata.json"))[0]
    r = runner.invoke(app, ["info", str(src)])
    assert r.exit_code == 0, r.stderr
    row = next(line for line in (r.stdout + r.stderr).splitlines() if "position only" in line)
    assert "unknown" in row and "0.00" not in row
    r = runner.invoke(app, ["info", str(src), "--json"])
    pose = json.loads(r.stdout)["positions"][0]["pose"]
    assert pose["sigma_yaw_deg"] >= 180.0


# --------------------------------------------------------------------------- label flavours built in tmp_path
PIX16 = np.random.default_rng(0).integers(0, 4096, (48, 64)).astype(np.uint16)
PIX8 = np.random.default_rng(1).integers(0, 256, (48, 64)).astype(np.uint8)


@pytest.mark.parametrize("flavour", ["MSL", "MSL-archive", "MER", "MSSS"])
@pytest.mark.parametrize("detached", [False, True])
@pytest.mark.parametrize("kind", ["CAHV", "CAHVOR", "CAHVORE1", "CAHVORE2", "CAHVORE3"])
def test_label_flavours_read_model_pose_mast_units_and_fillers(tmp_path, flavour, detached, kind):
    model = MODELS[kind]
    px = PIX16 if kind != "CAHVORE2" else PIX8
    quat = (0.0217046, 0.0118624, -0.0386198, -0.998948)
    p = pds3_product(tmp_path, "P1", px, model, flavour=flavour, detached=detached, rover_quat=quat,
                     exposure="0.4096 <s>" if kind == "CAHV" else "409.6 <ms>")
    im = read_products(p).images[0]
    assert im.camera_model.to_dict() == model.to_dict()  # repr digits: exactly the model written
    assert (im.site, im.drive) == (54, 992) and (im.camera, im.eye) == ("navcam", "left")
    assert product_to_plain(im)["pose"]["orientation_wxyz"] == list(quat)  # split over two lines in the label
    assert (im.mast.pan_rad, im.mast.tilt_rad) == (4.73721, 0.769993)  # "<rad>" units; a 1e+30 filler ignored
    assert im.exposure_ms == pytest.approx(409.6, rel=1e-12)  # "<ms>" or "<s>"
    assert im.pixels.dtype == px.dtype and np.array_equal(im.pixels, px)
    assert im.time_s == 516721703.665


def _project_both_ways(label_model, read_model, T_labelframe_rover):
    rng = np.random.default_rng(7)
    cam_pts = label_model.C + (label_model.A * rng.uniform(2, 10, (50, 1))
                               + rng.normal(0, 0.3, (50, 3)))  # points in front, in the label's frame
    uv_label = label_model.project(cam_pts)
    uv_read = read_model.project(T_labelframe_rover.inverse().apply(cam_pts))
    ok = np.all(np.isfinite(uv_label), axis=1)
    assert ok.sum() > 40
    return np.abs(uv_label[ok] - uv_read[ok]).max()


def test_model_in_the_site_frame_is_moved_into_the_rover_frame(tmp_path):
    """Independent check: project site points with the label's model, and their rover-frame coordinates with ours."""
    model_rover = MODELS["CAHVORE3"]
    quat = (0.423523, 0.00304319, 0.0215231, -0.905624)
    offset = (-176.437, -129.578, -0.203979)
    T_site_rover = RigidTransform(quat_wxyz_to_matrix(quat), np.array(offset))
    model_site = model_rover.transformed(T_site_rover)
    p = pds3_product(tmp_path, "PSITE", PIX16, model_site, rover_quat=quat, rover_offset=offset, site=14, drive=1262,
                     model_frame="SITE_FRAME", model_index="14", instrument="FHAZ_LEFT_B")
    im = read_products(p).images[0]
    assert _project_both_ways(model_site, im.camera_model, T_site_rover) < 1e-6
    assert np.abs(im.camera_model.C - model_rover.C).max() < 1e-9


def test_model_in_the_mast_head_frame_and_local_level_frame(tmp_path):
    head_off, head_q = (0.8045, 0.559285, -1.90608), (0.649067, 0.281544, -0.280342, 0.648732)
    T_rover_head = RigidTransform(quat_wxyz_to_matrix(head_q), np.array(head_off))
    model_rover = MODELS["CAHVOR"]
    model_head = model_rover.transformed(T_rover_head.inverse())
    idx = "(54,992,12,14,0,0,72,54,0,0)"
    from tests.io.pds_builders import cs_group

    rsm = cs_group("RSM_COORDINATE_SYSTEM", "RSM_HEAD_FRAME", idx, head_off, head_q, "ROVER_NAV_FRAME", idx)
    p = pds3_product(tmp_path, "PHEAD", PIX16, model_head, model_frame="RSM_HEAD_FRAME", extra_groups=rsm)
    im = read_products(p).images[0]
    assert _project_both_ways(model_head, im.camera_model, T_rover_head.inverse()) < 1e-6
    # LOCAL_LEVEL_FRAME: at the rover origin, site axes
    quat = (0.0217046, 0.0118624, -0.0386198, -0.998948)
    T_ll_rover = RigidTransform(quat_wxyz_to_matrix(quat), np.zeros(3))
    (tmp_path / "ll").mkdir()
    p = pds3_product(tmp_path / "ll", "PLL", PIX16, model_rover.transformed(T_ll_rover), model_frame="LOCAL_LEVEL_FRAME",
                     rover_quat=quat)
    im = read_products(p).images[0]
    assert _project_both_ways(model_rover.transformed(T_ll_rover), im.camera_model, T_ll_rover) < 1e-6


def test_stereo_partners_pair_by_spacecraft_clock_and_instrument(tmp_path):
    for name, inst, fid, sclk, drive in (("NLB_1", "NAV_LEFT_B", "LEFT", "516721703.665", 992),
                                         ("NRB_1", "NAV_RIGHT_B", "RIGHT", "516721703.665", 992),
                                         ("NLB_2", "NAV_LEFT_B", "LEFT", "516721803.100", 998),
                                         ("FLB_1", "FHAZ_LEFT_B", "LEFT", "516721703.665", 992)):
        pds3_product(tmp_path, name, PIX16, MODELS["CAHVOR"], instrument=inst, frame_id=fid, sclk=sclk, drive=drive,
                     rover_offset=(9.57832, -9.24059 + (drive - 992), -0.301764))
    dl = read_downlink(tmp_path)  # validated: the pair agrees in size and time
    assert dl.stereo_pair(dl.product("NLB_1")).product_id == "NRB_1"
    assert dl.stereo_pair(dl.product("NLB_2")) is None  # after a drive: no partner
    assert dl.product("FLB_1").camera == "hazcam" and dl.stereo_pair(dl.product("FLB_1")) is None
    ws = tmp_path.parent / (tmp_path.name + "-ws")
    r = runner.invoke(app, ["ingest", str(tmp_path), "-o", str(ws)])
    assert r.exit_code == 0, r.stderr
    again = read_downlink(ws)  # the workspace is a container-B downlink with the same content
    assert [product_to_plain(a) for a in again.images] == [product_to_plain(b) for b in dl.images]


# --------------------------------------------------------------------------- bad products: exit 2, product + field
def _bad(tmp_path, src, *fields):
    out = tmp_path / "ws"
    r = runner.invoke(app, ["ingest", str(src), "-o", str(out)])
    assert r.exit_code == 2, r.stdout + r.stderr
    assert r.stderr.count("\n") == 1 and r.stderr.startswith("scipctl: error: ")
    for f in fields:
        assert f in r.stderr, r.stderr
    assert not out.exists() and not list(tmp_path.glob("ws*"))
    return r.stderr


def test_truncated_products_are_exit_2(tmp_path):
    (tmp_path / "a").mkdir(), (tmp_path / "b").mkdir()
    p = pds3_product(tmp_path / "a", "PTRUNC", PIX16, MODELS["CAHVOR"], truncate_to=3000)
    _bad(tmp_path, p, "PTRUNC", "IMAGE", "cannot read the pixels")
    p = pds3_product(tmp_path / "b", "PTRUNC2", PIX16, MODELS["CAHVOR"], detached=True, truncate_to=1000)
    _bad(tmp_path, p, "PTRUNC2", "IMAGE")


def test_a_real_label_cut_short_is_exit_2_saying_so(tmp_path):
    # a real EDR cut inside its 20 kB label: before, pdr failed in its own code ("'NoneType' object has no
    # attribute 'get'") and the message showed it
    f = sorted(real("01_").glob("*.IMG"))[0]
    for n in (3000, 20000):
        (tmp_path / f"c{n}").mkdir()
        p = tmp_path / f"c{n}" / f.name
        p.write_bytes(f.read_bytes()[:n])
        err = _bad(tmp_path, p, "IMAGE", "no IMAGE object", "cut short")
        assert "NoneType" not in err


def test_label_without_camera_model_is_exit_2(tmp_path):
    p = pds3_product(tmp_path, "PNOMODEL", PIX16, None)
    _bad(tmp_path, p, "PNOMODEL", "GEOMETRIC_CAMERA_MODEL", "no camera model")


def test_model_in_an_unknown_frame_or_another_rover_position_is_exit_2(tmp_path):
    (tmp_path / "a").mkdir(), (tmp_path / "b").mkdir()
    p = pds3_product(tmp_path / "a", "PFRAME", PIX16, MODELS["CAHVOR"], model_frame="ARM_TURRET_FRAME")
    _bad(tmp_path, p, "PFRAME", "REFERENCE_COORD_SYSTEM_NAME", "ARM_TURRET_FRAME")
    p = pds3_product(tmp_path / "b", "PDRIVE", PIX16, MODELS["CAHVOR"], model_index="(54,990,12,14,0,0,72,54,0,0)")
    _bad(tmp_path, p, "PDRIVE", "REFERENCE_COORD_SYSTEM_INDEX")


def test_sizes_that_disagree_with_the_label_are_exit_2(tmp_path):
    (tmp_path / "a").mkdir(), (tmp_path / "b").mkdir(), (tmp_path / "c").mkdir()
    p = pds3_product(tmp_path / "a", "PBIG", PIX16, MODELS["CAHVOR"], label_lines=4800, detached=True)
    _bad(tmp_path, p, "PBIG", "IMAGE")
    # data file absent, browse picture of another size
    import cv2

    p = pds3_product(tmp_path / "b", "PBROWSEM1", PIX16, MODELS["CAHVOR"], detached=True)
    (tmp_path / "b" / "PBROWSEM1.IMG").unlink()
    cv2.imwrite(str(tmp_path / "b" / "PBROWSEM_.jpg"), np.zeros((32, 32), np.uint8))
    _bad(tmp_path, p, "PBROWSEM1", "^IMAGE", "32x32", "64x48")
    # raw JSON whose subframe/scale disagree with its PNG
    src = real("07_")
    jf = sorted(src.glob("*-metadata.json"))[0]
    meta = json.loads(jf.read_text())
    meta["scale_factor"] = 2 * meta["scale_factor"]
    meta.pop("dimension")
    (tmp_path / "c" / jf.name).write_text(json.dumps(meta))
    shutil.copy(jf.parent / jf.name.replace("-metadata.json", ".png"), tmp_path / "c")
    _bad(tmp_path, tmp_path / "c" / jf.name, "image", "subframe_rect")


def test_filler_in_a_required_value_is_exit_2(tmp_path):
    p = pds3_product(tmp_path, "PFILL", PIX16, MODELS["CAHVOR"])
    text = p.read_bytes()
    i = text.index(b"MODEL_COMPONENT_1 = (")
    j = text.index(b")", i)
    new = b"MODEL_COMPONENT_1 = (1.0e+30,0.0,0.0"
    old = text[i:j]
    p.write_bytes(text[:i] + new.ljust(len(old), b" ") + text[j:])
    _bad(tmp_path, p, "PFILL", "GEOMETRIC_CAMERA_MODEL.MODEL_COMPONENT_1", "1e+30")


def test_a_blank_product_id_or_a_negative_exposure_is_exit_2(tmp_path):
    # ingest used to accept both and write a workspace that every later command then refused (the downlink's
    # records require a product id and an exposure >= 0)
    (tmp_path / "a").mkdir(), (tmp_path / "b").mkdir()
    p = pds3_product(tmp_path / "a", "PNEGEXP", PIX16, MODELS["CAHVOR"], exposure="-5 <ms>")
    _bad(tmp_path, p, "PNEGEXP", "EXPOSURE_DURATION", "-5")
    p = pds3_product(tmp_path / "b", "PBLANKID", PIX16, MODELS["CAHVOR"])
    text = p.read_bytes()
    old = b'PRODUCT_ID = "PBLANKID"'
    assert text.count(old) == 1
    p.write_bytes(text.replace(old, b'PRODUCT_ID = ""'.ljust(len(old), b" ")))
    _bad(tmp_path, p, "PRODUCT_ID", "blank")


def test_read_products_rejects_what_is_not_a_product(tmp_path):
    (tmp_path / "notes.txt").write_text("hello")
    with pytest.raises(InputError) as e:
        read_products(tmp_path / "notes.txt")
    assert e.value.field == "path"


def test_a_folder_says_which_files_it_did_not_read(tmp_path):
    """A picture with no label or model (real folders hold them: an MSL web JPEG beside Mars 2020 raw JSONs) and
    notes are listed as unread, by info too, instead of being dropped without a word; the files a product uses
    (a detached label's data file) are not."""
    pds3_product(tmp_path, "P1", PIX16, MODELS["CAHVOR"], detached=True)
    (tmp_path / "stray.jpg").write_bytes(b"\xff\xd8\xff\xe0not a product")
    (tmp_path / "NOTES.md").write_text("x")
    (tmp_path / ".hidden").write_text("x")
    dl = read_products(tmp_path)
    assert len(dl.images) == 1 and dl.unread_files == ["NOTES.md", "stray.jpg"]
    r = CliRunner().invoke(app, ["info", str(tmp_path), "--json"])
    assert r.exit_code == 0, r.stderr
    assert json.loads(r.stdout)["unread_files"] == ["NOTES.md", "stray.jpg"]
    assert read_products(next(tmp_path.glob("*.LBL"))).unread_files == []  # one file named: nothing else looked at
