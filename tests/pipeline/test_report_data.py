"""pipeline/report_data.py: the gain and saturation table judges 12-bit data against 12 bits."""

import numpy as np
import pytest

from scipctl.io.images import encode_png
from scipctl.pipeline.report_data import image_stats
from tests.io.builders import make_small_downlink


def test_twelve_bit_data_is_not_called_dark():
    """Real MSL navcam products hold 12-bit data in 16-bit words: judged against 65535 they read as dark and flat
    (p99 0.03, "dark 58%; low contrast"), and saturation (4095) could never show."""
    dl = make_small_downlink(width=160, height=120)
    rng = np.random.default_rng(0)
    for i, im in enumerate(dl.images):
        px = rng.integers(800, 3000, (im.height, im.width)).astype(np.uint16)
        if i == 0:
            px[:60] = 4095  # half the image at the 12-bit ceiling
        im.png, im._pixels = encode_png(px), None
    stats = {s["product_id"]: s for s in image_stats(dl)}
    first = stats[dl.images[0].product_id]
    assert first["bits"] == 12 and first["saturated_fraction"] == 0.5 and "saturated 50.0%" in first["flags"]
    rest = [stats[im.product_id] for im in dl.images[1:]]
    assert all(s["bits"] == 12 and s["p99"] > 0.7 and not any("dark" in f or "contrast" in f for f in s["flags"])
               for s in rest)


def test_the_calibration_health_epipolar_offset_has_point_stereos_sign():
    """The report's offsets "from marks" and point stereo's (designate's) must be one quantity: on the same pair
    the report gave +0.28 px where point stereo gave -0.32 px (its curve runs far -> near, decreasing u, and the
    report did not orient it). Point stereo's own match, fed to the report's function, gives its offset back."""
    from scipctl.core.point_stereo import point_stereo
    from scipctl.pipeline.report_data import _epipolar_offset
    from tests.pipeline import scene as S

    _, dl = S.cached("slab")
    n = 0
    for cam in ("pancam", "navcam"):
        left, right = dl.product(f"{cam}_left_1_0"), dl.product(f"{cam}_right_1_0")
        for t in dl.targets:
            mk = t.mark_in(left.product_id)
            if mk is None:
                continue
            # the right image one row low, as a vertically misaligned pair: the match sits ~1 px off its curve
            R = np.roll(right.pixels_float(), 1, axis=0)
            ps = point_stereo(left.pixels_float(), R, left.camera_model, right.camera_model, [mk.u, mk.v])
            assert ps.ok and abs(ps.epipolar_offset_px) > 0.5
            got = _epipolar_offset(left.camera_model, right.camera_model, [mk.u, mk.v], ps.uv_right)
            # the same point and the same curve: equal but for the polylines' sampling (both use epipolar_curve)
            assert got == pytest.approx(ps.epipolar_offset_px, abs=0.02), (cam, t.id)
            n += 1
    assert n >= 3


def _mast_bias_case(rc, true_rc):
    """A downlink at one rover position: the navcam pair pointed at a patch of ground the left hazcam sees, three
    targets on it marked where ``true_rc``'s models see them, the products carrying ``rc``'s (the calibration)."""
    from scipctl.core.kinematics import RoverPose
    from scipctl.core.transforms import RigidTransform
    from scipctl.model import Downlink, ImageProduct, Mark, MastAngles, TargetMarks

    haz = rc.camera_model("hazcam", "left")
    centre = haz.C + (-haz.C[2] / haz.A[2]) * haz.A  # the hazcam's boresight on the ground (rover z = 0)
    points = [centre + d for d in ([0.15, 0.0, 0.0], [-0.1, 0.15, 0.0], [0.0, -0.15, 0.0])]
    pan, tilt = rc.point_at("navcam", centre)
    pose = RoverPose(RigidTransform.identity())
    images, marks = [], {i: [] for i in range(len(points))}
    for cam, eye, mast in (("navcam", "left", (pan, tilt)), ("navcam", "right", (pan, tilt)), ("hazcam", "left", None)):
        spec = rc.spec(cam, eye)
        pid = f"{cam}-{eye}"
        images.append(ImageProduct(pid, cam, eye, 0.0 if eye == "left" else 0.1, 1, 0, pose,
                                   rc.camera_model(cam, eye, *(mast or (0.0, 0.0))), spec.width, spec.height, b"",
                                   MastAngles(*mast) if mast else None))
        true_model = true_rc.camera_model(cam, eye, *(mast or (0.0, 0.0)))
        for i, X in enumerate(points):
            u, v = true_model.project(X[None])[0]
            assert 0 <= u < spec.width and 0 <= v < spec.height, (cam, eye, u, v)
            marks[i].append(Mark(pid, float(u), float(v)))
    return Downlink("test", 1, rc, images, [TargetMarks(f"t{i}", marks=m) for i, m in marks.items()])


@pytest.mark.parametrize("rover", ["default", "m2020"])
def test_the_mast_bias_estimate_is_the_injected_pan_and_tilt_offsets(rover):
    """With exact marks and the simulator's true geometry holding only mast encoder offsets, the report's estimate
    is those offsets, on the default rover and on Mars 2020's head (whose zero pose looks straight down): its pan
    on an M2020 downlink, ~3x the injected offset, is the tilt-axis error and head offset it absorbs (docs/report.md,
    "What the pan estimate holds"), not a wrong axis or sign."""
    import math
    from dataclasses import replace

    from scipctl.pipeline.report_data import mast_bias
    from scipctl.sim.errors import ErrorSettings, true_rover_config
    from scipctl.sim.rover import default_rover_config

    if rover == "m2020":
        from scipctl.io.m2020_geometry import m2020_rover_config
        from tests.io.real_data import real

        rc = m2020_rover_config(real("12_"))
    else:
        rc = default_rover_config()
    e = replace(ErrorSettings.none(), mast_pan_offset_rad=math.radians(0.2), mast_tilt_offset_rad=math.radians(-1.0))
    mb = mast_bias(_mast_bias_case(rc, true_rover_config(rc, e)))
    assert mb["cases"] == 3 and mb["rms_before_px"] > 5.0
    assert math.degrees(mb["dpan_rad"]) == pytest.approx(0.2, abs=1e-6)
    assert math.degrees(mb["dtilt_rad"]) == pytest.approx(-1.0, abs=1e-6)
    assert mb["rms_after_px"] < 1e-4


def test_the_report_s_chains_share_the_downlink_s_setups_and_keypoints(monkeypatch):
    """The report's chains (one per target) share what run_chain computes once per downlink (the hazcam handoffs'
    setups, each image's keypoints), as simulate-handoff --chain does: the same answers (tests/pipeline/test_chain.py
    shows it for the keypoints; /work/scratch/s59/ana/shared_chain_check.py: 20 chains of four downlinks equal,
    value for value, shared or alone) for ~30 % less CPU."""
    from pathlib import Path

    import scipctl.pipeline.chain as chain_mod
    from scipctl.io.downlink import read_downlink
    from scipctl.pipeline.report_data import ReportParams, collect

    calls = []

    def recording(dl, start, uv, target_id=None, setups=None, feature_cache=None, **kw):
        calls.append((target_id, setups, feature_cache))
        return []

    monkeypatch.setattr(chain_mod, "run_chain", recording)
    dl = read_downlink(Path(__file__).resolve().parents[2] / "sample_sols/mcap/paper-s1-straight.mcap")
    collect(dl, None, None, ReportParams(run_handoff=False, run_prediction=False, calib_points_per_pair=0))
    assert sorted(t for t, _, _ in calls) == ["t1", "t2", "t3"]
    assert all(isinstance(s, dict) and isinstance(f, dict) for _, s, f in calls)
    assert len({id(s) for _, s, _ in calls}) == 1 and len({id(f) for _, _, f in calls}) == 1
