"""What a PDS4 XML label of a Mars 2020 camera product says about its geometry.

The label is read with the standard library's ElementTree (namespaces
ignored, local names kept): ``pdr`` also parses PDS4 labels, but its metadata
drops the XML ``unit`` attributes (``<index_value_angle unit="deg">``), which
this reader needs; ``pdr`` still reads the pixels (:mod:`.pds_products`).

Read: the telemetry ``geom:Geometry_Lander`` (``Camera_Model_Parameters``
with its CAHV/CAHVOR/CAHVORE model and ``Coordinate_Space_Reference``; every
``Coordinate_Space_Definition`` as a frame-graph edge; the RSM articulation
angles), ``img:Frame/frame_id`` (eye), ``img_surface:ops_instrument_key``
(instrument), the spacecraft clock and sol, ``img:exposure_duration``, and the
``Array_2D_Image``/``Array_3D_Image`` of ``File_Area_Observational``.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path
from typing import Optional

import numpy as np

from ..core.camera import CameraModel, CameraModelError
from ..core.frames import FrameGraph, FrameRef
from ..core.transforms import RigidTransform
from ..model import InputError
from .pds_label import AZIMUTH_NAMES, ELEVATION_NAMES, FILLER_ABS, MastState, ProductGeometry

_ANGLE = {"rad": 1.0, "deg": math.pi / 180.0}
_TIME_MS = {"ms": 1.0, "s": 1000.0, "microseconds": 1e-3}
_BITS = {"UnsignedByte": 8, "SignedByte": 8, "UnsignedMSB2": 16, "UnsignedLSB2": 16, "SignedMSB2": 16,
         "SignedLSB2": 16}


@dataclass
class Pds4Array:
    """Where the pixels are: the data file (next to the label) and the array's shape ``(bands, lines, samples)``."""

    file_name: str
    local_identifier: str
    bands: int
    lines: int
    samples: int
    data_type: str


def _local(tag: str) -> str:
    return tag.rsplit("}", 1)[-1]


def _kids(el, name: str) -> list:
    return [c for c in el if _local(c.tag) == name]


def _kid(el, name: str):
    for c in el:
        if _local(c.tag) == name:
            return c
    return None


def _path(el, *names):
    for n in names:
        if el is None:
            return None
        el = _kid(el, n)
    return el


def _iter(el, name: str):
    return (e for e in el.iter() if _local(e.tag) == name)


class _Reader:
    def __init__(self, product: str):
        self.product = product

    def err(self, field: str, message: str) -> InputError:
        return InputError(self.product, field, message)

    def num(self, el, field: str, units: Optional[dict] = None, default_unit: str = "", required: bool = True):
        if el is None or el.text is None or not el.text.strip():
            if required:
                raise self.err(field, "missing")
            return None
        try:
            x = float(el.text.strip())
        except ValueError:
            raise self.err(field, f"not a number: {el.text.strip()!r}") from None
        if abs(x) >= FILLER_ABS:
            if required:
                raise self.err(field, "no value (1e+30 filler)")
            return None
        if not math.isfinite(x):
            raise self.err(field, f"not finite: {el.text.strip()!r}")
        if units is not None:
            u = el.get("unit", default_unit)
            if u not in units:
                raise self.err(field, f"unexpected unit {u!r}")
            x *= units[u]
        return x

    def vec(self, el, field: str, names) -> np.ndarray:
        if el is None:
            raise self.err(field, "missing")
        return np.array([self.num(_kid(el, n), f"{field}.{n}") for n in names])

    def frame_ref(self, indexed, field: str) -> FrameRef:
        name_el = _kid(indexed, "coordinate_space_frame_type")
        if name_el is None or not (name_el.text or "").strip():
            raise self.err(f"{field}.coordinate_space_frame_type", "missing")
        idx = []
        for ci in _kids(indexed, "Coordinate_Space_Index"):
            v = self.num(_kid(ci, "index_value_number"), f"{field}.Coordinate_Space_Index.index_value_number")
            idx.append(int(v))
        return FrameRef(name_el.text.strip().upper(), tuple(idx))


def _model(r: _Reader, cmp) -> tuple[CameraModel, FrameRef]:
    base = "geom:Camera_Model_Parameters"
    for kind in ("CAHVORE", "CAHVOR", "CAHV"):
        m = _kid(cmp, f"{kind}_Model")
        if m is not None:
            break
    else:
        raise r.err(base, "no CAHV_Model, CAHVOR_Model or CAHVORE_Model")
    f = f"{base}.{kind}_Model"
    xyz_p, xyz_u, xyz_px = ("x_position", "y_position", "z_position"), ("x_unit", "y_unit", "z_unit"), (
        "x_pixel", "y_pixel", "z_pixel")
    C = r.vec(_kid(m, "Vector_Center"), f"{f}.Vector_Center", xyz_p)
    A = r.vec(_kid(m, "Vector_Axis"), f"{f}.Vector_Axis", xyz_u)
    H = r.vec(_kid(m, "Vector_Horizontal"), f"{f}.Vector_Horizontal", xyz_px)
    V = r.vec(_kid(m, "Vector_Vertical"), f"{f}.Vector_Vertical", xyz_px)
    O = R = E = None
    mtype = lin = None
    if kind in ("CAHVOR", "CAHVORE"):
        O = r.vec(_kid(m, "Vector_Optical"), f"{f}.Vector_Optical", xyz_u)
        R = r.vec(_kid(m, "Radial_Terms"), f"{f}.Radial_Terms", ("c0", "c1", "c2"))
    if kind == "CAHVORE":
        E = r.vec(_kid(m, "Entrance_Terms"), f"{f}.Entrance_Terms", ("c0", "c1", "c2"))
        t = r.num(_kid(m, "cahvore_model_type"), f"{f}.cahvore_model_type")
        if t not in (1.0, 2.0, 3.0):
            raise r.err(f"{f}.cahvore_model_type", f"must be 1, 2 or 3, got {t!r}")
        mtype = int(t)
        lin = r.num(_kid(m, "cahvore_model_parameter"), f"{f}.cahvore_model_parameter", required=(mtype == 3))
        implied = {1: 1.0, 2: 0.0}.get(mtype)
        if implied is not None and lin is not None and lin != implied:
            raise r.err(f"{f}.cahvore_model_parameter", f"CAHVORE type {mtype} implies linearity {implied:g}, got {lin!r}")
    try:
        model = CameraModel(kind, C, A, H, V, O=O, R=R, E=E, cahvore_type=mtype, linearity=lin)
    except CameraModelError as e:
        msg = str(e)[len(e.field) + 2:] if str(e).startswith(f"{e.field}: ") else str(e)
        raise r.err(f"{f}.{e.field}", msg) from None
    indexed = _path(cmp, "Coordinate_Space_Reference", "Coordinate_Space_Indexed")
    if indexed is None:
        raise r.err(f"{base}.Coordinate_Space_Reference", "missing: the model's frame is not named")
    return model, r.frame_ref(indexed, f"{base}.Coordinate_Space_Reference")


def geometry_from_pds4(path: Path) -> tuple[ProductGeometry, Optional[Pds4Array]]:
    """Parse a PDS4 XML label -> (geometry, the image array's description or None)."""
    label = str(path.name)
    try:
        root = ET.parse(path).getroot()
    except (ET.ParseError, OSError) as e:
        raise InputError(label, "xml", f"unreadable PDS4 label ({e})") from None
    # product id: the VICAR PRODUCT_ID alias, else the logical identifier's last part
    pid = None
    for alias in _iter(root, "Alias"):
        alt = _kid(alias, "alternate_id")
        if alt is not None and alt.text:
            pid = alt.text.strip()
            break
    if pid is None:
        lid = next(_iter(root, "logical_identifier"), None)
        pid = lid.text.strip().rsplit(":", 1)[-1] if lid is not None and lid.text else path.stem
    r = _Reader(pid)

    def text(name: str) -> str:
        el = next(_iter(root, name), None)
        return el.text.strip() if el is not None and el.text else ""

    mission = _path(root, "Observation_Area", "Investigation_Area", "name")
    mission = mission.text.strip() if mission is not None and mission.text else ""
    instrument = text("ops_instrument_key").upper()
    frame_id = ""
    for fr in _iter(root, "Frame"):
        fid = _kid(fr, "frame_id")
        if fid is not None and fid.text:
            frame_id = fid.text.strip().upper()
            break
    sclk = None
    sc = text("spacecraft_clock_start")
    if sc:
        try:
            sclk = float(sc)
        except ValueError:
            raise r.err("spacecraft_clock_start", f"not a clock count: {sc!r}") from None
    sol = None
    for name in ("start_sol_number", "sol_number"):
        s = text(name)
        if s:
            sol = int(float(s))
            break
    exposure = None
    for ex in _iter(root, "Exposure"):
        d = _kid(ex, "exposure_duration")
        if d is not None:
            exposure = r.num(d, "img:Exposure.exposure_duration", _TIME_MS, "ms", required=False)
            break

    # the image array
    arr = None
    width = height = bits = None
    bands = 1
    for fao in _iter(root, "File_Area_Observational"):
        fn = _path(fao, "File", "file_name")
        for an in ("Array_3D_Image", "Array_2D_Image"):
            a = _kid(fao, an)
            if a is None:
                continue
            axes = {}
            for ax in _kids(a, "Axis_Array"):
                nm = (_kid(ax, "axis_name").text or "").strip().lower()
                axes[nm] = int(r.num(_kid(ax, "elements"), f"{an}.Axis_Array.elements"))
            if "line" not in axes or "sample" not in axes:
                raise r.err(f"{an}.Axis_Array", f"no Line/Sample axes (got {sorted(axes)})")
            dt = (_path(a, "Element_Array", "data_type").text or "").strip() if _path(a, "Element_Array", "data_type") is not None else ""
            width, height, bands = axes["sample"], axes["line"], axes.get("band", 1)
            bits = _BITS.get(dt)
            lid = _kid(a, "local_identifier")
            arr = Pds4Array(fn.text.strip() if fn is not None and fn.text else "",
                            lid.text.strip() if lid is not None and lid.text else "", bands, height, width, dt)
            break
        if arr is not None:
            break

    # geometry: the telemetry state (the first Geometry_Lander otherwise)
    landers = list(_iter(root, "Geometry_Lander"))
    geo = None
    for gl in landers:
        st = _kid(gl, "geometry_state")
        if st is not None and (st.text or "").strip().lower() == "telemetry":
            geo = gl
            break
    if geo is None and landers:
        geo = landers[0]
    missing: dict = {}
    model = model_frame = None
    graph = FrameGraph()
    rover_frame = rover_ref = T_ref_rover = rover_q = None
    mast = None
    if geo is None:
        missing["model"] = "geom:Geometry_Lander"
        missing["pose"] = "geom:Geometry_Lander"
    else:
        cmp = _kid(geo, "Camera_Model_Parameters")
        if cmp is None:
            missing["model"] = "geom:Camera_Model_Parameters"
        else:
            model, model_frame = _model(r, cmp)
        # coordinate spaces: resolve local references by local_identifier
        defs = _kids(geo, "Coordinate_Space_Definition")
        by_local: dict = {}
        present: list = []  # (index, definition, its frame), in label order
        for i, d in enumerate(defs):
            f = f"geom:Coordinate_Space_Definition[{i}]"
            ind = _path(d, "Coordinate_Space_Present", "Coordinate_Space_Indexed")
            if ind is None:
                continue
            frame = r.frame_ref(ind, f"{f}.Coordinate_Space_Present")
            present.append((i, d, frame))
            for lid in _kids(d, "local_identifier"):
                if lid.text:
                    by_local[lid.text.strip()] = frame
        for i, d, frame in present:  # references may point forward: resolved once every local name is known
            f = f"geom:Coordinate_Space_Definition[{i}]"
            ref_el = _kid(d, "Coordinate_Space_Reference")
            ref = None
            if ref_el is not None:
                rind = _kid(ref_el, "Coordinate_Space_Indexed")
                lref = _path(ref_el, "Local_Internal_Reference", "local_identifier_reference")
                if rind is not None:
                    ref = r.frame_ref(rind, f"{f}.Coordinate_Space_Reference")
                elif lref is not None and lref.text:
                    ref = by_local.get(lref.text.strip())
                    if ref is None:
                        raise r.err(f"{f}.Coordinate_Space_Reference", f"unknown local reference {lref.text.strip()!r}")
            if ref is None:
                raise r.err(f"{f}.Coordinate_Space_Reference", "missing")
            t = r.vec(_kid(d, "Vector_Origin_Offset"), f"{f}.Vector_Origin_Offset", ("x_position", "y_position", "z_position"))
            qel = _kid(d, "Quaternion_Plus_Direction")
            q = r.vec(qel, f"{f}.Quaternion_Plus_Direction", ("qcos", "qsin1", "qsin2", "qsin3"))
            direction = _kid(qel, "rotation_direction")
            if direction is not None and (direction.text or "").strip().lower() not in ("forward", ""):
                raise r.err(f"{f}.Quaternion_Plus_Direction.rotation_direction",
                            f"unsupported rotation direction {direction.text.strip()!r} (want Forward)")
            nq = float(np.linalg.norm(q))
            if abs(nq - 1.0) > 1e-3:
                raise r.err(f"{f}.Quaternion_Plus_Direction", f"not a unit quaternion (norm {nq:.6g})")
            T_ref_frame = RigidTransform.from_quat_wxyz(q, t)
            graph.add(T_ref_frame, frame, ref)
            if rover_frame is None and frame.name.startswith("ROVER") and ref.name == "SITE_FRAME":
                rover_frame, rover_ref, T_ref_rover, rover_q = frame, ref, T_ref_frame, tuple(float(x) for x in q)
        if rover_frame is None:
            missing["pose"] = "geom:Coordinate_Space_Definition (ROVER_NAV_FRAME)"
        # mast angles
        for adp in _kids(geo, "Articulation_Device_Parameters"):
            dev = _kid(adp, "device_id")
            if dev is None or (dev.text or "").strip().upper() not in ("RSM", "PMA"):
                continue
            angles = {}
            for da in _iter(adp, "Device_Angle_Index"):
                nm = _kid(da, "index_id")
                v = r.num(_kid(da, "index_value_angle"), "geom:Articulation_Device_Parameters.Device_Angle",
                          _ANGLE, "rad", required=False)
                if nm is not None and nm.text and v is not None:
                    angles.setdefault(nm.text.strip().upper(), v)
            az = next((angles[n] for n in AZIMUTH_NAMES if n in angles), None)
            el = next((angles[n] for n in ELEVATION_NAMES if n in angles), None)
            if az is None or el is None:
                raise r.err("geom:Articulation_Device_Parameters.Device_Angle",
                            f"no measured azimuth/elevation among {sorted(angles)}"[:200])
            mast = MastState(dev.text.strip().upper(), az, el, angles)
            break

    geom = ProductGeometry(
        product_id=pid, label_flavour="PDS4", mission=mission, instrument_id=instrument, frame_id=frame_id,
        sclk_s=sclk, sol=sol, width=width, height=height, bands=bands, sample_bits=bits, model=model,
        model_frame=model_frame, rover_frame=rover_frame, rover_reference=rover_ref, T_reference_rover=T_ref_rover,
        frames=graph, mast=mast, exposure_ms=exposure, missing_field=missing, rover_quat_wxyz=rover_q,
    )
    return geom, arr
