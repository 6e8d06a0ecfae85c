"""Camera models used across the tests: realistic MER/Rocky8-like geometry, all kinds and types."""

import numpy as np

from scipctl.core.camera import CameraModel, T_model_cam, cahv_from_intrinsics
from scipctl.core.transforms import RigidTransform, axis_angle_to_matrix

WIDTH = HEIGHT = 1024

# camera frame (x right, y down, z forward) -> rover frame (x fwd, y right, z down), looking forward
_R_ROVER_CAMFWD = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])


def pose(tilt_down_rad=0.4, yaw_rad=0.1, C=(0.4, 0.1, -1.5)):
    R = axis_angle_to_matrix([0, 0, 1], yaw_rad) @ axis_angle_to_matrix([0, 1, 0], -tilt_down_rad) @ _R_ROVER_CAMFWD
    return RigidTransform(R, np.array(C, float))


def cahv(f_px=1220.0, skew_free=True, **kw):
    m = cahv_from_intrinsics(f_px, f_px * 1.003, 511.3, 514.8, pose(**kw))
    if not skew_free:
        m = CameraModel("CAHV", m.C, m.A, m.H + 0.002 * f_px * m.v_axis, m.V)
    return m


def _tilted_axis(m, ang=0.004):
    T_rover_cam = T_model_cam(m)
    o = np.array([np.sin(ang), -np.sin(ang) * 0.5, 1.0])
    return T_rover_cam.R @ (o / np.linalg.norm(o))


def cahvor(**kw):
    m = cahv(**kw)
    return CameraModel("CAHVOR", m.C, m.A, m.H, m.V, O=_tilted_axis(m), R=[0.0, -0.18, 0.06])


def cahvore(cahvore_type=3, linearity=0.37, e=(0.0005, 0.004, -0.002), f_px=476.0, **kw):
    m = cahv(f_px=f_px, **kw)
    return CameraModel(
        "CAHVORE", m.C, m.A, m.H, m.V, O=_tilted_axis(m), R=[0.0, -0.02, 0.004], E=list(e),
        cahvore_type=cahvore_type, linearity=linearity,
    )


def all_models():
    return {
        "CAHV": cahv(),
        "CAHV-skew": cahv(skew_free=False),
        "CAHVOR": cahvor(),
        "CAHVORE1": cahvore(cahvore_type=1, linearity=None, f_px=700.0, e=(0.001, 0.01, -0.005)),
        "CAHVORE2": cahvore(cahvore_type=2, linearity=None),
        "CAHVORE3": cahvore(cahvore_type=3, linearity=0.37),
        "CAHVORE3-neg": cahvore(cahvore_type=3, linearity=-0.3),
    }


def pixel_grid(n=33, margin=0.0):
    u = np.linspace(-0.5 + margin, WIDTH - 0.5 - margin, n)
    v = np.linspace(-0.5 + margin, HEIGHT - 0.5 - margin, n)
    return np.stack(np.meshgrid(u, v), axis=-1).reshape(-1, 2)


def stereo_pair(kind="CAHVOR", baseline_m=0.2, misalign_rad=0.0, **kw):
    """(left, right) models: right = left moved ``baseline_m`` along the image h axis, optionally rotated a little."""
    from scipctl.core.transforms import RigidTransform, rotvec_to_matrix

    make = {"CAHV": cahv, "CAHVOR": cahvor, "CAHVORE": cahvore}[kind]
    left = make(**kw)
    T_move = RigidTransform(np.eye(3), baseline_m * left.h_axis)
    right = left.transformed(T_move)
    if misalign_rad:
        R = rotvec_to_matrix(misalign_rad * left.h_axis)  # pitch: vertical (epipolar) offset
        T_rot = RigidTransform(R, right.C - R @ right.C)
        right = right.transformed(T_rot)
    return left, right
