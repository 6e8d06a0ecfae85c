"""The rover placed on the terrain at the planned distances and bearings (scipctl/sim/placement.py)."""

import numpy as np


def test_paper_distances_and_arc_angle(run_full_exact, run_exact):
    def cam_ground_point(sim, stop, cam):
        ps = [p for p in sim.products if p.stop == stop and p.camera == cam]
        c = np.mean([p.model_true_site.C for p in ps], axis=0)
        return c[:2]

    rock_xy = run_full_exact.scene.target_rock.centre_xy_m
    for sim in (run_full_exact, run_exact):
        d_haz = np.linalg.norm(cam_ground_point(sim, "near", "hazcam") - rock_xy)
        d_far = np.linalg.norm(cam_ground_point(sim, "far", "navcam") - rock_xy)
        d_mid = np.linalg.norm(cam_ground_point(sim, "mid", "navcam") - rock_xy)
        d_p10 = np.linalg.norm(cam_ground_point(sim, "pan10", "pancam") - rock_xy)
        assert abs(d_haz - 1.0) < 0.05 and abs(d_far - 3.0) < 0.05
        assert abs(d_mid - 4.5) < 0.1 and abs(d_p10 - 10.0) < 0.1
        # the rover faces the rock at the near stop
        near = next(p for p in sim.products if p.stop == "near")
        fwd = near.T_site_rover_true.R[:2, 0]
        to_rock = rock_xy - near.T_site_rover_true.t[:2]
        ang = np.degrees(np.arccos(fwd @ to_rock / np.linalg.norm(fwd) / np.linalg.norm(to_rock)))
        assert ang < 3.0

    def bearing(sim, stop, cam):
        v = cam_ground_point(sim, stop, cam) - rock_xy
        return np.arctan2(v[1], v[0])

    straight = np.degrees(bearing(run_full_exact, "far", "navcam") - bearing(run_full_exact, "near", "hazcam"))
    arc = np.degrees(bearing(run_exact, "far", "navcam") - bearing(run_exact, "near", "hazcam"))
    assert abs((straight + 180) % 360 - 180) < 2.0
    assert abs(abs((arc + 180) % 360 - 180) - 30.0) < 2.0
