"""Mars 2020 rover configuration from the real static models + URDF (issue #16 part 4)."""

import shutil

import numpy as np

from scipctl.core.mast_fit import fit_mast_angles, pointing_residual
from scipctl.io.downlink import read_downlink
from scipctl.io.m2020_geometry import m2020_rover_config, static_models
from tests.io.real_data import real


def test_zero_angle_config_keeps_the_static_models_and_the_urdf_axes():
    folder = real("12_")
    rc = m2020_rover_config(folder)
    static = static_models(folder / "m2020-camera-models.json")
    # hazcams are in Body_Chassis = the rover frame: C and A unchanged; 4x averaging divides the size
    haz, _, w, h = static["HAZFLA"]
    spec = rc.spec("hazcam", "left")
    assert np.array_equal(spec.model.C, haz.C) and np.array_equal(spec.model.A, haz.A)
    assert (spec.width, spec.height) == (w // 4, h // 4)
    assert abs(spec.model.hs - haz.hs / 4) < 1e-9 * haz.hs
    # the navcam stereo baseline survives the chain (static models: 0.424 m)
    nl, nr = rc.spec("navcam", "left").model, rc.spec("navcam", "right").model
    assert abs(np.linalg.norm(nl.C - nr.C) - np.linalg.norm(static["NAVL"][0].C - static["NAVR"][0].C)) < 1e-12
    assert np.allclose(rc.mast.pan.axis, [0, 0, 1])  # azimuth about the rover's vertical


def test_urdf_and_fitted_mast_angles_reproduce_the_pointed_navcam_models():
    """Fit (pan, tilt) to each pointed model of 07_*; the 5 constraints leave C to mm and A to a fraction of a mrad."""
    rc = m2020_rover_config(real("12_"))
    dl = read_downlink(real("07_"))
    assert len(dl.images) == 2
    for im in dl.images:
        pan, tilt = fit_mast_angles(rc, "navcam", im.eye, im.camera_model)
        dC, dA = pointing_residual(rc, "navcam", im.eye, pan, tilt, im.camera_model)
        # the JSON prints C to 1e-6 m and A to 1e-6: residuals far above the printing, below 2 mm / 0.5 mrad
        assert dC < 2e-3, (im.product_id, dC)
        assert dA < 0.5e-3, (im.product_id, dA)


def test_pointing_the_navcam_gives_the_real_products_head_pose():
    """``point_at`` a point on each real product's line of sight, at its pixel there, finds the joint angles
    fitted to that product (two head poses centre a point; the other is ~pi away, upside down and beyond the
    URDF's elevation limit): within 5 mrad, against the fit's 0.6-1.8 mm / 0.2 mrad residuals above."""
    rc = m2020_rover_config(real("12_"))
    for im in read_downlink(real("07_")).images:
        pan_fit, tilt_fit = fit_mast_angles(rc, "navcam", im.eye, im.camera_model)
        m = im.camera_model
        X = m.C + 6.0 * m.A  # 6 m along the boresight, below the horizon
        # the same point's pixel in the config's model at the fitted angles, scaled to the config's image size
        uv = rc.camera_model("navcam", im.eye, pan_fit, tilt_fit).project(X[None])[0]
        pan, tilt = rc.point_at("navcam", X, eye=im.eye, pixel_uv=tuple(uv))
        d_pan = (pan - pan_fit + np.pi) % (2 * np.pi) - np.pi
        assert abs(d_pan) < 5e-3 and abs(tilt - tilt_fit) < 5e-3, (im.product_id, pan, tilt, pan_fit, tilt_fit)
        assert 0.0 <= tilt <= 3.1765  # RSM_EL_ENC's limits in m2020.urdf
        assert rc.camera_model("navcam", im.eye, pan, tilt).v_axis[2] > 0.0  # upright


def test_measured_rsm_angles_of_a_pds4_label_point_the_navcam(tmp_path):
    """With the label's own measured RSM angles (no fit), the URDF chain lands within 3 mm and 2 mrad of the
    label's pointed model (the flight model comes from a temperature-interpolated calibration)."""
    xml = sorted(real("11_").glob("*.xml"))[0]
    shutil.copy(xml, tmp_path / xml.name)
    text = xml.read_text()
    data_name = text.split("<file_name>")[1].split("<")[0]
    (tmp_path / data_name).write_bytes(b"\0" * 46656 + bytes(3 * 976 * 1296))
    im = read_downlink(tmp_path / xml.name).images[0]
    rc = m2020_rover_config(real("12_"))
    dC, dA = pointing_residual(rc, "navcam", "left", im.mast.pan_rad, im.mast.tilt_rad, im.camera_model)
    assert dC < 3e-3 and dA < 2e-3, (dC, dA)
    pan, tilt = fit_mast_angles(rc, "navcam", "left", im.camera_model)
    assert abs(pan - ((im.mast.pan_rad + np.pi) % (2 * np.pi) - np.pi)) < 5e-3 and abs(tilt - im.mast.tilt_rad) < 5e-3
