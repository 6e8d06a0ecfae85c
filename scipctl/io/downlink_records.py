"""Downlink records (format version 1; docs/downlink-format.md) <-> :mod:`scipctl.model` objects.

Both containers (:mod:`.downlink_mcap`, :mod:`.downlink_dir`) and the product readers carry the same
plain-data records (the tables of the format document: dicts/lists as they come out of JSON or YAML); this
module converts between them and the model, with one-line :class:`InputError` ``(product or file, field,
message)`` for anything wrong. It imports no container: :mod:`.downlink` (read/write/compare) sits above it.
"""

from __future__ import annotations

import math
from typing import Callable, Optional

import numpy as np

from ..core.camera import CameraModel, CameraModelError
from ..core.kinematics import CameraSpec, JointAxis, MastGeometry, RoverConfig, RoverPose, StereoCamera
from ..core.transforms import RigidTransform, matrix_to_quat_wxyz, quat_wxyz_to_matrix
from ..errors import InputError
from ..model import (
    FORMAT_VERSION,
    ImageProduct,
    ImageTruth,
    Mark,
    MastAngles,
    TargetMarks,
    TargetTruth,
)

QUAT_NORM_TOL = 1e-3  # |‖q‖ - 1| above this is an error

# A model file resolver: (path text, product, field) -> (CameraModel, dims or None). None: not allowed here.
ModelFileResolver = Optional[Callable[[str, str, str], tuple]]

# --------------------------------------------------------------------------- quaternion hints
# RoverPose keeps a rotation matrix; converting it back to a quaternion does not
# always give numbers that reproduce the same matrix bits. So that read -> write
# -> read is exact, the reader remembers, per rotation matrix (its bytes), the
# quaternion it came from; the writer uses it when (and only when) the matrix is
# bit-identical. Any quaternion found here reproduces the matrix exactly.
_QUAT_HINTS: dict = {}
_QUAT_HINTS_MAX = 200_000


def _remember_quat(R: np.ndarray, q: list) -> None:
    if len(_QUAT_HINTS) >= _QUAT_HINTS_MAX:
        _QUAT_HINTS.clear()
    _QUAT_HINTS[np.ascontiguousarray(R).tobytes()] = q


# Joint axes likewise: JointAxis normalises the axis it is given, and normalising an already normalised
# vector again need not give the same bits; so the writer writes the axis the reader saw.
_AXIS_HINTS: dict = {}


def _remember_axis(unit: np.ndarray, given: list) -> None:
    if len(_AXIS_HINTS) >= _QUAT_HINTS_MAX:
        _AXIS_HINTS.clear()
    _AXIS_HINTS[np.ascontiguousarray(unit).tobytes()] = given


def axis_for(j: JointAxis) -> list:
    """The axis to write for ``j``: the one read for exactly this normalised axis, else ``j.axis``."""
    given = _AXIS_HINTS.get(np.ascontiguousarray(j.axis).tobytes())
    return list(given) if given is not None else _fl(j.axis)


def quat_for(T_a_b: RigidTransform) -> list:
    """Quaternion ``[w, x, y, z]`` for ``T_a_b.R`` that reproduces it exactly when it came from a read quaternion."""
    q = _QUAT_HINTS.get(np.ascontiguousarray(T_a_b.R).tobytes())
    if q is not None:
        return list(q)
    return [float(x) for x in matrix_to_quat_wxyz(T_a_b.R)]


# --------------------------------------------------------------------------- field access
def _is_num(x) -> bool:
    return isinstance(x, (int, float, np.integer, np.floating)) and not isinstance(x, (bool, np.bool_))


def _join(prefix: str, key: str) -> str:
    return f"{prefix}.{key}" if prefix else key


class Fields:
    """Typed access to one mapping of a record, raising :class:`InputError` naming ``product`` and ``prefix.key``."""

    def __init__(self, d, product: str, prefix: str = ""):
        if not isinstance(d, dict):
            raise InputError(product, prefix or "record", f"must be a mapping, got {_type_name(d)}")
        self.d, self.product, self.prefix = d, product, prefix

    def f(self, key: str) -> str:
        return _join(self.prefix, key)

    def has(self, key: str) -> bool:
        return key in self.d and self.d[key] is not None

    def err(self, key: str, message: str) -> InputError:
        return InputError(self.product, self.f(key), message)

    def req(self, key: str):
        if not self.has(key):
            raise self.err(key, "missing")
        return self.d[key]

    def str_(self, key: str, required: bool = True, default: str = "") -> str:
        if not self.has(key):
            if required:
                raise self.err(key, "missing")
            return default
        v = self.d[key]
        if not isinstance(v, str):
            raise self.err(key, f"must be a string, got {_type_name(v)} {v!r}"[:200])
        if not _is_text(v):
            raise self.err(key, f"must be Unicode text, got a lone surrogate in {v!r}"[:200])
        return v

    def float_(self, key: str, required: bool = True, default=None, min_value=None) -> Optional[float]:
        if not self.has(key):
            if required:
                raise self.err(key, "missing")
            return default
        v = self.d[key]
        if not _is_num(v):
            raise self.err(key, f"must be a number, got {_type_name(v)} {v!r}"[:200])
        try:
            v = float(v)
        except OverflowError:  # an integer such as 10**400
            raise self.err(key, "must be finite, got an integer too large for a float") from None
        if not math.isfinite(v):
            raise self.err(key, f"must be finite, got {v!r}")
        if min_value is not None and v < min_value:
            raise self.err(key, f"must be >= {min_value}, got {v!r}")
        return v

    def int_(self, key: str, required: bool = True, default=None, min_value=None) -> Optional[int]:
        if not self.has(key):
            if required:
                raise self.err(key, "missing")
            return default
        v = self.d[key]
        if isinstance(v, (float, np.floating)) and math.isfinite(v) and float(v).is_integer():
            v = int(v)  # 1.0: JSON has one number type, and JSON Schema's "integer" includes 1.0
        if isinstance(v, (bool, np.bool_)) or not isinstance(v, (int, np.integer)):
            raise self.err(key, f"must be an integer, got {_type_name(v)} {v!r}"[:200])
        v = int(v)
        if min_value is not None and v < min_value:
            raise self.err(key, f"must be >= {min_value}, got {v}")
        return v

    def vec(self, key: str, n: int, required: bool = True) -> Optional[list]:
        if not self.has(key):
            if required:
                raise self.err(key, "missing")
            return None
        v = self.d[key]
        if not isinstance(v, (list, tuple)) or len(v) != n:
            raise self.err(key, f"must be a list of {n} numbers, got {v!r}"[:200])
        out = []
        for x in v:
            if not _is_num(x):
                raise self.err(key, f"must be a list of {n} numbers, got {v!r}"[:200])
            try:
                x = float(x)
            except OverflowError:
                raise self.err(key, f"must be finite, got an integer too large for a float in {v!r}"[:200]) from None
            if not math.isfinite(x):
                raise self.err(key, f"must be finite, got {v!r}"[:200])
            out.append(x)
        return out

    def map_(self, key: str, required: bool = True) -> Optional["Fields"]:
        if not self.has(key):
            if required:
                raise self.err(key, "missing")
            return None
        return Fields(self.d[key], self.product, self.f(key))

    def list_(self, key: str, required: bool = True) -> list:
        if not self.has(key):
            if required:
                raise self.err(key, "missing")
            return []
        v = self.d[key]
        if not isinstance(v, list):
            raise self.err(key, f"must be a list, got {_type_name(v)}")
        return v


def _is_text(s: str) -> bool:
    """False for a string no UTF-8 file can hold: a lone surrogate, which JSON's ``"\\udc80"`` escape gives."""
    try:
        s.encode("utf-8")
    except UnicodeEncodeError:
        return False
    return True


def _type_name(v) -> str:
    return {dict: "mapping", list: "list", str: "string", bool: "boolean", type(None): "null"}.get(type(v), type(v).__name__)


def _f(x) -> float:
    return float(x)


def _fl(a) -> list:
    return [float(x) for x in a]


# --------------------------------------------------------------------------- records <-> objects
def pose_from_plain(fs: Fields, source_required: bool = True) -> RoverPose:
    """``{position_m, orientation_wxyz, source, sigma_position_m?, sigma_yaw_rad?}`` -> :class:`RoverPose`."""
    t = fs.vec("position_m", 3)
    q = fs.vec("orientation_wxyz", 4)
    norm = math.sqrt(sum(x * x for x in q))
    if abs(norm - 1.0) > QUAT_NORM_TOL:
        raise fs.err("orientation_wxyz", f"not a unit quaternion (norm {norm:.6g}, |norm - 1| > {QUAT_NORM_TOL:g})")
    source = fs.str_("source", required=source_required, default="truth")
    sp = fs.float_("sigma_position_m", required=False, min_value=0.0)
    sy = fs.float_("sigma_yaw_rad", required=False, min_value=0.0)
    R = quat_wxyz_to_matrix(q)
    _remember_quat(R, q)
    return RoverPose(RigidTransform(R, np.array(t)), source, sp, sy)


def pose_to_plain(p: RoverPose) -> dict:
    out = {"position_m": _fl(p.T_site_rover.t), "orientation_wxyz": quat_for(p.T_site_rover), "source": str(p.source)}
    if p.sigma_position_m is not None:
        out["sigma_position_m"] = _f(p.sigma_position_m)
    if p.sigma_yaw_rad is not None:
        out["sigma_yaw_rad"] = _f(p.sigma_yaw_rad)
    return out


def _cm_message(e: CameraModelError) -> str:
    s, prefix = str(e), f"{e.field}: "
    return s[len(prefix):] if s.startswith(prefix) else s


def camera_model_from_plain(fs: Fields) -> CameraModel:
    """A ``camera_model`` mapping ``{type, C, A, H, V, O, R, E, cahvore_type, linearity}`` -> :class:`CameraModel`."""
    kind = fs.str_("type").upper()
    if kind not in ("CAHV", "CAHVOR", "CAHVORE"):
        raise fs.err("type", f"unknown camera model type {fs.d['type']!r} (want CAHV, CAHVOR or CAHVORE)")
    vecs = {k: fs.vec(k, 3) for k in kind}
    mtype = lin = None
    if kind == "CAHVORE":
        mtype = fs.int_("cahvore_type")
        if mtype not in (1, 2, 3):
            raise fs.err("cahvore_type", f"must be 1, 2 or 3, got {mtype}")
        lin = fs.float_("linearity", required=(mtype == 3))
        implied = {1: 1.0, 2: 0.0}.get(mtype)
        if implied is not None and lin is not None and lin != implied:
            raise fs.err("linearity", f"CAHVORE type {mtype} implies linearity {implied:g}, got {lin!r}")
    try:
        return CameraModel(kind, vecs["C"], vecs["A"], vecs["H"], vecs["V"], O=vecs.get("O"), R=vecs.get("R"),
                           E=vecs.get("E"), cahvore_type=mtype, linearity=lin)
    except CameraModelError as e:
        raise InputError(fs.product, fs.f(e.field), _cm_message(e)) from None


def camera_model_to_plain(m: CameraModel) -> dict:
    return m.to_dict()


def model_slot_from_plain(fs: Fields, resolve_file: ModelFileResolver) -> tuple[CameraModel, Optional[tuple]]:
    """Read ``camera_model`` or (directory container) ``camera_model_file`` from ``fs`` -> (model, dims from file or None)."""
    has_m, has_f = fs.has("camera_model"), fs.has("camera_model_file")
    if resolve_file is None and has_m:
        # the MCAP container knows no camera_model_file: beside a camera_model it is an extra key, ignored
        has_f = False
    if has_m and has_f:
        raise fs.err("camera_model_file", "both camera_model and camera_model_file given (give one)")
    if has_f:
        rel = fs.str_("camera_model_file")
        if resolve_file is None:
            raise fs.err("camera_model_file", "only allowed in a directory downlink (use camera_model)")
        return resolve_file(rel, fs.product, fs.f("camera_model_file"))
    return camera_model_from_plain(fs.map_("camera_model")), None


def _dims(fs: Fields) -> tuple[int, int]:
    return fs.int_("width", min_value=1), fs.int_("height", min_value=1)


def rover_config_from_plain(d, resolve_file: ModelFileResolver = None, product: str = "rover_config") -> RoverConfig:
    """The rover configuration mapping (``name``, ``mast.{pan,tilt}``, ``cameras``) -> :class:`RoverConfig`."""
    fs = Fields(d, product, "")
    name = fs.str_("name", required=False, default="")
    mast = fs.map_("mast")
    joints = {}
    for j in ("pan", "tilt"):
        jf = mast.map_(j)
        origin, axis = jf.vec("origin_m", 3), jf.vec("axis", 3)
        if math.sqrt(sum(a * a for a in axis)) < 1e-9:
            raise jf.err("axis", "zero-length axis")
        joints[j] = JointAxis(np.array(origin), np.array(axis))
        _remember_axis(joints[j].axis, axis)
    cams_fs = fs.map_("cameras")
    cameras = {}
    for cam_name in cams_fs.d:
        if not isinstance(cam_name, str) or not _is_text(cam_name):
            raise cams_fs.err(ascii(cam_name), "camera names must be strings (Unicode text)")
        cf = cams_fs.map_(cam_name)
        mount = cf.str_("mount")
        if mount not in ("mast", "body"):
            raise cf.err("mount", f"must be 'mast' or 'body', got {mount!r}")
        eyes = {}
        for eye in ("left", "right"):
            ef = cf.map_(eye)
            model, file_dims = model_slot_from_plain(ef, resolve_file)
            w, h = _dims(ef)
            if file_dims is not None and file_dims != (w, h):
                raise ef.err("camera_model_file", f"Dimensions {file_dims[0]}x{file_dims[1]} in the file differ from width x height {w}x{h}")
            eyes[eye] = CameraSpec(model, w, h)
        cameras[cam_name] = StereoCamera(mount, eyes["left"], eyes["right"])
    return RoverConfig(name, MastGeometry(joints["pan"], joints["tilt"]), cameras)


def rover_config_to_plain(rc: RoverConfig) -> dict:
    def joint(j: JointAxis):
        return {"origin_m": _fl(j.origin_m), "axis": axis_for(j)}

    def spec(s: CameraSpec):
        return {"camera_model": camera_model_to_plain(s.model), "width": int(s.width), "height": int(s.height)}

    return {
        "name": rc.name,
        "mast": {"pan": joint(rc.mast.pan), "tilt": joint(rc.mast.tilt)},
        "cameras": {n: {"mount": c.mount, "left": spec(c.left), "right": spec(c.right)} for n, c in rc.cameras.items()},
    }


def product_label(d, index: int, where: str) -> str:
    """A name for an image record in error messages: its product_id if it has a usable one."""
    if isinstance(d, dict) and isinstance(d.get("product_id"), str) and d["product_id"] and _is_text(d["product_id"]):
        return d["product_id"]
    return f"{where}[{index}]"


def product_from_plain(d, png: bytes, rover_config: Optional[RoverConfig], label: str,
                       resolve_file: ModelFileResolver = None) -> ImageProduct:
    """One image-product record (without its pixels, given as ``png``) -> :class:`ImageProduct`."""
    fs = Fields(d, label, "")
    pid = fs.str_("product_id")
    if not pid.strip():
        raise fs.err("product_id", "must not be empty")
    fs.product = pid
    camera = fs.str_("camera")
    eye = fs.str_("eye")
    if eye not in ("left", "right"):
        raise fs.err("eye", f"must be 'left' or 'right', got {eye!r}")
    time_s = fs.float_("time_s")
    pos = fs.map_("position")
    site, drive = pos.int_("site"), pos.int_("drive")
    pose = pose_from_plain(fs.map_("pose"))
    model, file_dims = model_slot_from_plain(fs, resolve_file)
    w, h = _dims(fs)
    if file_dims is not None and file_dims != (w, h):
        raise fs.err("camera_model_file", f"Dimensions {file_dims[0]}x{file_dims[1]} in the file differ from width x height {w}x{h}")
    mount = None
    if rover_config is not None and camera in rover_config.cameras:
        mount = rover_config.cameras[camera].mount
    mast = None
    if mount == "body":
        pass  # mast angles are allowed and ignored on body cameras
    elif fs.has("mast"):
        mf = fs.map_("mast")
        mast = MastAngles(mf.float_("pan_rad"), mf.float_("tilt_rad"))
    elif mount == "mast":
        raise fs.err("mast", f"missing: {camera} is a mast camera, its pan_rad/tilt_rad are required")
    exposure = fs.float_("exposure_ms", required=False, min_value=0.0)
    gain = fs.float_("gain", required=False)
    return ImageProduct(
        product_id=pid, camera=camera, eye=eye, time_s=time_s, site=site, drive=drive, pose=pose,
        camera_model=model, width=w, height=h, png=bytes(png), mast=mast, exposure_ms=exposure, gain=gain,
    )


def product_to_plain(im: ImageProduct) -> dict:
    """An image-product record without ``image`` (the container adds it)."""
    out = {
        "product_id": im.product_id,
        "camera": im.camera,
        "eye": im.eye,
        "time_s": _f(im.time_s),
        "position": {"site": int(im.site), "drive": int(im.drive)},
        "pose": pose_to_plain(im.pose),
        "camera_model": camera_model_to_plain(im.camera_model),
        "width": int(im.width),
        "height": int(im.height),
    }
    if im.mast is not None:
        out["mast"] = {"pan_rad": _f(im.mast.pan_rad), "tilt_rad": _f(im.mast.tilt_rad)}
    if im.exposure_ms is not None:
        out["exposure_ms"] = _f(im.exposure_ms)
    if im.gain is not None:
        out["gain"] = _f(im.gain)
    return out


def _nonempty_id(fs: Fields, key: str) -> str:
    """The record's id (it names the record in later errors, so it must not be blank)."""
    v = fs.str_(key)
    if not v.strip():
        raise fs.err(key, "must not be empty")
    return v


def target_from_plain(d, label: str) -> TargetMarks:
    fs = Fields(d, label, "")
    tid = _nonempty_id(fs, "id")
    fs.product = tid
    kind = fs.str_("kind", required=False)
    desc = fs.str_("description", required=False)
    marks = []
    for i, md in enumerate(fs.list_("marks", required=False)):
        mf = Fields(md, tid, f"marks[{i}]")
        sigma = mf.float_("sigma_px", required=False, default=0.0)
        if sigma < 0:
            raise mf.err("sigma_px", f"must be >= 0, got {sigma!r}")
        marks.append(Mark(mf.str_("product_id"), mf.float_("u"), mf.float_("v"), sigma))
    return TargetMarks(tid, kind, desc, marks)


def target_to_plain(t: TargetMarks) -> dict:
    return {
        "id": t.id,
        "kind": t.kind,
        "description": t.description,
        "marks": [{"product_id": m.product_id, "u": _f(m.u), "v": _f(m.v), "sigma_px": _f(m.sigma_px)} for m in t.marks],
    }


def truth_image_from_plain(d, label: str, resolve_file: ModelFileResolver = None) -> ImageTruth:
    fs = Fields(d, label, "")
    pid = _nonempty_id(fs, "product_id")
    fs.product = pid
    fs.prefix = "truth"
    pose = pose_from_plain(fs.map_("pose"), source_required=False)
    model, _ = model_slot_from_plain(fs, resolve_file)
    return ImageTruth(pid, pose, model)


def truth_image_to_plain(t: ImageTruth) -> dict:
    return {"product_id": t.product_id, "pose": pose_to_plain(t.pose), "camera_model": camera_model_to_plain(t.camera_model)}


def truth_target_from_plain(d, label: str) -> TargetTruth:
    fs = Fields(d, label, "")
    tid = _nonempty_id(fs, "id")
    fs.product = tid
    fs.prefix = "truth"
    return TargetTruth(tid, np.array(fs.vec("xyz_site_m", 3)))


def truth_target_to_plain(t: TargetTruth) -> dict:
    return {"id": t.id, "xyz_site_m": _fl(t.xyz_site_m)}


def check_format_version(value, where: str) -> str:
    v = str(value).strip() if isinstance(value, (str, int)) and not isinstance(value, bool) else None
    if v is None:
        raise InputError(where, "format_version", f"must be a string or integer, got {value!r}")
    if v != FORMAT_VERSION:
        raise InputError(where, "format_version", f"unsupported format version {v!r} (this scipctl reads {FORMAT_VERSION!r})")
    return v
