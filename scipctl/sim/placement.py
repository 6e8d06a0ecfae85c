"""Placing the simulated rover on the terrain: its true pose at a stop (pure numerics).

The wheels' ground heights are fitted by a plane (the rover's roll and pitch); a stop is then moved
until its reference cameras stand at the planned distance and bearing from the target rock.
"""

from __future__ import annotations

import numpy as np

from ..core.kinematics import RoverConfig
from ..core.transforms import RigidTransform
from . import rover as rover_mod
from .errors import rover_rotation
from .scenarios import StopPlan
from .scene import Scene

WHEELS_XY_M = rover_mod.DEFAULT_WHEELS_XY_M


def true_rover_pose(scene: Scene, xy_m, yaw_rad: float, wheels_xy_m=None) -> RigidTransform:
    """``T_site_rover`` of a rover standing on the terrain at ``xy_m`` (2,) with heading ``yaw_rad``.

    The ground heights under the wheels (``wheels_xy_m`` ``(K, 2)`` rover frame; default the default rover's) are
    fitted by a plane; the rover frame's z axis is its downward normal and the origin lies on it under the
    reference point.
    """
    wheels = WHEELS_XY_M if wheels_xy_m is None else np.asarray(wheels_xy_m, float)
    c, s = np.cos(yaw_rad), np.sin(yaw_rad)
    Rz = np.array([[c, -s], [s, c]])
    wxy = np.asarray(xy_m, float)[None, :] + wheels @ Rz.T
    h = scene.ground_height_m(wxy)
    A = np.concatenate([np.ones((len(wxy), 1)), wxy - np.asarray(xy_m)[None, :]], axis=1)
    a0, hx, hy = np.linalg.lstsq(A, h, rcond=None)[0]
    n_up = np.array([-hx, -hy, -1.0])  # site z down: the upward normal of z = -h(x, y)
    n_up /= np.linalg.norm(n_up)
    R = rover_rotation(yaw_rad, n_up)
    return RigidTransform(R, np.array([xy_m[0], xy_m[1], -a0]))


def _ref_point_xy(stop: StopPlan, T_site_rover: RigidTransform, calibrated: RoverConfig, true_cfg: RoverConfig,
                  aim_site) -> np.ndarray:
    """Site (x, y) of the middle of the stop's reference camera pair (true models; mast pointed at the aim)."""
    cam = stop.ref_camera
    pan = tilt = 0.0
    if calibrated.cameras[cam].mount == "mast":
        pan, tilt = calibrated.point_at(cam, T_site_rover.inverse().apply(aim_site))
    c = [true_cfg.camera_model(cam, eye, pan, tilt).transformed(T_site_rover).C for eye in ("left", "right")]
    return 0.5 * (c[0][:2] + c[1][:2])


def place_on_terrain(scene: Scene, stop: StopPlan, calibrated: RoverConfig, true_cfg: RoverConfig, aim_site,
                     iterations: int = 4, wheels_xy_m=None) -> RigidTransform:
    """The true ``T_site_rover`` of a stop, moved so that its reference cameras really stand ``ref_dist_m`` from
    the rock along ``bearing_rad`` (the rover's roll and pitch on the terrain move the mast head sideways).
    Updates ``stop.xy_m``."""
    want = stop.ref_dist_m * np.array([np.cos(stop.bearing_rad), np.sin(stop.bearing_rad)]) + scene.target_rock.centre_xy_m
    xy = np.array(stop.xy_m, float)
    for _ in range(iterations):
        T_site_rover = true_rover_pose(scene, xy, stop.yaw_rad, wheels_xy_m)
        xy = xy + (want - _ref_point_xy(stop, T_site_rover, calibrated, true_cfg, aim_site))
    stop.xy_m = xy
    return true_rover_pose(scene, xy, stop.yaw_rad, wheels_xy_m)
