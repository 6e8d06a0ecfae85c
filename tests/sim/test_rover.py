"""The simulated rover's cameras and mast conventions."""

import numpy as np
import pytest

from scipctl.sim.rover import default_rover_config, describe, scale_model, scale_rover_config


def test_cameras_like_mer_and_rocky8():
    cfg = default_rover_config()
    d = describe(cfg)
    spec = {"pancam": (16.0, 0.28, 0.30, "CAHVOR"), "navcam": (45.0, 0.82, 0.20, "CAHVOR"),
            "hazcam": (124.0, 2.1, 0.10, "CAHVORE")}
    for cam, (fov_deg, ifov_mrad, baseline_m, kind) in spec.items():
        for eye in ("left", "right"):
            e = d[f"{cam}/{eye}"]
            assert e["kind"] == kind and e["width"] == e["height"] == 1024
            assert e["ifov_mrad"][0] == pytest.approx(ifov_mrad, rel=0.01)
            assert e["fov_deg"][0] == pytest.approx(fov_deg, rel=0.03)
        C = [cfg.spec(cam, e).model.C for e in ("left", "right")]
        assert np.linalg.norm(C[1] - C[0]) == pytest.approx(baseline_m, abs=1e-9)
        assert C[1][1] > C[0][1]  # right eye to the right (+y)
    haz = cfg.spec("hazcam", "left").model
    assert haz.cahvore_type == 3 and 0.3 <= haz.linearity <= 0.5 and not haz.is_central
    assert haz.C[2] == pytest.approx(-0.5)
    assert np.degrees(np.arcsin(haz.A[2])) == pytest.approx(45.0)  # looking 45 deg down (+z is down)
    for cam in ("pancam", "navcam"):
        assert cfg.cameras[cam].mount == "mast"
        assert -1.55 <= cfg.spec(cam, "left").model.C[2] <= -1.45
    assert cfg.cameras["hazcam"].mount == "body"


def test_mast_sign_conventions():
    """pan > 0 turns right (towards +y); tilt > 0 raises the boresight (towards -z, up)."""
    cfg = default_rover_config()
    A0 = cfg.camera_model("navcam", "left").A
    assert np.allclose(A0, [1, 0, 0])
    assert cfg.camera_model("navcam", "left", pan_rad=0.3).A[1] > 0.25
    assert cfg.camera_model("navcam", "left", tilt_rad=0.3).A[2] < -0.25
    # pointing at a point right and below gives pan > 0, tilt < 0, and centres it
    target = np.array([3.0, 1.0, 0.0])
    for cam in ("pancam", "navcam"):
        pan, tilt = cfg.point_at(cam, target)
        assert pan > 0 and tilt < 0
        uv = cfg.camera_model(cam, "left", pan, tilt).project(target[None])[0]
        assert np.allclose(uv, [511.5, 511.5], atol=1e-6)


@pytest.mark.parametrize("scale", [0.125, 0.5, 2.0])
def test_scaled_models_resample_the_image(scale):
    cfg = default_rover_config()
    rng = np.random.default_rng(0)
    for cam in ("pancam", "navcam", "hazcam"):
        m = cfg.spec(cam, "left").model
        ms = scale_model(m, scale)
        uv = rng.uniform(0, 1023, (50, 2))
        o, d = m.unproject(uv)
        X = o + 2.0 * d
        assert np.allclose(ms.project(X), scale * (uv + 0.5) - 0.5, atol=1e-8)
    small = scale_rover_config(cfg, 0.125)
    assert small.spec("navcam", "right").width == 128
    with pytest.raises(ValueError):
        scale_rover_config(cfg, 0.3)
