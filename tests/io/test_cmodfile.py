import json
import subprocess
from pathlib import Path

import numpy as np
import pytest

from scipctl.core.camera import CameraModel
from scipctl.io.cmodfile import format_cmod, read_cmod, write_cmod
from scipctl.model import InputError
from tests.io.builders import make_rover_config
from tests.models import all_models, cahvor, cahvore, pixel_grid

DATA = Path(__file__).resolve().parents[1] / "data" / "cmod"
MODELS = all_models()


def _bits_equal(a: CameraModel, b: CameraModel) -> bool:
    if (a.kind, a.cahvore_type) != (b.kind, b.cahvore_type):
        return False
    if a.linearity != b.linearity:
        return False
    for k in "CAHVORE":
        x, y = getattr(a, k), getattr(b, k)
        if (x is None) != (y is None) or (x is not None and x.tobytes() != y.tobytes()):
            return False
    return True


@pytest.mark.parametrize("name", sorted(MODELS))
def test_format_read_round_trip_is_bit_exact(name):
    m = MODELS[name]
    text = format_cmod(m, 1024, 768, comment="round trip\nsecond comment line")
    m2, dims = read_cmod(text)
    assert _bits_equal(m, m2), f"{name}: not bit-identical after a text round trip"
    assert dims == (1024, 768)


def test_round_trip_awkward_floats(tmp_path):
    # values whose short decimal forms are tricky: tiny, huge, negative zero, many digits
    m = MODELS["CAHVORE3"]
    m = CameraModel("CAHVORE", [1e-300, -0.0, 123456789.123456789], m.A, m.H, m.V, O=m.O,
                    R=[5e-324, -1.0000000000000002, 1e17], E=[1 / 3, 2 / 3, -7e-20], cahvore_type=3, linearity=0.1 + 0.2)
    write_cmod(tmp_path / "x.cahvore", m, 10, 20)
    m2, dims = read_cmod(tmp_path / "x.cahvore")
    assert _bits_equal(m, m2)
    assert dims == (10, 20)


def test_model_lines_follow_jpl_spelling():
    assert "Model = CAHV = perspective, linear" in format_cmod(MODELS["CAHV"])
    assert "Model = CAHVOR = perspective, distortion" in format_cmod(MODELS["CAHVOR"])
    assert "Model = CAHVORE1 = perspective, distortion, pupil" in format_cmod(MODELS["CAHVORE1"])
    assert "Model = CAHVORE2 = fish-eye" in format_cmod(MODELS["CAHVORE2"])
    assert "Model = CAHVORE3,0.37 = general" in format_cmod(MODELS["CAHVORE3"])
    assert "Dimensions" not in format_cmod(MODELS["CAHV"])


def test_derived_terms_written_and_consistent():
    m = MODELS["CAHVOR"]
    lines = dict(line.split(" = ", 1) for line in format_cmod(m, 8, 8).splitlines() if " = " in line)
    assert float(lines["Hs"]) == m.hs and float(lines["Vc"]) == m.vc
    assert float(lines["Theta"].split()[0]) == pytest.approx(-np.pi / 2, abs=1e-9)


def test_reads_jpl_layout_with_covariance_blocks():
    m, dims = read_cmod(DATA / "hazcam_left_jpl_layout.cahvore")
    ref = make_rover_config(1024, 1024).cameras["hazcam"].left.model  # the model the file was made from
    assert dims == (1024, 1024)
    assert (m.kind, m.cahvore_type, m.linearity) == ("CAHVORE", 3, 0.37)
    # the file holds 9 decimals: agreement to that precision, and the file's own derived terms agree with ours
    for k in "CAHVORE":
        assert np.allclose(getattr(m, k), getattr(ref, k), atol=5e-10, rtol=0), k
    text = (DATA / "hazcam_left_jpl_layout.cahvore").read_text()
    hs = float(text.split("Hs    =")[1].split()[0])
    # |d hs| <= |dA| |H| + |dH| with every component rounded to 5e-10
    bound = 5e-10 * np.sqrt(3) * (np.linalg.norm(ref.H) + 1) + 5e-10
    assert m.hs == pytest.approx(hs, abs=bound)
    uv = pixel_grid(5, margin=100)
    o, d = ref.unproject(uv)
    assert np.abs(m.project(o + 2.0 * d) - uv).max() < 1e-4


def test_no_model_line_infers_kind_and_tolerates_unknown_keys():
    m, dims = read_cmod(DATA / "navcam_right_no_model_line.cahvor")
    ref = make_rover_config(1024, 1024).cameras["navcam"].right.model
    assert m.kind == "CAHVOR" and dims == (1024, 1024)
    assert np.allclose(m.R, ref.R, atol=1e-12) and np.allclose(m.H, ref.H, atol=1e-9)


def test_inference_without_model_line():
    base = MODELS["CAHVORE1"]
    for keep, kind in (("CAHV", "CAHV"), ("CAHVOR", "CAHVOR"), ("CAHVORE", "CAHVORE")):
        text = "\n".join(f"{k} = " + " ".join(repr(float(x)) for x in getattr(base, k)) for k in keep)
        m, dims = read_cmod(text)
        assert m.kind == kind and dims is None
    assert m.cahvore_type == 1 and m.linearity == 1.0  # CAHVORE without a Model line: type 1 (documented)


def _text(model, **replace):
    lines = format_cmod(model, 64, 48).splitlines()
    out = []
    for line in lines:
        key = line.split(" = ", 1)[0]
        if key in replace:
            if replace[key] is not None:
                out.append(f"{key} = {replace[key]}")
        else:
            out.append(line)
    return "\n".join(out)


@pytest.mark.parametrize(
    "replace, field, fragment",
    [
        ({"A": None}, "A", "missing"),
        ({"R": None}, "R", "missing"),
        ({"H": "1 2"}, "H", "expected 3 numbers"),
        ({"V": "1 2 abc"}, "V", "not a number"),
        ({"C": "1 nan 3"}, "C", "not finite"),
        ({"A": "2 0 0"}, "A", "unit vector"),
        ({"Model": "CAHVORE3 = general"}, "Model", "linearity"),
        ({"Model": "CAHVORE7"}, "Model", "1, 2 or 3"),
        ({"Model": "PINHOLE"}, "Model", "unknown model"),
        ({"Model": "CAHV = perspective, linear"}, "O", "contradiction"),
        ({"Dimensions": "64"}, "Dimensions", "expected 2 numbers"),
        ({"Dimensions": "64.5 48"}, "Dimensions", "positive integers"),
    ],
)
def test_read_errors_name_the_field(replace, field, fragment):
    with pytest.raises(InputError) as ei:
        read_cmod(_text(MODELS["CAHVOR"], **replace), name="bad.cahvor")
    assert ei.value.product == "bad.cahvor"
    assert ei.value.field == field
    assert fragment in ei.value.message


def test_read_errors_duplicates_garbage_and_files(tmp_path):
    good = format_cmod(MODELS["CAHV"])
    with pytest.raises(InputError) as ei:
        read_cmod(good + "C = 1 2 3\n")
    assert ei.value.field == "C" and "more than once" in ei.value.message
    with pytest.raises(InputError) as ei:
        read_cmod(good + "this is not a cmod line\n")
    assert ei.value.field.startswith("line ")
    with pytest.raises(InputError) as ei:
        read_cmod(tmp_path / "missing.cahv")
    assert ei.value.field == "file" and ei.value.product.endswith("missing.cahv")
    (tmp_path / "bin.cahv").write_bytes(b"\xff\xfe\x00garbage")
    with pytest.raises(InputError):
        read_cmod(tmp_path / "bin.cahv")


def test_cahvore_type_and_linearity_contradiction():
    text = format_cmod(MODELS["CAHVORE1"]).replace("CAHVORE1 = perspective", "CAHVORE1,0.5 = perspective")
    with pytest.raises(InputError) as ei:
        read_cmod(text)
    assert ei.value.field == "Model"


# --------------------------------------------------------------------------- mrcal (independent reader)
_MRCAL_SCRIPT = r"""
import json, sys
import numpy as np
import mrcal
req = json.load(sys.stdin)
out = {}
for name, item in req.items():
    m = mrcal.cameramodel(item["path"])
    lensmodel, intr = m.intrinsics()
    p_cam = mrcal.transform_point_Rt(m.extrinsics_Rt_fromref(), np.array(item["points_ref"], float))
    uv = mrcal.project(p_cam, lensmodel, intr)
    out[name] = {"lensmodel": lensmodel, "imagersize": [int(x) for x in m.imagersize()],
                 "intrinsics": [float(x) for x in intr], "uv": uv.tolist()}
json.dump(out, sys.stdout)
"""


def _mrcal_available() -> bool:
    try:
        r = subprocess.run(["/usr/bin/python3", "-c", "import mrcal"], capture_output=True, timeout=60)
    except (OSError, subprocess.TimeoutExpired):
        return False
    return r.returncode == 0


@pytest.mark.mrcal
def test_mrcal_reads_what_we_write(tmp_path):
    if not _mrcal_available():
        pytest.skip("/usr/bin/python3 cannot import mrcal (Debian package python3-mrcal not installed)")
    base = cahvore(3, 0.37)
    central = CameraModel("CAHVORE", base.C, base.A, base.H, base.V, O=base.O, R=base.R, E=[0.0, 0.0, 0.0],
                          cahvore_type=3, linearity=0.37)
    cases = {  # name -> (model, file name, range of the test points from C in metres)
        "cahvor": (cahvor(), "navcam.cahvor", 3.0),
        "cahvore3_central": (central, "hazcam_central.cahvore", 3.0),
        # mrcal evaluates CAHVORE on the direction only (as if the point were 1 m from C), so with E != 0
        # the non-central model agrees with mrcal at 1 m
        "cahvore3": (base, "hazcam.cahvore", 1.0),
        "cahvore3_negative_linearity": (cahvore(3, -0.3), "hazcam_neg.cahvor", 1.0),
    }
    uv = pixel_grid(7, margin=40)
    req = {}
    for name, (m, fname, rng_m) in cases.items():
        write_cmod(tmp_path / fname, m, 1024, 1024)
        o, d = m.unproject(uv)
        req[name] = {"path": str(tmp_path / fname), "points_ref": (m.C + rng_m * d if rng_m == 1.0 else o + rng_m * d).tolist()}
    r = subprocess.run(["/usr/bin/python3", "-c", _MRCAL_SCRIPT], input=json.dumps(req), capture_output=True, text=True,
                       timeout=120)
    assert r.returncode == 0, r.stderr[-2000:]
    res = json.loads(r.stdout)
    for name, (m, _, _) in cases.items():
        got = res[name]
        assert got["imagersize"] == [1024, 1024], name
        fx, fy, cx, cy = got["intrinsics"][:4]
        assert (fx, fy, cx, cy) == pytest.approx((m.hs, m.vs, m.hc, m.vc), rel=1e-12), name
        if m.kind == "CAHVOR":
            assert got["lensmodel"] == "LENSMODEL_CAHVOR"
            assert got["intrinsics"][6:9] == m.R.tolist()
        else:
            assert got["lensmodel"] == f"LENSMODEL_CAHVORE_linearity={m.linearity!r}"
            assert got["intrinsics"][6:9] == m.R.tolist() and got["intrinsics"][9:12] == m.E.tolist()
        P = np.array(req[name]["points_ref"])
        ours = m.project(P)
        err = np.abs(np.array(got["uv"]) - ours).max()
        assert err < 1e-5, f"{name}: mrcal and scipctl projections differ by {err:.3g} px"


def test_cmod_file_with_a_utf8_byte_order_mark_and_crlf(tmp_path):
    """A cmod file saved by a Windows editor (UTF-8 BOM, CRLF lines) is the same text file; the BOM made the
    first line unparseable ('cannot parse ... expected key = value')."""
    model = cahvor()
    p = tmp_path / "m.cahvor"
    p.write_bytes(b"\xef\xbb\xbf" + format_cmod(model, 64, 48, comment="saved on Windows").replace("\n", "\r\n").encode())
    got, dims = read_cmod(p)
    assert _bits_equal(got, model) and dims == (64, 48)
