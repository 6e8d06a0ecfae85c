"""The Mars 2020 rules file's rover-specific values are what scipctl/io/m2020_rules.py derives from the URDF and the
camera models (real products: skipped with the reason when shared/real is absent)."""

import numpy as np
import pytest
from scipy.optimize import least_squares

from scipctl.io.m2020_geometry import m2020_rover_config, read_urdf_joints
from scipctl.io.m2020_rules import (ARM_JOINTS, arm_fk, derive_m2020, ground_reach,
                                    hazcam_margin_px, urdf_joint_limits)
from scipctl.io.rules_file import BUILTIN_RULES
from scipctl.pipeline.rules import load_rules
from tests.io.real_data import real


@pytest.fixture(scope="module")
def derived():
    m2020 = load_rules("m2020").values
    return derive_m2020(real("12_"), m2020["flight_rules"]["target_keep_out_m"],
                        m2020["flight_rules"]["hazcam_fov_margin_px"])


def test_the_files_arm_workspace_and_footprint_are_the_derivation(derived):
    v = load_rules("m2020").values
    w = derived.arm_workspace
    # the derivation works on a 1 cm grid and the file gives its values: equal to the printed digits
    assert v["arm_workspace"] == {"r_min_m": w.r_min_m, "r_max_m": w.r_max_m, "half_width_m": w.half_width_m}
    b = derived.rover_body
    assert v["rover_body"] == pytest.approx({"front_m": b.front_m, "rear_m": b.rear_m,
                                             "half_width_m": b.half_width_m}, abs=5e-4)  # file: 1 mm digits
    assert v["flight_rules"]["min_standoff_m"] == w.r_min_m
    # the URDF's six hubs: a 2.26 m wheelbase and the wheel radius (hub height) of the 52.5 cm wheels
    assert np.ptp(derived.rover_body.wheels_xy_m[:, 0]) == pytest.approx(2.26, abs=1e-9)
    assert derived.rover_body.wheel_radius_m == pytest.approx(0.2629, abs=1e-4)
    # the file names the SHA-256 of the inputs it was derived from
    text = BUILTIN_RULES["m2020"].read_text()
    for name, sha in derived.inputs:
        assert sha in text, name


def test_the_hazcam_legs_are_the_default_files_carried_beyond_the_workspace_centre(derived):
    d, m = load_rules("default").values, load_rules("m2020").values
    c_default = 0.5 * (d["arm_workspace"]["r_min_m"] + d["arm_workspace"]["r_max_m"])
    c_m2020 = 0.5 * (derived.arm_workspace.r_min_m + derived.arm_workspace.r_max_m)
    want_stops = [s - c_default + c_m2020 for s in d["approach"]["hazcam_stops_m"]]
    assert list(m["approach"]["hazcam_stops_m"]) == pytest.approx(want_stops, abs=5e-3)  # file: cm digits
    assert m["approach"]["hazcam_handoff_m"] == pytest.approx(d["approach"]["hazcam_handoff_m"] - c_default + c_m2020,
                                                              abs=5e-3)
    # every planned hazcam distance and every standoff of the workspace sees the target (on the ground straight
    # ahead) inside both hazcam images by the rule's margin
    rc = m2020_rover_config(real("12_"))
    xs = [m["approach"]["hazcam_handoff_m"], *m["approach"]["hazcam_stops_m"],
          *np.arange(derived.arm_workspace.r_min_m, derived.arm_workspace.r_max_m + 1e-9, 0.05)]
    margin = hazcam_margin_px(rc, np.array([[x, 0.0, 0.0] for x in xs]))
    assert np.all(margin >= m["flight_rules"]["hazcam_fov_margin_px"]), dict(zip(xs, margin))
    assert derived.hazcam_view_x_m[0] < derived.arm_workspace.r_min_m


def _nadir_ik(joints, limits, instrument, xy, seeds, enough=1e-9):
    """Generic numerical IK (the URDF forward kinematics, no closed form): the smallest residual (m) of placing
    ``instrument`` at ground point ``xy`` with its boresight straight down, over the ``seeds`` (stops at one
    below ``enough``)."""
    lo = np.array([limits[n][0] for n in ARM_JOINTS])
    hi = np.array([limits[n][1] for n in ARM_JOINTS])

    def f(q):
        T, o = arm_fk(joints, instrument, q[None])
        below = np.maximum(o[1:, 0, 2], 0.0)  # a joint below the ground counts as a miss
        return np.concatenate([T[0, :3, 3] - [xy[0], xy[1], 0.0], T[0, :2, 0], below])

    best = np.inf
    for q0 in seeds:
        r = least_squares(f, np.clip(q0, lo + 1e-6, hi - 1e-6), bounds=(lo, hi), xtol=1e-12, ftol=1e-12)
        best = min(best, float(np.linalg.norm(r.fun)))
        if best < enough:
            break
    return best


def test_the_closed_form_reach_agrees_with_numerical_ik_on_the_urdf():
    folder = real("12_")
    joints = read_urdf_joints(folder / "m2020.urdf")
    limits = urdf_joint_limits(folder / "m2020.urdf")
    rng = np.random.default_rng(0)
    lo = np.array([limits[n][0] for n in ARM_JOINTS])
    hi = np.array([limits[n][1] for n in ARM_JOINTS])
    seeds = lo + (hi - lo) * rng.random((16, 5))
    ws = load_rules("m2020").values["arm_workspace"]
    inside = [(ws["r_min_m"], 0.0), (ws["r_max_m"], 0.0), (0.5 * (ws["r_min_m"] + ws["r_max_m"]), ws["half_width_m"]),
              (0.5 * (ws["r_min_m"] + ws["r_max_m"]), -ws["half_width_m"])]
    outside = [(3.3, 0.0), (2.9, 0.9)]  # beyond the arm's reach (measured: 3.07 m straight ahead)
    for name in ("Frame_PIXL", "Frame_DRILL"):
        reach = ground_reach(joints, limits, name)
        assert np.all(reach.contains(np.array(inside))) and not np.any(reach.contains(np.array(outside)))
        for xy in inside:
            assert _nadir_ik(joints, limits, name, xy, seeds) < 1e-6, (name, xy)
        if name == "Frame_PIXL":  # no seed reaches beyond (the closed form says why: too far from the shoulder)
            for xy in outside:
                assert _nadir_ik(joints, limits, name, xy, seeds) > 1e-2, (name, xy)


def test_an_arm_the_closed_form_does_not_fit_is_refused_not_approximated():
    import dataclasses

    from scipctl.core.transforms import RigidTransform
    from scipctl.errors import InputError

    folder = real("12_")
    joints = read_urdf_joints(folder / "m2020.urdf")
    limits = urdf_joint_limits(folder / "m2020.urdf")
    j3 = joints["Body_RA_Link3"]
    assert j3.name == "JOINT3_ENC"
    bent = dict(joints, Body_RA_Link3=dataclasses.replace(
        j3, T_parent_origin=RigidTransform(j3.T_parent_origin.R, j3.T_parent_origin.t + [0.0, 0.0, 0.05])))
    with pytest.raises(InputError) as e:
        ground_reach(bent, limits, "Frame_PIXL")
    assert e.value.field == "arm joints"
    with pytest.raises(InputError):
        ground_reach(joints, {k: v for k, v in limits.items() if k != "JOINT4_ENC"}, "Frame_PIXL")
