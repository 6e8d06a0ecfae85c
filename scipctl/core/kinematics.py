"""Rover kinematics: mast pan/tilt head, camera models at joint angles, pointing, rover poses.

Frames (docs/conventions.md): rover frame +x forward, +y right, +z down; site
frame +x north, +y east, +z down. A rover pose is ``T_site_rover``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Optional

import numpy as np

from .camera import CameraModel
from .transforms import RigidTransform, matrix_to_euler_zyx


@dataclass(frozen=True)
class JointAxis:
    """A revolute joint: rotation about the line through ``origin_m`` along unit ``axis`` (rover frame at zero angles)."""

    origin_m: np.ndarray
    axis: np.ndarray

    def __post_init__(self):
        o = np.asarray(self.origin_m, dtype=float).reshape(3)
        a = np.asarray(self.axis, dtype=float).reshape(3)
        if not np.all(np.isfinite(o)) or not np.all(np.isfinite(a)):
            raise ValueError("joint axis: non-finite origin or zero-length axis")
        with np.errstate(over="ignore"):
            n = np.linalg.norm(a)
        if np.isinf(n):  # huge finite components (1e308): |a| overflowed, and a / |a| would be a zero axis
            a = a / np.abs(a).max()
            n = np.linalg.norm(a)
        if not n >= 1e-9:
            raise ValueError("joint axis: non-finite origin or zero-length axis")
        object.__setattr__(self, "origin_m", o)
        object.__setattr__(self, "axis", a / n)

    def motion(self, angle_rad: float) -> RigidTransform:
        return RigidTransform.rotation_about_line(self.axis, self.origin_m, angle_rad)


@dataclass(frozen=True)
class MastGeometry:
    pan: JointAxis
    tilt: JointAxis

    def head_motion(self, pan_rad: float, tilt_rad: float) -> RigidTransform:
        """``M = Rot(pan) . Rot(tilt)``: maps head-fixed points at zero angles to their rover-frame place at (pan, tilt)."""
        return self.pan.motion(pan_rad) @ self.tilt.motion(tilt_rad)


@dataclass(frozen=True)
class CameraSpec:
    model: CameraModel  # rover frame; for mast cameras at pan = tilt = 0
    width: int
    height: int


@dataclass(frozen=True)
class StereoCamera:
    mount: str  # "mast" or "body"
    left: CameraSpec
    right: CameraSpec


@dataclass(frozen=True)
class RoverConfig:
    """The calibrated geometry from which the rover computes its camera models."""

    name: str
    mast: MastGeometry
    cameras: dict = field(default_factory=dict)  # name -> StereoCamera

    def camera_model(self, camera: str, eye: str, pan_rad: float = 0.0, tilt_rad: float = 0.0) -> CameraModel:
        """The model of ``camera``/``eye`` in the rover frame at the given joint angles."""
        if camera not in self.cameras:
            raise KeyError(f"rover_config.cameras: no camera {camera!r}")
        cam = self.cameras[camera]
        spec = getattr(cam, eye)
        if cam.mount == "mast":
            return spec.model.transformed(self.mast.head_motion(pan_rad, tilt_rad))
        return spec.model

    def spec(self, camera: str, eye: str) -> CameraSpec:
        return getattr(self.cameras[camera], eye)

    def point_at(
        self,
        camera: str,
        target_rover_m,
        eye: str = "left",
        pixel_uv: Optional[tuple[float, float]] = None,
        initial: Optional[tuple[float, float]] = None,
    ) -> tuple[float, float]:
        """(pan_rad, tilt_rad) that put ``target_rover_m`` (3,) at ``pixel_uv`` (default: image centre) of a mast camera.

        Gauss-Newton on the pixel residual with finite-difference Jacobians;
        works for any axis layout. Of the two head poses that centre a target (turned towards it, or turned half
        round and tilted over), the one whose image is upright (image down along the rover's +z): a head whose
        zero pose looks straight down (Mars 2020's RSM) otherwise reaches targets ahead upside down, beyond its
        joints' limits. Angles in [-pi, pi). Raises ``ValueError`` if it cannot converge.
        """
        cam = self.cameras[camera]
        if cam.mount != "mast":
            raise ValueError(f"{camera} is body-mounted; it cannot be pointed")
        spec = getattr(cam, eye)
        goal = np.array(pixel_uv if pixel_uv is not None else ((spec.width - 1) / 2, (spec.height - 1) / 2), float)
        X = np.asarray(target_rover_m, dtype=float).reshape(3)
        # initial guess from the pan axis geometry: azimuth/elevation of the target seen from the head
        x = self._pointing_guess(spec.model, X) if initial is None else np.array(initial, dtype=float).reshape(2)
        if not np.all(np.isfinite(x)):
            x = np.zeros(2)

        def resid(q):
            uv = self.camera_model(camera, eye, q[0], q[1]).project(X[None])[0]
            return uv - goal

        def solve(x):
            for _ in range(60):
                r = resid(x)
                if not np.all(np.isfinite(r)):  # target behind the camera from here: nudge and retry
                    x = x + np.array([0.05, -0.1])
                    continue
                if np.linalg.norm(r) < 1e-9:
                    break
                h = 1e-6
                J = np.stack([(resid(x + np.array([h, 0])) - r) / h, (resid(x + np.array([0, h])) - r) / h], axis=1)
                if not np.all(np.isfinite(J)):
                    break
                step = np.linalg.lstsq(J, -r, rcond=None)[0]
                n = np.linalg.norm(step)
                if n > 0.5:  # keep Gauss-Newton steps inside the region where it is a good model
                    step *= 0.5 / n
                x = x + step
                if n < 1e-13:
                    break
            r = resid(x)
            return x, (float(np.linalg.norm(r)) if np.all(np.isfinite(r)) else np.inf)

        x, err = solve(x)
        if err > 1e-3:  # near the singular straight-down direction the first guess can fail: try a few others
            for p0 in (0.0, np.pi / 2, -np.pi / 2, np.pi):
                for t0 in (-1.4, -0.8, 0.0):
                    x, err = solve(np.array([p0, t0]))
                    if err <= 1e-3:
                        break
                if err <= 1e-3:
                    break
        r = resid(x)
        if not np.all(np.isfinite(r)) or np.linalg.norm(r) > 1e-3:
            raise ValueError(f"cannot point {camera} at {X.tolist()} (residual {np.linalg.norm(r):.3g} px)")
        # Two head poses centre the target: the head turned one way, or turned half round and tilted over the
        # other way, which sees the same ray with the image upside down. Keep the one whose image is upright.
        if self._upright(camera, eye, x) < 0.0:
            for flipped in (np.array([x[0] + np.pi, -x[1]]), np.array([x[0] + np.pi, np.pi - x[1]])):
                y, err = solve(flipped)
                if err <= 1e-3 and self._upright(camera, eye, y) > self._upright(camera, eye, x):
                    x = y
        x = (x + np.pi) % (2 * np.pi) - np.pi
        return float(x[0]), float(x[1])

    def _upright(self, camera: str, eye: str, pan_tilt_rad: np.ndarray) -> float:
        """How upright ``camera``'s image is at these joint angles: the image's down direction (increasing ``v``)
        along the rover's down (+z); > 0 upright, < 0 upside down, ~0 looking straight down."""
        return float(self.camera_model(camera, eye, pan_tilt_rad[0], pan_tilt_rad[1]).v_axis[2])

    def _pointing_guess(self, model0: CameraModel, X: np.ndarray) -> np.ndarray:
        pan_ax = self.mast.pan.axis
        o = self.mast.tilt.origin_m
        d = X - o
        A = model0.A

        def az(v):
            # angle about the pan axis
            ref = np.cross(pan_ax, self.mast.tilt.axis)
            ref2 = np.cross(pan_ax, ref)
            return np.arctan2(np.dot(v, ref2), np.dot(v, ref))

        pan = az(d) - az(A)
        Mp = self.mast.pan.motion(pan)
        A1 = Mp.rotate(A)
        tilt_ax = Mp.rotate(self.mast.tilt.axis)
        dn = d / np.linalg.norm(d)
        # tilt angle that brings A1 to the elevation of d, about tilt_ax
        a_perp = A1 - np.dot(A1, tilt_ax) * tilt_ax
        d_perp = dn - np.dot(dn, tilt_ax) * tilt_ax
        tilt = np.arctan2(np.dot(np.cross(a_perp, d_perp), tilt_ax), np.dot(a_perp, d_perp))
        return np.array([pan, tilt])


@dataclass(frozen=True)
class RoverPose:
    """A rover pose in the site frame, ``T_site_rover``, with optional 1-sigma figures."""

    T_site_rover: RigidTransform
    source: str = "unknown"
    sigma_position_m: Optional[float] = None
    sigma_yaw_rad: Optional[float] = None

    @staticmethod
    def from_wxyz(position_m, orientation_wxyz, source="unknown", sigma_position_m=None, sigma_yaw_rad=None):
        return RoverPose(RigidTransform.from_quat_wxyz(orientation_wxyz, position_m), source, sigma_position_m, sigma_yaw_rad)

    @property
    def position_m(self) -> np.ndarray:
        return self.T_site_rover.t

    @property
    def orientation_wxyz(self) -> np.ndarray:
        return self.T_site_rover.quat_wxyz

    @property
    def yaw_pitch_roll_rad(self) -> tuple[float, float, float]:
        return matrix_to_euler_zyx(self.T_site_rover.R)


def T_roverB_roverA(pose_b: RoverPose, pose_a: RoverPose) -> RigidTransform:
    """Maps points in rover frame at pose A into rover frame at pose B: ``T_site_roverB^-1 @ T_site_roverA``."""
    return pose_b.T_site_rover.inverse() @ pose_a.T_site_rover


def model_in_other_pose(model_roverA: CameraModel, pose_a: RoverPose, pose_b: RoverPose) -> CameraModel:
    """A camera model expressed in rover frame A, re-expressed in rover frame B (e.g. far navcam into the hazcam's frame)."""
    return model_roverA.transformed(T_roverB_roverA(pose_b, pose_a))
