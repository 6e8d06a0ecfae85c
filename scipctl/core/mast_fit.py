"""Mast joint angles that reproduce a pointed camera model (pure numerics).

Flight products give the pointed model (rover frame); the rover configuration
gives the model at zero angles and the pan/tilt axes. ``fit_mast_angles``
finds ``(pan_rad, tilt_rad)`` minimising the camera-centre distance (per mm)
and the boresight angle (per mrad) together, so both residuals are a check
of the kinematic chain (5 constraints, 2 unknowns).
"""

from __future__ import annotations

import numpy as np

from .camera import CameraModel
from .kinematics import RoverConfig

C_SCALE_M = 1e-3  # 1 mm ...
A_SCALE_RAD = 1e-3  # ... weighs like 1 mrad


def pointing_residual(config: RoverConfig, camera: str, eye: str, pan_rad: float, tilt_rad: float,
                      model_rover: CameraModel) -> tuple[float, float]:
    """(|C_config - C_model| metres, angle between the A axes radians) at the given joint angles."""
    m = config.camera_model(camera, eye, pan_rad, tilt_rad)
    dC = float(np.linalg.norm(m.C - model_rover.C))
    dA = float(np.arctan2(np.linalg.norm(np.cross(m.A, model_rover.A)), np.dot(m.A, model_rover.A)))
    return dC, dA


def fit_mast_angles(config: RoverConfig, camera: str, eye: str, model_rover: CameraModel) -> tuple[float, float]:
    """``(pan_rad, tilt_rad)`` in ``(-pi, pi]`` that best reproduce ``model_rover``'s ``C`` and ``A`` (rover frame)."""
    from scipy.optimize import least_squares

    def res(x):
        m = config.camera_model(camera, eye, x[0], x[1])
        return np.concatenate([(m.C - model_rover.C) / C_SCALE_M, (m.A - model_rover.A) / A_SCALE_RAD])

    best = None
    for p0 in np.linspace(-np.pi, np.pi, 8, endpoint=False):
        for t0 in (-1.2, 0.0, 1.2):
            r = least_squares(res, [p0, t0], xtol=1e-14, ftol=1e-14)
            if best is None or r.cost < best.cost:
                best = r
    pan, tilt = (best.x + np.pi) % (2 * np.pi) - np.pi
    return float(pan), float(tilt)
