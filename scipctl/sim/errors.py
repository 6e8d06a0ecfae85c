"""Errors as on a real rover, injected into the simulated downlinks (pure numerics).

All settings live in :class:`ErrorSettings`; random parts are drawn from a
``numpy.random.Generator`` the scenario seeds, and every realised value is
returned for the simulation record. ``ErrorSettings.none()`` is the
error-free mode: calibrated == true geometry, exact poses, equal gains, no
vibration, no washed-out images (sensor noise stays: it is physics, not an
error; switch it off with ``sensor_noise=False``).

Mast calibration error. The true head differs from the calibrated one by
encoder offsets (true pan = commanded + ``mast_pan_offset_rad``, true tilt =
commanded + ``mast_tilt_offset_rad``), a tilt axis rotated about the pan axis
by ``mast_tilt_axis_error_rad``, and a head displaced by ``mast_head_offset_m``.
The default tilt offset is -1 deg: the head really looks 1 deg lower than the
rover believes, so targets handed off through the calibrated mast appear
*below* their predicted place in the hazcams, as in the paper's experiment.
Products carry the calibrated models; the truth carries
:func:`true_rover_config`'s.

Odometry. Wheel odometry over-reports distance by a per-run factor
(``1 + N(0, odometry_scale_sigma)``) and per leg ``N(0, odometry_scale_leg_sigma)``;
heading drifts ``N(0, heading_drift_sigma_rad_per_m)`` per metre (per run) plus
``N(0, heading_noise_sigma_rad)`` per leg and ``N(0, turn_scale_sigma)`` of each
turn in place; roll and pitch come from a tilt sensor with
``tilt_sensor_sigma_rad`` noise. Errors accumulate along the drive.

Unsynchronised stereo / mast vibration. The right eye of each mast pair is
exposed after the left one while the mast still rocks: its true model is
rotated about the head by a random rotation of size
``U(0.3, 1) * vibration_max_rad`` (1.1 mrad: up to ~4 px in pancam,
~1.3 px in navcam). Body cameras get ``vibration_body_max_rad``.

Radiometry. True responsivity per camera and eye (``responsivity``), which
auto-exposure (computed for a nominal camera) does not see, so hazcams come
out darker than navcams. ``washed_out`` lists ``(run, stop, camera)`` whose
exposure is ``washed_out_factor`` times too long (both eyes).

Stale calibration (optional). ``stale_camera``'s true geometry differs from
its calibration: baseline x ``stale_baseline_scale`` (right eye moved along
the baseline) and focal length x ``stale_focal_scale`` (both eyes). Stereo
ranges then come out scaled by ``1 / (baseline scale x focal scale)``.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field, replace
from typing import Optional

import numpy as np

from ..core.camera import CameraModel
from ..core.kinematics import CameraSpec, JointAxis, MastGeometry, RoverConfig, StereoCamera
from ..core.transforms import RigidTransform, axis_angle_to_matrix, matrix_to_euler_zyx, rotvec_to_matrix

DEG = np.pi / 180.0


def _default_responsivity() -> dict:
    return {"pancam": (1.0, 0.94), "navcam": (1.0, 1.07), "hazcam": (0.62, 0.58)}


@dataclass(frozen=True)
class ErrorSettings:
    """Error settings (see the module docstring). Angles in radians, lengths in metres."""

    mast_tilt_offset_rad: float = -1.0 * DEG
    mast_pan_offset_rad: float = 0.2 * DEG
    mast_tilt_axis_error_rad: float = 0.3 * DEG
    mast_head_offset_m: tuple = (0.003, -0.002, 0.004)
    odometry_scale_sigma: float = 0.05
    odometry_scale_leg_sigma: float = 0.02
    heading_drift_sigma_rad_per_m: float = 1.0 * DEG
    heading_noise_sigma_rad: float = 0.5 * DEG
    turn_scale_sigma: float = 0.03
    tilt_sensor_sigma_rad: float = 0.1 * DEG
    vibration_max_rad: float = 1.1e-3
    vibration_body_max_rad: float = 0.0
    pointing_noise_frac: float = 0.005
    responsivity: dict = field(default_factory=_default_responsivity)
    washed_out: tuple = ()  # ((run, stop, camera), ...)
    washed_out_factor: float = 4.0
    stale_camera: Optional[str] = None
    stale_baseline_scale: float = 1.0
    stale_focal_scale: float = 1.0
    sensor_noise: bool = True

    @staticmethod
    def none(sensor_noise: bool = True) -> "ErrorSettings":
        """No errors: calibrated == true, exact poses, equal gains, no vibration, nothing washed out."""
        return ErrorSettings(
            mast_tilt_offset_rad=0.0, mast_pan_offset_rad=0.0, mast_tilt_axis_error_rad=0.0,
            mast_head_offset_m=(0.0, 0.0, 0.0), odometry_scale_sigma=0.0, odometry_scale_leg_sigma=0.0,
            heading_drift_sigma_rad_per_m=0.0, heading_noise_sigma_rad=0.0, turn_scale_sigma=0.0,
            tilt_sensor_sigma_rad=0.0, vibration_max_rad=0.0, vibration_body_max_rad=0.0, pointing_noise_frac=0.0,
            responsivity={}, washed_out=(), stale_camera=None, sensor_noise=sensor_noise,
        )

    def scaled(self, scale: float) -> "ErrorSettings":
        """These errors with their magnitudes times ``scale`` in [0, 2]: 0 is :meth:`none` (sensor noise as here),
        1 is ``self``. Offsets, sigmas and the vibration / pointing-noise sizes scale linearly; the multiplicative
        errors scale in log space (responsivity ``r -> r ** scale``, the washed-out exposure factor ``f -> f ** scale``,
        the stale-calibration scales ``s -> s ** scale``), so 2 is the same error applied twice."""
        s = float(scale)
        if not 0.0 <= s <= 2.0:
            raise ValueError(f"error scale: want 0 .. 2, got {scale}")
        if s == 0.0:
            return ErrorSettings.none(self.sensor_noise)
        if s == 1.0:
            return self
        return replace(
            self, mast_tilt_offset_rad=s * self.mast_tilt_offset_rad, mast_pan_offset_rad=s * self.mast_pan_offset_rad,
            mast_tilt_axis_error_rad=s * self.mast_tilt_axis_error_rad,
            mast_head_offset_m=tuple(s * float(v) for v in self.mast_head_offset_m),
            odometry_scale_sigma=s * self.odometry_scale_sigma, odometry_scale_leg_sigma=s * self.odometry_scale_leg_sigma,
            heading_drift_sigma_rad_per_m=s * self.heading_drift_sigma_rad_per_m,
            heading_noise_sigma_rad=s * self.heading_noise_sigma_rad, turn_scale_sigma=s * self.turn_scale_sigma,
            tilt_sensor_sigma_rad=s * self.tilt_sensor_sigma_rad, vibration_max_rad=s * self.vibration_max_rad,
            vibration_body_max_rad=s * self.vibration_body_max_rad, pointing_noise_frac=s * self.pointing_noise_frac,
            responsivity={k: tuple(float(v) ** s for v in pair) for k, pair in self.responsivity.items()},
            washed_out_factor=float(self.washed_out_factor) ** s,
            stale_baseline_scale=float(self.stale_baseline_scale) ** s, stale_focal_scale=float(self.stale_focal_scale) ** s,
        )

    @property
    def mast_is_exact(self) -> bool:
        return (self.mast_tilt_offset_rad == 0 and self.mast_pan_offset_rad == 0 and self.mast_tilt_axis_error_rad == 0
                and not any(self.mast_head_offset_m))

    @property
    def odometry_is_exact(self) -> bool:
        return (self.odometry_scale_sigma == 0 and self.odometry_scale_leg_sigma == 0
                and self.heading_drift_sigma_rad_per_m == 0 and self.heading_noise_sigma_rad == 0
                and self.turn_scale_sigma == 0 and self.tilt_sensor_sigma_rad == 0)

    def responsivity_of(self, camera: str, eye: str) -> float:
        pair = self.responsivity.get(camera, (1.0, 1.0))
        return float(pair[0] if eye == "left" else pair[1])

    def is_washed_out(self, run: str, stop: str, camera: str) -> bool:
        return any(tuple(w) == (run, stop, camera) for w in self.washed_out)

    def to_dict(self) -> dict:
        d = asdict(self)
        d["mast_head_offset_m"] = list(self.mast_head_offset_m)
        d["responsivity"] = {k: list(v) for k, v in sorted(self.responsivity.items())}
        d["washed_out"] = [list(w) for w in self.washed_out]
        return d


# ----------------------------------------------------------------------------- mast / calibration
def _scaled_focal(model: CameraModel, s: float) -> CameraModel:
    """The model with its focal length scaled by ``s`` about the optical centre (hc, vc)."""
    A = model.A
    return replace(model, H=s * (model.H - model.hc * A) + model.hc * A, V=s * (model.V - model.vc * A) + model.vc * A)


def true_rover_config(calibrated: RoverConfig, e: ErrorSettings) -> RoverConfig:
    """The TRUE geometry of the rover whose calibration is ``calibrated``.

    For joint angles (pan, tilt) the true head motion is
    ``Rot(pan axis, pan + dp) . Rot(tilt' axis, tilt + dt)`` where ``tilt'`` is the
    tilt axis rotated about the pan axis by the axis error and displaced with the
    head. It is written in ``RoverConfig`` form (fixed axes at zero angles, models
    at zero angles) by conjugation: tilt axis ``Rot(pan, dp) tilt'``, zero-angle
    models ``Rot(pan, dp) Rot(tilt', dt) (head offset) m0``.
    """
    mast = calibrated.mast
    off = np.asarray(e.mast_head_offset_m, float)
    T_offset_nominal = RigidTransform(np.eye(3), off)
    R_ax = axis_angle_to_matrix(mast.pan.axis, e.mast_tilt_axis_error_rad)
    tilt_true = JointAxis(mast.tilt.origin_m + off, R_ax @ mast.tilt.axis)
    P_dp = mast.pan.motion(e.mast_pan_offset_rad)
    tilt_conj = JointAxis(P_dp.apply(tilt_true.origin_m), P_dp.rotate(tilt_true.axis))
    M0 = P_dp @ tilt_true.motion(e.mast_tilt_offset_rad) @ T_offset_nominal
    cams = {}
    for name, cam in calibrated.cameras.items():
        specs = []
        for eye in ("left", "right"):
            spec = getattr(cam, eye)
            m = spec.model
            if e.stale_camera == name:
                if e.stale_focal_scale != 1.0:
                    m = _scaled_focal(m, e.stale_focal_scale)
                if eye == "right" and e.stale_baseline_scale != 1.0:
                    cl = cam.left.model.C
                    m = replace(m, C=cl + e.stale_baseline_scale * (m.C - cl))
            if cam.mount == "mast":
                m = m.transformed(M0)
            specs.append(CameraSpec(m, spec.width, spec.height))
        cams[name] = StereoCamera(cam.mount, specs[0], specs[1])
    return RoverConfig(calibrated.name, MastGeometry(mast.pan, tilt_conj), cams)


def vibration(rng: np.random.Generator, max_rad: float, pivot_m) -> tuple[RigidTransform, np.ndarray]:
    """A random small rotation about ``pivot_m`` (3,) (rover frame): ``(T_vibrated_nominal, rotvec (3,))``, a motion
    in the rover frame (``model.transformed(T_vibrated_nominal)`` is the vibrated model).

    The angle is ``U(0.3, 1) * max_rad`` about a uniformly random axis; ``max_rad == 0`` gives the identity.
    """
    if max_rad <= 0:
        return RigidTransform.identity(), np.zeros(3)
    ax = rng.normal(size=3)
    ax /= np.linalg.norm(ax)
    rv = ax * rng.uniform(0.3, 1.0) * max_rad
    R = rotvec_to_matrix(rv)
    p = np.asarray(pivot_m, float)
    return RigidTransform(R, p - R @ p), rv


# ----------------------------------------------------------------------------- odometry
def rover_rotation(yaw_rad: float, up_normal_site) -> np.ndarray:
    """``R_site_rover`` ``(3, 3)`` for a rover with heading ``yaw_rad`` standing on ground with upward unit normal ``(3,)`` (site, z down)."""
    n = np.asarray(up_normal_site, float)
    n = n / np.linalg.norm(n)
    z = -n  # rover +z points down, into the ground
    h = np.array([np.cos(yaw_rad), np.sin(yaw_rad), 0.0])
    x = h - np.dot(h, z) * z
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    return np.stack([x, y, z], axis=1)


def estimate_poses(true_poses: list, path_lengths_m, turns_rad, e: ErrorSettings, rng: np.random.Generator):
    """Wheel-odometry estimates of a sequence of rover poses.

    ``true_poses``: ``T_site_rover`` per stop (``RigidTransform``); ``path_lengths_m[i]`` and ``turns_rad[i]``
    describe the drive from stop ``i-1`` to ``i`` (index 0 unused). The first estimate is exact.
    Returns ``(estimates: list[RigidTransform], record: dict)``.
    """
    n = len(true_poses)
    if len(path_lengths_m) != n or len(turns_rad) != n:
        raise ValueError("path_lengths_m and turns_rad need one entry per stop")
    if e.odometry_is_exact:
        exact = [RigidTransform(T_site_rover.R.copy(), T_site_rover.t.copy()) for T_site_rover in true_poses]
        return exact, {"exact": True, "legs": []}
    run_scale = rng.normal(0.0, e.odometry_scale_sigma)
    run_drift = rng.normal(0.0, e.heading_drift_sigma_rad_per_m)
    est = [true_poses[0]]
    yaw_est = matrix_to_euler_zyx(true_poses[0].R)[0]
    legs = []
    for i in range(1, n):
        T_site_roverprev, T_site_rover = true_poses[i - 1], true_poses[i]
        d_rover = T_site_roverprev.inverse().apply(T_site_rover.t)  # true displacement in the previous rover frame
        scale = 1.0 + run_scale + rng.normal(0.0, e.odometry_scale_leg_sigma)
        L = float(path_lengths_m[i])
        dyaw_err = run_drift * L + rng.normal(0.0, e.heading_noise_sigma_rad) + rng.normal(0.0, e.turn_scale_sigma) * abs(float(turns_rad[i]))
        yaw_p, _, _ = matrix_to_euler_zyx(T_site_roverprev.R)
        yaw_c, pitch_c, roll_c = matrix_to_euler_zyx(T_site_rover.R)
        dyaw_true = (yaw_c - yaw_p + np.pi) % (2 * np.pi) - np.pi
        # translate along the previous estimated heading, with half of this leg's heading error
        R_mid = axis_angle_to_matrix([0, 0, 1], 0.5 * dyaw_err) @ est[-1].R
        p = est[-1].t + R_mid @ (scale * d_rover)
        yaw_est = yaw_est + dyaw_true + dyaw_err
        pitch = pitch_c + rng.normal(0.0, e.tilt_sensor_sigma_rad)
        roll = roll_c + rng.normal(0.0, e.tilt_sensor_sigma_rad)
        R = (axis_angle_to_matrix([0, 0, 1], yaw_est) @ axis_angle_to_matrix([0, 1, 0], pitch)
             @ axis_angle_to_matrix([1, 0, 0], roll))
        est.append(RigidTransform(R, p))
        legs.append({"leg": i, "path_length_m": L, "distance_scale": scale, "yaw_error_added_rad": float(dyaw_err)})
    rec = {"exact": False, "run_distance_scale_error": float(run_scale), "run_heading_drift_rad_per_m": float(run_drift), "legs": legs}
    return est, rec
