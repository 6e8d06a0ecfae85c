"""The simulated rover: a MER / Rocky8-like camera and mast layout (pure numerics).

Rover frame: +x forward, +y right, +z down, origin on the ground under the
rover's reference point (the middle of the wheelbase).

Mast head (pan/tilt), per ``docs/simulator.md``:

* pan axis: the vertical line through the head, along rover ``+z``
  (pointing down). Right-hand rule about ``+z`` down: **pan > 0 turns the
  cameras to the right** (towards rover ``+y``).
* tilt axis: along rover ``+y`` (pointing right) through the head.
  Right-hand rule about ``+y``: **tilt > 0 raises the boresight** (forward
  ``+x`` goes towards ``-z``, up); looking down needs tilt < 0.
* ``M = Rot(pan) · Rot(tilt)`` (tilt first), as in the downlink contract.

At pan = tilt = 0 all mast cameras look forward and level (``A = +x``), with
image ``u`` to the right (``+y``) and ``v`` down (``+z``).

Cameras (1024 x 1024):

=========  ==========  ============  ========  ===================================
camera     model       IFOV centre   baseline  place
=========  ==========  ============  ========  ===================================
pancam     CAHVOR      0.28 mrad/px  0.30 m    head, 1.52 m above ground
navcam     CAHVOR      0.82 mrad/px  0.20 m    head, 1.48 m above ground
hazcam     CAHVORE 3   2.1 mrad/px   0.10 m    body front, 0.50 m up, 45 deg down
=========  ==========  ============  ========  ===================================

Field of view: pancam 16.3 deg, navcam 45.3 deg, hazcam ~124 deg (see
:func:`describe`).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ..core.camera import CameraModel, cahv_from_intrinsics
from ..core.kinematics import CameraSpec, JointAxis, MastGeometry, RoverConfig, StereoCamera
from ..core.transforms import RigidTransform, axis_angle_to_matrix

WIDTH_PX = HEIGHT_PX = 1024

# camera frame (x right = u, y down = v, z forward = A) -> rover frame, looking forward and level
R_ROVER_CAMFWD = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])

# mast head: pan axis (vertical) and tilt axis (lateral) through the head
MAST_X_M = 0.30
PAN_ORIGIN_M = (MAST_X_M, 0.0, -1.30)
TILT_ORIGIN_M = (MAST_X_M, 0.0, -1.50)
HAZCAM_X_M = 0.62
HAZCAM_HEIGHT_M = 0.50
HAZCAM_TILT_DOWN_RAD = np.deg2rad(45.0)

PANCAM_IFOV_RAD = 0.28e-3
NAVCAM_IFOV_RAD = 0.82e-3
HAZCAM_IFOV_RAD = 2.1e-3


def _model_axis(T_rover_cam: RigidTransform, ang_x: float, ang_y: float) -> np.ndarray:
    """Optical axis O slightly off the boresight (camera-frame angles) -> (3,) in the rover frame."""
    o = np.array([np.tan(ang_x), np.tan(ang_y), 1.0])
    return T_rover_cam.R @ (o / np.linalg.norm(o))


def _cahvor(f_px, cx, cy, T_rover_cam, R, o_ang=(0.0, 0.0), aspect=1.0):
    m = cahv_from_intrinsics(f_px, f_px * aspect, cx, cy, T_rover_cam)
    return CameraModel("CAHVOR", m.C, m.A, m.H, m.V, O=_model_axis(T_rover_cam, *o_ang), R=list(R))


def _cahvore(f_px, cx, cy, T_rover_cam, R, E, linearity, o_ang=(0.0, 0.0)):
    m = cahv_from_intrinsics(f_px, f_px, cx, cy, T_rover_cam)
    return CameraModel(
        "CAHVORE", m.C, m.A, m.H, m.V, O=_model_axis(T_rover_cam, *o_ang), R=list(R), E=list(E),
        cahvore_type=3, linearity=linearity,
    )


def _mast_pose(x, y, z) -> RigidTransform:
    return RigidTransform(R_ROVER_CAMFWD, np.array([x, y, z], float))


def _hazcam_pose(y) -> RigidTransform:
    # looking forward, then pitched down by 45 deg: rotation about +y by -45 deg (right-hand rule; +tilt is up)
    R = axis_angle_to_matrix([0, 1, 0], -HAZCAM_TILT_DOWN_RAD) @ R_ROVER_CAMFWD
    return RigidTransform(R, np.array([HAZCAM_X_M, y, -HAZCAM_HEIGHT_M]))


def default_rover_config() -> RoverConfig:
    """The calibrated ``rocky8-sim`` rover: mast head with pancam and navcam pairs, front hazcam pair."""
    c = (WIDTH_PX - 1) / 2.0
    f_pan = 1.0 / PANCAM_IFOV_RAD
    f_nav = 1.0 / NAVCAM_IFOV_RAD
    f_haz = 1.0 / HAZCAM_IFOV_RAD
    pancam = StereoCamera(
        "mast",
        CameraSpec(_cahvor(f_pan, c + 3.2, c - 2.1, _mast_pose(MAST_X_M + 0.06, -0.15, -1.52), (0.0, -0.004, 0.0), (0.0008, -0.0005)), WIDTH_PX, HEIGHT_PX),
        CameraSpec(_cahvor(f_pan * 1.0012, c - 1.7, c + 2.6, _mast_pose(MAST_X_M + 0.06, 0.15, -1.52), (0.0, -0.0035, 0.0), (-0.0006, 0.0004)), WIDTH_PX, HEIGHT_PX),
    )
    navcam = StereoCamera(
        "mast",
        CameraSpec(_cahvor(f_nav, c - 4.1, c + 1.3, _mast_pose(MAST_X_M + 0.08, -0.10, -1.48), (0.0, -0.018, 0.003), (0.001, 0.0015)), WIDTH_PX, HEIGHT_PX),
        CameraSpec(_cahvor(f_nav * 0.9985, c + 2.8, c - 3.5, _mast_pose(MAST_X_M + 0.08, 0.10, -1.48), (0.0, -0.0175, 0.0028), (-0.0012, 0.001)), WIDTH_PX, HEIGHT_PX),
    )
    hazcam = StereoCamera(
        "body",
        CameraSpec(_cahvore(f_haz, c + 2.4, c - 1.9, _hazcam_pose(-0.05), (0.0, -0.046, 0.002), (0.0005, 0.004, -0.002), 0.37, (0.002, -0.001)), WIDTH_PX, HEIGHT_PX),
        CameraSpec(_cahvore(f_haz * 1.002, c - 3.0, c + 1.1, _hazcam_pose(0.05), (0.0, -0.047, 0.0021), (0.0006, 0.0038, -0.0019), 0.37, (-0.0015, 0.002)), WIDTH_PX, HEIGHT_PX),
    )
    mast = MastGeometry(pan=JointAxis(np.array(PAN_ORIGIN_M), np.array([0.0, 0.0, 1.0])),
                        tilt=JointAxis(np.array(TILT_ORIGIN_M), np.array([0.0, 1.0, 0.0])))
    return RoverConfig("rocky8-sim", mast, {"pancam": pancam, "navcam": navcam, "hazcam": hazcam})


def scale_model(model: CameraModel, scale: float) -> CameraModel:
    """The model of the same camera with its image resampled by ``scale`` (e.g. 0.125: 1024 -> 128 px).

    Pixel centres map as ``u' = scale (u + 0.5) - 0.5``, so ``H' = scale H + (scale - 1)/2 A``
    (same for ``V``); the 3-D geometry (C, A, O, R, E) is unchanged.
    """
    s = float(scale)
    if not s > 0:
        raise ValueError(f"scale: must be > 0, got {scale}")
    k = (s - 1.0) / 2.0
    return replace(model, H=s * model.H + k * model.A, V=s * model.V + k * model.A)


def scale_rover_config(config: RoverConfig, scale: float) -> RoverConfig:
    """All cameras of ``config`` resampled by ``scale`` (width and height rounded to integers, must be exact)."""
    cams = {}
    for name, cam in config.cameras.items():
        specs = []
        for spec in (cam.left, cam.right):
            w, h = spec.width * scale, spec.height * scale
            if abs(w - round(w)) > 1e-9 or abs(h - round(h)) > 1e-9:
                raise ValueError(f"scale {scale} does not give whole image sizes for {name} ({spec.width}x{spec.height})")
            specs.append(CameraSpec(scale_model(spec.model, scale), int(round(w)), int(round(h))))
        cams[name] = StereoCamera(cam.mount, specs[0], specs[1])
    return RoverConfig(config.name, config.mast, cams)


def describe(config: RoverConfig) -> dict:
    """Per camera/eye: model kind, size, IFOV at the centre (mrad/px), full FOV (deg), C in the rover frame."""
    out = {}
    for name, cam in config.cameras.items():
        for eye in ("left", "right"):
            spec = getattr(cam, eye)
            fh, fv = spec.model.field_of_view_rad(spec.width, spec.height)
            ih, iv = spec.model.ifov_rad()
            out[f"{name}/{eye}"] = {
                "kind": spec.model.kind, "width": spec.width, "height": spec.height,
                "ifov_mrad": [ih * 1e3, iv * 1e3], "fov_deg": [np.rad2deg(fh), np.rad2deg(fv)],
                "C_m": spec.model.C.tolist(),
            }
    return out


# ----------------------------------------------------------------------------- rover profiles for the scenarios
# the default rover's wheel contact points (rover frame x, y), metres: a 1 m x 1 m six-wheeler
DEFAULT_WHEELS_XY_M = np.array([[0.5, -0.45], [0.5, 0.45], [0.0, -0.5], [0.0, 0.5], [-0.5, -0.45], [-0.5, 0.45]])
# where the default rover's camera pairs stand along rover x (metres), used to place the stops
DEFAULT_MAST_REF_X_M = MAST_X_M + 0.07  # between the pancam and navcam centres
DEFAULT_NAVCAM_REF_X_M = MAST_X_M + 0.08
DEFAULT_HAZCAM_REF_X_M = HAZCAM_X_M
DEFAULT_HALF_TRACK_M = 0.5


@dataclass(frozen=True)
class SimRover:
    """What the scenarios need to know about a rover besides its camera configuration.

    ``config``: the calibrated :class:`RoverConfig` (full-size cameras, rover frame at zero mast angles);
    ``wheels_xy_m`` ``(K, 2)``: wheel contact points in the rover frame (x forward, y right), the rover's pose on
    the terrain is the plane fitted to the ground under them; ``*_ref_x_m``: rover-frame x of the camera pairs'
    centres with the mast looking forward (the first guess of where a stop stands; the stop is then moved until
    the true cameras really stand at the planned distance); ``corridor_extra_m``: added to the half width of the
    rock-free approach corridors (a wider rover needs wider corridors); ``inputs``: ``((file label, sha256), ...)``
    of the files the configuration was read from (provenance); ``key``: ``"default"`` or ``"m2020"``.
    """

    key: str
    config: RoverConfig
    wheels_xy_m: np.ndarray
    mast_ref_x_m: float
    navcam_ref_x_m: float
    hazcam_ref_x_m: float
    corridor_extra_m: float = 0.0
    inputs: tuple = ()
    notes: tuple = ()

    @property
    def is_default(self) -> bool:
        return self.key == "default"

    def to_record(self) -> dict:
        return {"key": self.key, "name": self.config.name, "wheels_xy_m": np.asarray(self.wheels_xy_m).tolist(),
                "mast_ref_x_m": self.mast_ref_x_m, "navcam_ref_x_m": self.navcam_ref_x_m,
                "hazcam_ref_x_m": self.hazcam_ref_x_m, "corridor_extra_m": self.corridor_extra_m,
                "inputs": [{"file": f, "sha256": h} for f, h in self.inputs], "notes": list(self.notes)}


def default_sim_rover() -> SimRover:
    """The ``rocky8-sim`` rover of :func:`default_rover_config` with its fixed placement constants."""
    return SimRover("default", default_rover_config(), DEFAULT_WHEELS_XY_M, DEFAULT_MAST_REF_X_M,
                    DEFAULT_NAVCAM_REF_X_M, DEFAULT_HAZCAM_REF_X_M)


def _pair_centre_forward_m(config: RoverConfig, camera: str) -> np.ndarray:
    """Rover-frame centre ``(3,)`` of a camera pair's two C vectors, mast pointed at a point 10 m ahead at head height."""
    cam = config.cameras[camera]
    pan = tilt = 0.0
    if cam.mount == "mast":
        head = np.asarray(config.mast.tilt.origin_m, float)
        pan, tilt = config.point_at(camera, head + np.array([10.0, 0.0, 0.0]))
    return 0.5 * (config.camera_model(camera, "left", pan, tilt).C + config.camera_model(camera, "right", pan, tilt).C)


def sim_rover_from_config(key: str, config: RoverConfig, wheels_xy_m, inputs: tuple = (), notes: tuple = ()) -> SimRover:
    """A :class:`SimRover` for any configuration with ``pancam``, ``navcam`` (mast) and ``hazcam`` pairs.

    The reference x of each pair is measured from the configuration (mast pointed forward); the corridors widen by
    the amount the wheels' half track exceeds the default rover's.
    """
    missing = [c for c in ("pancam", "navcam", "hazcam") if c not in config.cameras]
    if missing:
        raise ValueError(f"rover configuration {config.name!r} lacks camera(s) {', '.join(missing)}")
    wheels = np.asarray(wheels_xy_m, float).reshape(-1, 2)
    if len(wheels) < 3:
        raise ValueError("wheels_xy_m: need at least 3 wheel contact points")
    pan_c = _pair_centre_forward_m(config, "pancam")
    nav_c = _pair_centre_forward_m(config, "navcam")
    haz_c = _pair_centre_forward_m(config, "hazcam")
    extra = max(0.0, float(np.max(np.abs(wheels[:, 1]))) - DEFAULT_HALF_TRACK_M)
    return SimRover(key, config, wheels, float(0.5 * (pan_c[0] + nav_c[0])), float(nav_c[0]), float(haz_c[0]),
                    extra, tuple(inputs), tuple(notes))
