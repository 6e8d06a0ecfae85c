"""Rigid transforms, rotations and quaternions (pure numerics).

Naming rule (see docs/conventions.md): ``T_a_b`` maps points expressed in
frame ``b`` into frame ``a``::

    p_a = T_a_b.apply(p_b) = T_a_b.R @ p_b + T_a_b.t
    T_site_hazcam = T_site_rover @ T_rover_hazcam   # inner frames cancel

Quaternions are scalar-first ``(w, x, y, z)``, Hamilton convention, and
represent the rotation ``R`` of ``p_a = R p_b``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


def _as_vec3(x, name: str) -> np.ndarray:
    a = np.asarray(x, dtype=float)
    if a.shape != (3,):
        raise ValueError(f"{name}: expected shape (3,), got {a.shape}")
    return a


def quat_wxyz_to_matrix(q_wxyz) -> np.ndarray:
    """Unit quaternion ``(w, x, y, z)`` (shape ``(..., 4)``) -> rotation matrix ``(..., 3, 3)``.

    The quaternion is normalised first; either sign gives the same matrix.
    """
    q = np.asarray(q_wxyz, dtype=float)
    if q.shape[-1] != 4:
        raise ValueError(f"q_wxyz: expected shape (..., 4), got {q.shape}")
    n = np.linalg.norm(q, axis=-1, keepdims=True)
    if np.any(n < 1e-12) or not np.all(np.isfinite(q)):
        raise ValueError("q_wxyz: zero or non-finite quaternion")
    w, x, y, z = np.moveaxis(q / n, -1, 0)
    R = np.empty(q.shape[:-1] + (3, 3))
    R[..., 0, 0] = 1 - 2 * (y * y + z * z)
    R[..., 0, 1] = 2 * (x * y - w * z)
    R[..., 0, 2] = 2 * (x * z + w * y)
    R[..., 1, 0] = 2 * (x * y + w * z)
    R[..., 1, 1] = 1 - 2 * (x * x + z * z)
    R[..., 1, 2] = 2 * (y * z - w * x)
    R[..., 2, 0] = 2 * (x * z - w * y)
    R[..., 2, 1] = 2 * (y * z + w * x)
    R[..., 2, 2] = 1 - 2 * (x * x + y * y)
    return R


def matrix_to_quat_wxyz(R) -> np.ndarray:
    """Rotation matrix ``(3, 3)`` -> unit quaternion ``(4,)`` ``(w, x, y, z)`` with ``w >= 0``."""
    R = np.asarray(R, dtype=float)
    if R.shape != (3, 3):
        raise ValueError(f"R: expected shape (3, 3), got {R.shape}")
    tr = np.trace(R)
    if tr > 0:
        s = np.sqrt(tr + 1.0) * 2
        q = np.array([0.25 * s, (R[2, 1] - R[1, 2]) / s, (R[0, 2] - R[2, 0]) / s, (R[1, 0] - R[0, 1]) / s])
    elif R[0, 0] > R[1, 1] and R[0, 0] > R[2, 2]:
        s = np.sqrt(1.0 + R[0, 0] - R[1, 1] - R[2, 2]) * 2
        q = np.array([(R[2, 1] - R[1, 2]) / s, 0.25 * s, (R[0, 1] + R[1, 0]) / s, (R[0, 2] + R[2, 0]) / s])
    elif R[1, 1] > R[2, 2]:
        s = np.sqrt(1.0 + R[1, 1] - R[0, 0] - R[2, 2]) * 2
        q = np.array([(R[0, 2] - R[2, 0]) / s, (R[0, 1] + R[1, 0]) / s, 0.25 * s, (R[1, 2] + R[2, 1]) / s])
    else:
        s = np.sqrt(1.0 + R[2, 2] - R[0, 0] - R[1, 1]) * 2
        q = np.array([(R[1, 0] - R[0, 1]) / s, (R[0, 2] + R[2, 0]) / s, (R[1, 2] + R[2, 1]) / s, 0.25 * s])
    q /= np.linalg.norm(q)
    return q if q[0] >= 0 else -q


def axis_angle_to_matrix(axis, angle_rad: float) -> np.ndarray:
    """Rotation by ``angle_rad`` about unit ``axis`` (3,), right-hand rule -> ``(3, 3)``."""
    a = _as_vec3(axis, "axis")
    n = np.linalg.norm(a)
    if n < 1e-12:
        raise ValueError("axis: zero-length rotation axis")
    a = a / n
    K = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    return np.eye(3) + np.sin(angle_rad) * K + (1 - np.cos(angle_rad)) * (K @ K)


def rotvec_to_matrix(rotvec) -> np.ndarray:
    """Rotation vector (axis * angle, rad) ``(3,)`` -> ``(3, 3)``."""
    r = _as_vec3(rotvec, "rotvec")
    ang = np.linalg.norm(r)
    if ang < 1e-15:
        return np.eye(3)
    return axis_angle_to_matrix(r / ang, ang)


def matrix_to_rotvec(R) -> np.ndarray:
    """Rotation matrix ``(3, 3)`` -> rotation vector ``(3,)`` (rad)."""
    q = matrix_to_quat_wxyz(R)
    s = np.linalg.norm(q[1:])
    if s < 1e-15:
        return np.zeros(3)
    ang = 2 * np.arctan2(s, q[0])
    return q[1:] / s * ang


def euler_zyx_to_matrix(yaw_rad: float, pitch_rad: float, roll_rad: float) -> np.ndarray:
    """``Rz(yaw) @ Ry(pitch) @ Rx(roll)`` (aerospace yaw-pitch-roll, z down in rover/site frames)."""
    return (
        axis_angle_to_matrix([0, 0, 1], yaw_rad)
        @ axis_angle_to_matrix([0, 1, 0], pitch_rad)
        @ axis_angle_to_matrix([1, 0, 0], roll_rad)
    )


def matrix_to_euler_zyx(R) -> tuple[float, float, float]:
    """Inverse of :func:`euler_zyx_to_matrix`: ``(yaw_rad, pitch_rad, roll_rad)``."""
    R = np.asarray(R, dtype=float)
    pitch = float(np.arcsin(np.clip(-R[2, 0], -1, 1)))
    yaw = float(np.arctan2(R[1, 0], R[0, 0]))
    roll = float(np.arctan2(R[2, 1], R[2, 2]))
    return yaw, pitch, roll


@dataclass(frozen=True)
class RigidTransform:
    """``T_a_b``: ``p_a = R @ p_b + t``. ``R`` is ``(3, 3)`` orthonormal, ``t`` is ``(3,)`` metres."""

    R: np.ndarray
    t: np.ndarray

    def __post_init__(self):
        R = np.asarray(self.R, dtype=float)
        t = np.asarray(self.t, dtype=float)
        if R.shape != (3, 3):
            raise ValueError(f"R: expected shape (3, 3), got {R.shape}")
        if t.shape != (3,):
            raise ValueError(f"t: expected shape (3,), got {t.shape}")
        object.__setattr__(self, "R", R)
        object.__setattr__(self, "t", t)

    @staticmethod
    def identity() -> "RigidTransform":
        return RigidTransform(np.eye(3), np.zeros(3))

    @staticmethod
    def from_quat_wxyz(q_wxyz, t) -> "RigidTransform":
        return RigidTransform(quat_wxyz_to_matrix(q_wxyz), _as_vec3(t, "t"))

    @staticmethod
    def from_matrix(M) -> "RigidTransform":
        M = np.asarray(M, dtype=float)
        if M.shape != (4, 4):
            raise ValueError(f"M: expected shape (4, 4), got {M.shape}")
        return RigidTransform(M[:3, :3], M[:3, 3])

    @staticmethod
    def rotation_about_line(axis, origin_m, angle_rad: float) -> "RigidTransform":
        """Rotation by ``angle_rad`` about the line through ``origin_m`` along ``axis``."""
        R = axis_angle_to_matrix(axis, angle_rad)
        o = _as_vec3(origin_m, "origin_m")
        return RigidTransform(R, o - R @ o)

    @property
    def quat_wxyz(self) -> np.ndarray:
        return matrix_to_quat_wxyz(self.R)

    @property
    def matrix(self) -> np.ndarray:
        M = np.eye(4)
        M[:3, :3] = self.R
        M[:3, 3] = self.t
        return M

    def apply(self, p) -> np.ndarray:
        """Map points ``(..., 3)`` from frame b to frame a."""
        p = np.asarray(p, dtype=float)
        if p.shape[-1] != 3:
            raise ValueError(f"points: expected shape (..., 3), got {p.shape}")
        out = p @ self.R.T
        out += self.t
        return out

    def rotate(self, v) -> np.ndarray:
        """Rotate direction vectors ``(..., 3)`` (no translation)."""
        v = np.asarray(v, dtype=float)
        if v.shape[-1] != 3:
            raise ValueError(f"vectors: expected shape (..., 3), got {v.shape}")
        return v @ self.R.T

    def inverse(self) -> "RigidTransform":
        """``T_a_b.inverse() == T_b_a``."""
        Rt = self.R.T
        return RigidTransform(Rt, -Rt @ self.t)

    def __matmul__(self, other: "RigidTransform") -> "RigidTransform":
        """``T_a_b @ T_b_c == T_a_c``."""
        if not isinstance(other, RigidTransform):
            return NotImplemented
        return RigidTransform(self.R @ other.R, self.R @ other.t + self.t)

    def almost_equal(self, other: "RigidTransform", tol: float = 1e-9) -> bool:
        return bool(np.allclose(self.R, other.R, atol=tol) and np.allclose(self.t, other.t, atol=tol))

    def rotation_angle_rad(self) -> float:
        return float(np.linalg.norm(matrix_to_rotvec(self.R)))
