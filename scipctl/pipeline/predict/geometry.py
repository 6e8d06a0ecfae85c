"""Small geometry of the prediction: rover poses resting on a ground plane, their yaw and tilt, pose
perturbations and camera models of resampled images (site frame +x north, +y east, +z down)."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from ...core.camera import CameraModel
from ...core.transforms import RigidTransform, axis_angle_to_matrix, matrix_to_euler_zyx


def scaled_model(model: CameraModel, scale: float) -> CameraModel:
    """The model of the same camera with its image resampled by ``scale`` (pixel centres: ``u' = s (u + 0.5) - 0.5``)."""
    s = float(scale)
    if not s > 0:
        raise ValueError(f"scale: must be > 0, got {scale}")
    k = (s - 1.0) / 2.0
    return replace(model, H=s * model.H + k * model.A, V=s * model.V + k * model.A)


def pose_on_plane(xy_site, yaw_rad: float, plane) -> RigidTransform:
    """``T_site_rover`` for a rover at horizontal ``xy_site`` (2,) heading ``yaw_rad`` resting on ``plane``.

    ``plane = (a, b, c)``: the ground ``z = a x + b y + c`` (site frame, z down).
    The rover z axis is the plane's downward normal; its x axis is the heading
    projected onto the plane.
    """
    a, b, c = (float(v) for v in plane)
    x, y = (float(v) for v in np.asarray(xy_site, float).reshape(2))
    n = np.array([-a, -b, 1.0])
    n /= np.linalg.norm(n)  # down normal (site z is down)
    h = np.array([math.cos(yaw_rad), math.sin(yaw_rad), 0.0])
    xa = h - np.dot(h, n) * n
    xa /= np.linalg.norm(xa)
    ya = np.cross(n, xa)
    R = np.stack([xa, ya, n], axis=1)
    return RigidTransform(R, np.array([x, y, a * x + b * y + c]))


def yaw_of(T_site_rover: RigidTransform) -> float:
    return float(matrix_to_euler_zyx(T_site_rover.R)[0])


def tilt_of(T_site_rover: RigidTransform) -> float:
    """Angle (rad) between the rover's z axis and the site vertical."""
    return float(math.acos(np.clip(T_site_rover.R[2, 2], -1.0, 1.0)))


def _wrap(a):
    return (np.asarray(a, float) + np.pi) % (2 * np.pi) - np.pi


def perturb_pose(T_site_rover: RigidTransform, dxy_rover, dyaw_rad) -> list:
    """Poses ``T_site_rover @ Exp(d)`` for errors ``dxy_rover`` (N, 2) (rover frame) and ``dyaw_rad`` (N,)."""
    d = np.asarray(dxy_rover, float).reshape(-1, 2)
    y = np.asarray(dyaw_rad, float).reshape(-1)
    out = []
    for k in range(len(d)):
        D = RigidTransform(axis_angle_to_matrix([0, 0, 1], y[k]), np.array([d[k, 0], d[k, 1], 0.0]))
        out.append(T_site_rover @ D)
    return out
