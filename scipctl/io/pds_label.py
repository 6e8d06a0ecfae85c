"""What a PDS3 or VICAR label of a rover camera product says about its geometry (MER, MSL, Mars 2020).

The labels are parsed by the field's readers (``pdr`` for PDS3, ``rms-vicar``
for plain VICAR files, see :mod:`.pds_products`); this module turns their
key/value trees into one :class:`ProductGeometry`. It knows:

* the three spellings of the groups: attached labels
  (``GEOMETRIC_CAMERA_MODEL``, ``ROVER_COORDINATE_SYSTEM``,
  ``RSM_ARTICULATION_STATE``), detached archive labels (``..._PARMS``,
  ``ROVER_COORD_SYSTEM_PARMS``) and MSSS-camera labels
  (``ROVER_COORDINATE_SYSTEM_PARMS``, without a site index);
* namespaced keys (``MSL:MODEL_TRANSFORM_VECTOR`` reads as ``MODEL_TRANSFORM_VECTOR``);
* values with units (``3.15717 <rad>``, ``409.6 <ms>``, ``90 <deg>``) and the
  ``1e+30`` "no value" filler (absent where optional, an error where required);
* every ``*_COORDINATE_SYSTEM`` / ``*_COORD_SYSTEM_PARMS`` group as one edge of
  a :class:`~scipctl.core.frames.FrameGraph`.

Errors are :class:`~scipctl.model.InputError` ``(product, field, message)``
where ``field`` names the label group and keyword.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from typing import Any, Optional

import numpy as np

from ..core.camera import CameraModel, CameraModelError
from ..core.frames import FrameGraph, FrameRef
from ..core.transforms import RigidTransform
from ..model import InputError

FILLER_ABS = 1e29  # |value| >= this is the PDS "no value" filler (1e+30)
NO_VALUE_STRINGS = {"N/A", "NULL", "UNK", "UNKNOWN", "NONE", ""}

CAMERA_MODEL_GROUPS = ("GEOMETRIC_CAMERA_MODEL", "GEOMETRIC_CAMERA_MODEL_PARMS")
ROVER_CS_GROUPS = ("ROVER_COORDINATE_SYSTEM", "ROVER_COORD_SYSTEM_PARMS", "ROVER_COORDINATE_SYSTEM_PARMS")
MAST_STATE_GROUPS = (
    ("RSM", ("RSM_ARTICULATION_STATE", "RSM_ARTICULATION_STATE_PARMS", "RSM_ARTICULATION_ST_PARMS")),
    ("PMA", ("PMA_ARTICULATION_STATE", "PMA_ARTICULATION_STATE_PARMS", "PMA_ARTICULATION_ST_PARMS")),
)
# angle names for the measured head angles at the exposure, in order of preference
AZIMUTH_NAMES = ("AZIMUTH-MEASURED", "AZIMUTH FINAL-ENCODER", "AZIMUTH-FINAL", "AZIMUTH FINAL-RESOLVER", "AZIMUTH")
ELEVATION_NAMES = ("ELEVATION-MEASURED", "ELEVATION FINAL-ENCODER", "ELEVATION-FINAL", "ELEVATION FINAL-RESOLVER",
                   "ELEVATION")
_CS_GROUP_RE = re.compile(r"^[A-Z0-9_]*(COORDINATE_SYSTEM|COORD_SYSTEM)(_PARMS)?$")
_ANGLE_UNITS_RAD = {"RAD": 1.0, "RADIAN": 1.0, "RADIANS": 1.0, "DEG": math.pi / 180.0, "DEGREE": math.pi / 180.0,
                    "DEGREES": math.pi / 180.0}
_TIME_UNITS_MS = {"MS": 1.0, "MSEC": 1.0, "MILLISECOND": 1.0, "S": 1000.0, "SEC": 1000.0, "SECOND": 1000.0}


@dataclass(frozen=True)
class Quantity:
    """A label value with its unit (``3.15717 <rad>``)."""

    value: Any
    unit: str


@dataclass
class MastState:
    device: str  # "RSM" (MSL, M2020) or "PMA" (MER)
    azimuth_rad: float
    elevation_rad: float
    angles_rad: dict = field(default_factory=dict)  # every named angle of the group


@dataclass
class ProductGeometry:
    """Everything a downlink needs from one product label, as the label states it.

    ``model`` is in ``model_frame``; ``frames`` holds every coordinate system
    the label defines (``T_reference_frame`` edges). ``width``/``height`` are
    the image object's samples/lines.
    """

    product_id: str
    label_flavour: str  # "PDS3", "VICAR", "PDS4", "M2020-JSON"
    mission: str
    instrument_id: str
    frame_id: str  # "LEFT" / "RIGHT" / "" (eye as the label says it)
    sclk_s: Optional[float]
    sol: Optional[int]
    width: Optional[int]
    height: Optional[int]
    bands: int
    sample_bits: Optional[int]
    model: Optional[CameraModel]
    model_frame: Optional[FrameRef]
    rover_frame: Optional[FrameRef]
    rover_reference: Optional[FrameRef]
    T_reference_rover: Optional[RigidTransform]  # the rover pose, reference = rover_reference (a SITE_FRAME)
    frames: FrameGraph
    mast: Optional[MastState] = None
    exposure_ms: Optional[float] = None
    missing_field: dict = field(default_factory=dict)  # what could not be read: {"model": field, ...}
    rover_quat_wxyz: Optional[tuple] = None  # the pose quaternion as printed in the label


# --------------------------------------------------------------------------- value helpers
def strip_ns(key: str) -> str:
    """``MSL:MODEL_TRANSFORM_VECTOR`` -> ``MODEL_TRANSFORM_VECTOR`` (PDS3 local namespaces)."""
    return key.split(":", 1)[1] if ":" in key and not key.startswith("^") else key


def _is_filler(x) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool) and abs(float(x)) >= FILLER_ABS


def _unit_of(v) -> tuple[Any, str]:
    if isinstance(v, Quantity):
        return v.value, v.unit.strip().upper()
    return v, ""


class Group:
    """Typed access to one label group (a mapping); errors name ``group.KEY``."""

    def __init__(self, d: dict, product: str, name: str):
        self.d, self.product, self.name = d, product, name

    def err(self, key: str, message: str) -> InputError:
        return InputError(self.product, f"{self.name}.{key}" if self.name else key, message)

    def raw(self, key: str):
        return self.d.get(key)

    def has(self, key: str) -> bool:
        v = self.d.get(key)
        return v is not None and not (isinstance(v, str) and v.strip().upper() in NO_VALUE_STRINGS)

    def number(self, key: str, required: bool = True, units: Optional[dict] = None, default_unit: str = ""):
        v = self.d.get(key)
        if v is None or (isinstance(v, str) and v.strip().upper() in NO_VALUE_STRINGS):
            if required:
                raise self.err(key, "missing")
            return None
        x = self._num(key, v, units, default_unit)
        if x is None and required:
            raise self.err(key, "no value (1e+30 filler)")
        return x

    def _num(self, key, v, units, default_unit):
        v, unit = _unit_of(v)
        if isinstance(v, str):
            try:
                v = float(v.strip())
            except ValueError:
                raise self.err(key, f"not a number: {v!r}") from None
        if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)):
            raise self.err(key, f"not a number: {v!r}")
        if _is_filler(v):
            return None
        x = float(v)
        if not math.isfinite(x):
            raise self.err(key, f"not finite: {v!r}")
        if units is not None:
            u = unit or default_unit
            if u not in units:
                raise self.err(key, f"unexpected unit <{unit}>")
            x *= units[u]
        return x

    def vector(self, key: str, n: int, required: bool = True) -> Optional[np.ndarray]:
        v = self.d.get(key)
        if v is None:
            if required:
                raise self.err(key, "missing")
            return None
        if not isinstance(v, (list, tuple)) or len(v) != n:
            raise self.err(key, f"must be {n} numbers, got {v!r}"[:200])
        out = []
        for x in v:
            y = self._num(key, x, None, "")
            if y is None:
                if required:
                    raise self.err(key, f"no value (1e+30 filler) in {list(v)!r}"[:200])
                return None
            out.append(y)
        return np.array(out)

    def string(self, key: str, required: bool = True) -> str:
        v = self.d.get(key)
        if v is None:
            if required:
                raise self.err(key, "missing")
            return ""
        v, _ = _unit_of(v)
        return str(v).strip()

    def index(self, key: str) -> tuple:
        """A coordinate-system index: ``14`` or ``(14, 1262, ...)`` -> a tuple of ints (``()`` when absent)."""
        v = self.d.get(key)
        if v is None or (isinstance(v, str) and v.strip().upper() in NO_VALUE_STRINGS):
            return ()
        vals = v if isinstance(v, (list, tuple)) else (v,)
        out = []
        for x in vals:
            x, _ = _unit_of(x)
            try:
                f = float(x)
            except (TypeError, ValueError):
                raise self.err(key, f"not an integer index: {v!r}"[:200]) from None
            if f != int(f):
                raise self.err(key, f"not an integer index: {v!r}"[:200])
            out.append(int(f))
        return tuple(out)


def find_group(tree: dict, names) -> tuple[Optional[str], Optional[dict]]:
    for n in names:
        g = tree.get(n)
        if isinstance(g, dict):
            return n, g
    return None, None


# --------------------------------------------------------------------------- pieces
def camera_model_from_group(g: Group) -> CameraModel:
    """``MODEL_TYPE`` + ``MODEL_COMPONENT_ID`` + ``MODEL_COMPONENT_n`` -> :class:`CameraModel` (in the group's frame)."""
    kind = g.string("MODEL_TYPE").upper()
    if kind not in ("CAHV", "CAHVOR", "CAHVORE"):
        raise g.err("MODEL_TYPE", f"unsupported camera model type {kind!r} (want CAHV, CAHVOR or CAHVORE)")
    ids = g.raw("MODEL_COMPONENT_ID")
    if isinstance(ids, str):
        ids = (ids,)
    if not ids:
        ids = tuple(kind) + (("T", "P") if kind == "CAHVORE" else ())
    ids = [str(i).strip().upper() for i in ids]
    comps: dict = {}
    for i, cid in enumerate(ids, start=1):
        key = f"MODEL_COMPONENT_{i}"
        if cid in ("T", "P"):
            comps[cid] = (key, g.number(key, required=(kind == "CAHVORE" and cid == "T")))
        else:
            comps[cid] = (key, g.vector(key, 3))
    for need in kind:
        if need not in comps:
            raise g.err("MODEL_COMPONENT_ID", f"no {need} component for a {kind} model")
    mtype = lin = None
    if kind == "CAHVORE":
        key_t, t = comps.get("T", ("MODEL_COMPONENT_8", None))
        if t is None:
            raise g.err(key_t, "missing CAHVORE type (T)")
        if t not in (1.0, 2.0, 3.0):
            raise g.err(key_t, f"CAHVORE type must be 1, 2 or 3, got {t!r}")
        mtype = int(t)
        key_p, lin = comps.get("P", ("MODEL_COMPONENT_9", None))
        implied = {1: 1.0, 2: 0.0}.get(mtype)
        if mtype == 3 and lin is None:
            raise g.err(key_p, "missing linearity (P) for CAHVORE type 3")
        if implied is not None and lin is not None and lin != implied:
            raise g.err(key_p, f"CAHVORE type {mtype} implies linearity {implied:g}, got {lin!r}")
    try:
        return CameraModel(kind, comps["C"][1], comps["A"][1], comps["H"][1], comps["V"][1],
                           O=comps.get("O", (None, None))[1], R=comps.get("R", (None, None))[1],
                           E=comps.get("E", (None, None))[1], cahvore_type=mtype, linearity=lin)
    except CameraModelError as e:
        key = {c: k for c, (k, _) in comps.items()}.get(e.field, e.field)
        msg = str(e)[len(e.field) + 2:] if str(e).startswith(f"{e.field}: ") else str(e)
        raise g.err(key, msg) from None


def coordinate_systems(tree: dict, product: str) -> list:
    """Every coordinate-system group -> ``[(group name, frame, reference, T_reference_frame, quaternion_wxyz)]``."""
    out = []
    for gname, gd in tree.items():
        if not isinstance(gd, dict) or not _CS_GROUP_RE.match(gname):
            continue
        g = Group(gd, product, gname)
        if not g.has("COORDINATE_SYSTEM_NAME") or not g.has("ORIGIN_OFFSET_VECTOR"):
            continue
        frame = FrameRef(g.string("COORDINATE_SYSTEM_NAME").upper(), g.index("COORDINATE_SYSTEM_INDEX"))
        ref = FrameRef(g.string("REFERENCE_COORD_SYSTEM_NAME").upper(), g.index("REFERENCE_COORD_SYSTEM_INDEX"))
        t = g.vector("ORIGIN_OFFSET_VECTOR", 3)
        q = g.vector("ORIGIN_ROTATION_QUATERNION", 4)
        nq = float(np.linalg.norm(q))
        if abs(nq - 1.0) > 1e-3:
            raise g.err("ORIGIN_ROTATION_QUATERNION", f"not a unit quaternion (norm {nq:.6g})")
        out.append((gname, frame, ref, RigidTransform.from_quat_wxyz(q, t), tuple(float(x) for x in q)))
    return out


def mast_state(tree: dict, product: str) -> Optional[MastState]:
    """Measured head azimuth/elevation from ``RSM_ARTICULATION_STATE`` (MSL) or ``PMA_ARTICULATION_STATE`` (MER)."""
    for device, names in MAST_STATE_GROUPS:
        gname, gd = find_group(tree, names)
        if gd is None:
            continue
        g = Group(gd, product, gname)
        vals = g.raw("ARTICULATION_DEVICE_ANGLE")
        labels = g.raw("ARTICULATION_DEVICE_ANGLE_NAME")
        if vals is None or labels is None:
            raise g.err("ARTICULATION_DEVICE_ANGLE", "missing (or its _NAME list)")
        vals = vals if isinstance(vals, (list, tuple)) else (vals,)
        labels = labels if isinstance(labels, (list, tuple)) else (labels,)
        if len(vals) != len(labels):
            raise g.err("ARTICULATION_DEVICE_ANGLE", f"{len(vals)} angles but {len(labels)} names")
        angles = {}
        for name, v in zip(labels, vals):
            x = Group({"A": v}, product, gname)._num("ARTICULATION_DEVICE_ANGLE", v, _ANGLE_UNITS_RAD, "RAD")
            if x is not None:
                angles[str(name).strip().upper()] = x
        az = next((angles[n] for n in AZIMUTH_NAMES if n in angles), None)
        el = next((angles[n] for n in ELEVATION_NAMES if n in angles), None)
        if az is None or el is None:
            raise g.err("ARTICULATION_DEVICE_ANGLE", f"no measured azimuth/elevation among {sorted(angles)}"[:200])
        return MastState(device, az, el, angles)
    return None


def exposure_ms(tree: dict, product: str) -> Optional[float]:
    for gname in ("INSTRUMENT_STATE_PARMS", "INSTRUMENT_STATE"):
        gd = tree.get(gname)
        if isinstance(gd, dict) and "EXPOSURE_DURATION" in gd:
            return Group(gd, product, gname).number("EXPOSURE_DURATION", required=False, units=_TIME_UNITS_MS,
                                                     default_unit="MS")
    return None


def _top(tree: dict, key: str):
    v = tree.get(key)
    if v is None:
        ident = tree.get("IDENTIFICATION")
        if isinstance(ident, dict):
            v = ident.get(key)
    return v


# --------------------------------------------------------------------------- the whole label
def geometry_from_tree(tree: dict, product_hint: str, flavour: str) -> ProductGeometry:
    """A normalised PDS3/VICAR label tree (namespaces stripped, groups as dicts) -> :class:`ProductGeometry`.

    Reading never fails on a missing camera model or pose (``missing_field``
    records it; the product builder decides): it fails on present but bad values.
    """
    top = Group(tree, product_hint, "")
    pid_v = _top(tree, "PRODUCT_ID")
    product = str(_unit_of(pid_v)[0]).strip() if pid_v is not None else product_hint
    top.product = product
    missing: dict = {}

    mission = str(_unit_of(_top(tree, "INSTRUMENT_HOST_ID") or _top(tree, "MISSION_NAME") or "")[0]).strip()
    instrument = str(_unit_of(_top(tree, "INSTRUMENT_ID") or "")[0]).strip().upper()
    frame_id = str(_unit_of(_top(tree, "FRAME_ID") or "")[0]).strip().upper()
    sclk = None
    sc = _top(tree, "SPACECRAFT_CLOCK_START_COUNT")
    if sc is not None:
        sc = str(_unit_of(sc)[0]).strip().strip('"')
        try:
            sclk = float(sc.split("/")[-1])  # "1/431397159.601" partitioned form
        except ValueError:
            raise top.err("SPACECRAFT_CLOCK_START_COUNT", f"not a clock count: {sc!r}") from None
        if _is_filler(sclk):
            sclk = None
    sol_v = _top(tree, "PLANET_DAY_NUMBER")
    sol = None
    if sol_v is not None:
        s = Group({"P": sol_v}, product, "").number("P", required=False)
        sol = None if s is None else int(s)

    # image object size (PDS3 IMAGE object, or the VICAR system label)
    width = height = bits = None
    bands = 1
    img = tree.get("IMAGE")
    if isinstance(img, dict):
        gi = Group(img, product, "IMAGE")
        width = int(gi.number("LINE_SAMPLES"))
        height = int(gi.number("LINES"))
        bands = int(gi.number("BANDS", required=False) or 1)
        b = gi.number("SAMPLE_BITS", required=False)
        bits = None if b is None else int(b)
    elif "NS" in tree and "NL" in tree:
        width, height = int(top.number("NS")), int(top.number("NL"))
        bands = int(top.number("NB", required=False) or 1)

    # camera model in its frame
    model = model_frame = None
    gname, gd = find_group(tree, CAMERA_MODEL_GROUPS)
    if gd is None:
        missing["model"] = "GEOMETRIC_CAMERA_MODEL"
    else:
        g = Group(gd, product, gname)
        model = camera_model_from_group(g)
        model_frame = FrameRef(g.string("REFERENCE_COORD_SYSTEM_NAME", required=True).upper(),
                               g.index("REFERENCE_COORD_SYSTEM_INDEX"))

    # coordinate systems, the rover among them
    graph = FrameGraph()
    rover_frame = rover_ref = T_ref_rover = None
    rover_group_names = set(ROVER_CS_GROUPS)
    rover_q = None
    for cs_group, frame, ref, T_ref_frame, q in coordinate_systems(tree, product):
        graph.add(T_ref_frame, frame, ref)
        if cs_group in rover_group_names and rover_frame is None:
            rover_frame, rover_ref, T_ref_rover, rover_q = frame, ref, T_ref_frame, q
            if not rover_frame.index:  # MSSS-camera labels: no index in the group; the motion counter has it
                rmc = Group(tree, product, "").index("ROVER_MOTION_COUNTER")
                if rmc:
                    rover_frame = FrameRef(frame.name, rmc)
    if rover_frame is None:
        gname_r, _ = find_group(tree, ROVER_CS_GROUPS)
        missing["pose"] = gname_r or "ROVER_COORDINATE_SYSTEM"

    return ProductGeometry(
        product_id=product, label_flavour=flavour, mission=mission, instrument_id=instrument, frame_id=frame_id,
        sclk_s=sclk, sol=sol, width=width, height=height, bands=bands, sample_bits=bits,
        model=model, model_frame=model_frame, rover_frame=rover_frame, rover_reference=rover_ref,
        T_reference_rover=T_ref_rover, frames=graph, mast=mast_state(tree, product),
        exposure_ms=exposure_ms(tree, product), missing_field=missing, rover_quat_wxyz=rover_q,
    )


# --------------------------------------------------------------------------- tree builders
def _plain(v):
    """pdr metadata values -> plain Python (unit dicts -> :class:`Quantity`, tuples kept)."""
    if isinstance(v, dict) and set(v) == {"value", "units"}:
        return Quantity(_plain(v["value"]), str(v["units"]))
    if isinstance(v, (list, tuple)):
        return tuple(_plain(x) for x in v)
    if hasattr(v, "items") and hasattr(v, "keys"):
        return tree_from_mapping(v)
    return v


def tree_from_mapping(m) -> dict:
    """A pdr ``Metadata``/``MultiDict`` (PDS3 label) -> nested dict; the first of repeated keys wins."""
    out: dict = {}
    for k, v in m.items():
        k = strip_ns(str(k))
        if k not in out:
            out[k] = _plain(v)
    return out


def tree_from_vicar_items(items) -> dict:
    """rms-vicar ``VicarLabel.items()`` -> nested dict: system keys and ``IDENTIFICATION`` at the top,
    each ``PROPERTY`` a group; ``TASK`` (history) sections are skipped."""
    out: dict = {}
    current = out
    for k, v in items:
        if isinstance(k, tuple):  # rms-vicar keys repeated names as (name, occurrence)
            k = k[0]
        k = strip_ns(str(k))
        if k.endswith("__UNIT") and current is not None and k[:-6] in current:
            base, val = k[:-6], current[k[:-6]]
            units = [str(u) for u in v] if isinstance(v, (list, tuple)) else None
            if isinstance(val, tuple):
                units = units if units is not None and len(units) == len(val) else [str(v)] * len(val)
                current[base] = tuple(Quantity(x, u) for x, u in zip(val, units))
            else:
                current[base] = Quantity(val, str(v))
            continue
        if k == "PROPERTY":
            name = str(v).strip().upper()
            current = out if name == "IDENTIFICATION" else out.setdefault(name, {})
            continue
        if k == "TASK":
            current = None
            continue
        if current is None:
            continue
        if isinstance(v, list):
            v = tuple(v)
        if k not in current:
            current[k] = v
    return out
