"""A Mars 2020 rover configuration from JPL's static camera models and the rover URDF (``nasa-jpl/m2020-urdf-models``).

Inputs, read at run time from a folder (``../shared/real/12_m2020-urdf-models_camera_models``;
the repository keeps no copy): ``m2020-camera-models.json`` (static CAHV/CAHVOR/CAHVORE models; the
navcams in ``Body_RSM_EL``, the hazcams in ``Body_Chassis``, full 5120 x 3840 detector) and ``m2020.urdf``.

Frames: ``Body_Chassis`` is taken as the rover navigation frame (the URDF root, under a floating joint at
identity; the flight labels' RSM head origin agrees with the URDF's azimuth-joint origin to 1 mm).
The mast chain is ``Body_Chassis -[RSM_AZ_ENC, revolute]-> Body_RSM_AZ -[RSM_EL_ENC, revolute]->
Body_RSM_EL``; URDF joints are ``T_parent_child(q) = T_parent_origin(xyz, rpy) . Rot(axis, q)`` with
``R(rpy) = Rz(yaw) Ry(pitch) Rx(roll)``. So ``T_rover_head(az, el) = O1 Rz(az) O2 Ry(el)`` equals the
downlink contract's ``M = Rot(pan axis, pan) . Rot(tilt axis, tilt)`` applied to the zero-angle head
``O1 O2``, with pan = az about the line through ``O1.t`` along ``O1.R z`` and tilt = el about the line
through ``(O1 O2).t`` along ``(O1 O2).R y`` (both in the rover frame at zero angles).
"""

from __future__ import annotations

import json
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..core.camera import CameraModel, CameraModelError
from ..core.camera_subimage import subimage_model
from ..core.kinematics import CameraSpec, JointAxis, MastGeometry, RoverConfig, StereoCamera
from ..core.transforms import RigidTransform, euler_zyx_to_matrix
from ..model import InputError

MODELS_FILE = "m2020-camera-models.json"
URDF_FILE = "m2020.urdf"
ROVER_LINK = "Body_Chassis"
HEAD_LINK = "Body_RSM_EL"


@dataclass(frozen=True)
class UrdfJoint:
    name: str
    kind: str  # "revolute", "fixed", ...
    parent: str
    child: str
    T_parent_origin: RigidTransform  # the joint frame at q = 0 in the parent link
    axis: np.ndarray  # (3,), in the joint frame

    def T_parent_child(self, q_rad: float = 0.0) -> RigidTransform:
        if self.kind in ("revolute", "continuous"):
            return self.T_parent_origin @ RigidTransform.rotation_about_line(self.axis, np.zeros(3), q_rad)
        return self.T_parent_origin


def urdf_root(path):
    """The parsed root element of a URDF file; InputError naming the file when it cannot be read."""
    p = Path(path)
    try:
        return ET.parse(p).getroot()
    except (ET.ParseError, OSError) as e:
        raise InputError(p.name, "urdf", f"unreadable URDF ({e})") from None


def read_urdf_joints(path) -> dict:
    """``child link -> UrdfJoint`` for every joint of a URDF file."""
    root = urdf_root(path)
    out = {}
    for j in root.findall("joint"):
        o = j.find("origin")
        xyz = [float(x) for x in (o.get("xyz", "0 0 0") if o is not None else "0 0 0").split()]
        rpy = [float(x) for x in (o.get("rpy", "0 0 0") if o is not None else "0 0 0").split()]
        a = j.find("axis")
        axis = np.array([float(x) for x in (a.get("xyz", "1 0 0") if a is not None else "1 0 0").split()])
        T_parent_origin = RigidTransform(euler_zyx_to_matrix(rpy[2], rpy[1], rpy[0]), np.array(xyz))
        child, parent = j.find("child").get("link"), j.find("parent").get("link")
        out[child] = UrdfJoint(j.get("name"), j.get("type"), parent, child, T_parent_origin, axis / np.linalg.norm(axis))
    return out


def chain(joints: dict, base: str, tip: str) -> list:
    """The joints from ``base`` to ``tip`` (in order); :class:`InputError` if ``tip`` does not hang below ``base``."""
    out, node = [], tip
    while node != base:
        if node not in joints:
            raise InputError(URDF_FILE, "joint", f"link {tip} does not hang below {base}")
        out.append(joints[node])
        node = joints[node].parent
    return out[::-1]


def head_motion_from_urdf(joints: dict) -> tuple[MastGeometry, RigidTransform]:
    """(pan/tilt geometry, ``T_rover_head`` at zero angles) from the rover -> ``Body_RSM_EL`` chain."""
    ch = chain(joints, ROVER_LINK, HEAD_LINK)
    moving = [j for j in ch if j.kind in ("revolute", "continuous")]
    if [j.name for j in moving] != ["RSM_AZ_ENC", "RSM_EL_ENC"]:
        raise InputError(URDF_FILE, "joint", f"expected the RSM_AZ_ENC, RSM_EL_ENC chain, got {[j.name for j in moving]}")
    T_rover_link = RigidTransform.identity()
    axes = []
    for j in ch:
        if j in moving:
            T_rover_joint = T_rover_link @ j.T_parent_origin  # the joint frame in the rover frame at zero angles
            axes.append(JointAxis(T_rover_joint.t, T_rover_joint.R @ j.axis))
        T_rover_link = T_rover_link @ j.T_parent_child(0.0)
    return MastGeometry(axes[0], axes[1]), T_rover_link


def _model(rec: dict, name: str) -> CameraModel:
    m = rec["model"]
    kind = str(m["type"]).upper()
    try:
        if kind == "CAHVORE":
            return CameraModel(kind, m["C"], m["A"], m["H"], m["V"], O=m["O"], R=m["R"], E=m["E"],
                               cahvore_type=int(m["pupilType"]), linearity=m.get("linearity"))
        if kind == "CAHVOR":
            return CameraModel(kind, m["C"], m["A"], m["H"], m["V"], O=m["O"], R=m["R"])
        return CameraModel(kind, m["C"], m["A"], m["H"], m["V"])
    except (KeyError, CameraModelError) as e:
        raise InputError(MODELS_FILE, f"{name}.model", str(e)) from None


def static_models(path) -> dict:
    """``name -> (CameraModel in its frame, frame name, width, height)`` from ``m2020-camera-models.json``."""
    p = Path(path)
    try:
        recs = json.loads(p.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as e:
        raise InputError(p.name, "json", f"unreadable camera models ({e})") from None
    return {r["name"]: (_model(r, r["name"]), r["frame"], int(r["model"]["width"]), int(r["model"]["height"]))
            for r in recs}


def m2020_rover_config(folder, navcam_scale: int = 4, hazcam_scale: int = 4, hazcam_string: str = "A",
                       pancam_zoom: str = "Z034") -> RoverConfig:
    """The Mars 2020 configuration: navcam (mast, NAVL/NAVR), hazcam (body, front HAZFL?/HAZFR?), pancam
    (mast, Mastcam-Z at ``pancam_zoom``); models in the rover frame at zero mast angles.

    ``navcam_scale``/``hazcam_scale``: on-board pixel averaging (4: 1280 x 960, as flight navcam
    products), applied with :func:`~scipctl.core.camera_subimage.subimage_model`.
    """
    folder = Path(folder)
    joints = read_urdf_joints(folder / URDF_FILE)
    mast, T_rover_head0 = head_motion_from_urdf(joints)
    models = static_models(folder / MODELS_FILE)

    def in_rover(name: str, scale: int) -> CameraSpec:
        if name not in models:
            raise InputError(MODELS_FILE, name, "no such camera in the static models")
        m, frame, w, h = models[name]
        if frame == HEAD_LINK:
            T_rover_frame = T_rover_head0
        elif frame == ROVER_LINK:
            T_rover_frame = RigidTransform.identity()
        else:
            T_rover_frame = RigidTransform.identity()
            for j in chain(joints, ROVER_LINK, frame):
                T_rover_frame = T_rover_frame @ j.T_parent_child(0.0)
        m = subimage_model(m.transformed(T_rover_frame), 0.0, 0.0, scale)
        return CameraSpec(m, w // scale, h // scale)

    cams = {
        "navcam": StereoCamera("mast", in_rover("NAVL", navcam_scale), in_rover("NAVR", navcam_scale)),
        "hazcam": StereoCamera("body", in_rover(f"HAZFL{hazcam_string}", hazcam_scale),
                               in_rover(f"HAZFR{hazcam_string}", hazcam_scale)),
        "pancam": StereoCamera("mast", in_rover(f"MCAM_Z_LEFT-{pancam_zoom}", 1),
                               in_rover(f"MCAM_Z_RIGHT-{pancam_zoom}", 1)),
    }
    return RoverConfig("m2020 (nasa-jpl/m2020-urdf-models static models + URDF)", mast, cams)


WHEEL_LINKS = ("Body_WheelLeftFront", "Body_WheelRightFront", "Body_WheelLeftMiddle", "Body_WheelRightMiddle",
               "Body_WheelLeftRear", "Body_WheelRightRear")


def wheels_xy_from_urdf(joints: dict) -> np.ndarray:
    """Rover-frame (x, y) ``(6, 2)`` metres of the six wheel hubs at zero joint angles (the contact points lie under
    them); :class:`InputError` if the URDF lacks a wheel link."""
    out = []
    for link in WHEEL_LINKS:
        T_rover_wheel = RigidTransform.identity()
        for j in chain(joints, ROVER_LINK, link):
            T_rover_wheel = T_rover_wheel @ j.T_parent_child(0.0)
        out.append(T_rover_wheel.t[:2])
    return np.array(out)


def m2020_rover_files(folder, **config_kwargs) -> tuple:
    """What the simulator's Mars 2020 rover is made of, read from ``folder``: ``(config, wheels_xy_m, inputs,
    notes)`` -- the configuration of :func:`m2020_rover_config`, the URDF's wheel hubs ``(6, 2)`` m, the SHA-256 of
    the two files read (``((name, sha256), ...)``) and notes on the choices made. :class:`InputError` if a file
    is missing. :func:`scipctl.sim.rover.sim_rover_from_config` makes the :class:`~scipctl.sim.rover.SimRover`."""
    from .provenance import sha256_file

    folder = Path(folder)
    for name in (MODELS_FILE, URDF_FILE):
        if not (folder / name).is_file():
            raise InputError(str(folder), name, "missing (the Mars 2020 static camera models and URDF folder)")
    config = m2020_rover_config(folder, **config_kwargs)
    wheels = wheels_xy_from_urdf(read_urdf_joints(folder / URDF_FILE))
    inputs = tuple((name, sha256_file(folder / name)) for name in (MODELS_FILE, URDF_FILE))
    notes = ("pancam is Mastcam-Z (MCAM_Z_LEFT/RIGHT at zoom " + config_kwargs.get("pancam_zoom", "Z034")
             + "): Mars 2020 has no pancam; Mastcam-Z rides the same RSM head",
             "navcam/hazcam: NAVL/NAVR and front HAZFL/HAZFR string A, 4x pixel averaging (1280 x 960)")
    return config, wheels, inputs, notes
