"""Mars 2020 raw-image JSON (``*-metadata.json`` of the public raw-image service) + its PNG -> one product.

The JSON gives the pointed model as one string
``"(C);(A);(H);(V);(O);(R);(E);T;P"`` (``camera_model_component_list``,
``camera_model_type``) in the rover navigation frame at ``(site, drive)``,
``instrument`` (``NAVCAM_LEFT`` ...), ``sclk``, the rover position ``xyz``
(site frame), the tile's ``subframe_rect`` ``[first_sample, first_line,
samples, lines]`` (1-based, full-detector pixels) and ``scale_factor``, and
``dimension`` ``(width,height)``.

The model is the model of the delivered tile (its ``H``/``V`` already carry
the subframe offset and the scale): for the two tiles in ``shared/real``
the unprojected tile centre lies within a few degrees of the JSON's
``camera_vector``, and the 2x tile's ``hs`` is half the full-frame one. So
the model is used as given; ``subframe_rect`` / ``scale_factor`` must agree
with the PNG's size. The JSON gives no rover attitude: the pose has the
identity orientation with ``sigma_yaw_rad = pi`` (heading unknown), source
``m2020-raw-json (position only)``. ``mast_az``/``mast_el`` are pointing
angles, not joint angles, so the product carries no ``mast``.
"""

from __future__ import annotations

import json
import math
import re
from pathlib import Path

import numpy as np

from ..core.camera import CameraModel, CameraModelError
from ..core.frames import FrameGraph, FrameRef
from ..core.transforms import RigidTransform
from ..model import InputError
from .pds_label import ProductGeometry

_VEC_RE = re.compile(r"^\(\s*([^,()]+),\s*([^,()]+),\s*([^,()]+)\s*\)$")


def _num(pid: str, field: str, v) -> float:
    try:
        x = float(v)
    except (TypeError, ValueError):
        raise InputError(pid, field, f"not a number: {v!r}"[:200]) from None
    if not math.isfinite(x) or abs(x) >= 1e29:
        raise InputError(pid, field, f"no value: {v!r}")
    return x


def _vec(pid: str, field: str, text: str) -> np.ndarray:
    m = _VEC_RE.match(text.strip())
    if not m:
        raise InputError(pid, field, f"not a 3-vector '(x,y,z)': {text!r}"[:200])
    return np.array([_num(pid, field, g) for g in m.groups()])


def parse_model_string(pid: str, kind: str, text: str) -> CameraModel:
    """``"(C);(A);(H);(V)[;(O);(R)[;(E);T;P]]"`` -> :class:`CameraModel`."""
    field = "camera_model_component_list"
    kind = (kind or "").strip().upper()
    if kind not in ("CAHV", "CAHVOR", "CAHVORE"):
        raise InputError(pid, "camera_model_type", f"unsupported camera model type {kind!r}")
    parts = [s for s in str(text).split(";")]
    need = {"CAHV": 4, "CAHVOR": 6, "CAHVORE": 9}[kind]
    if len(parts) != need:
        raise InputError(pid, field, f"{kind} needs {need} ';'-separated components, got {len(parts)}")
    vecs = [_vec(pid, f"{field}[{i}]", s) for i, s in enumerate(parts[: min(need, 7)])]
    kw = {}
    if kind in ("CAHVOR", "CAHVORE"):
        kw.update(O=vecs[4], R=vecs[5])
    mtype = lin = None
    if kind == "CAHVORE":
        kw["E"] = vecs[6]
        t = _num(pid, f"{field}[7]", parts[7])
        if t not in (1.0, 2.0, 3.0):
            raise InputError(pid, f"{field}[7]", f"CAHVORE type must be 1, 2 or 3, got {parts[7]!r}")
        mtype = int(t)
        lin = _num(pid, f"{field}[8]", parts[8])
        implied = {1: 1.0, 2: 0.0}.get(mtype)
        if implied is not None and lin != implied:
            raise InputError(pid, f"{field}[8]", f"CAHVORE type {mtype} implies linearity {implied:g}, got {lin!r}")
    try:
        return CameraModel(kind, *vecs[:4], cahvore_type=mtype, linearity=lin, **kw)
    except CameraModelError as e:
        raise InputError(pid, f"{field}.{e.field}", str(e)) from None


def png_for(json_path: Path) -> Path:
    name = json_path.name
    stem = name[: -len("-metadata.json")] if name.endswith("-metadata.json") else json_path.stem
    return json_path.parent / (stem + ".png")


def read_m2020_json(path: Path):
    """One raw-image JSON (and the PNG beside it) -> :class:`~scipctl.io.product_read.ProductRead`."""
    from .product_pixels import read_picture
    from .product_read import ProductRead

    try:
        d = json.loads(Path(path).read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as e:
        raise InputError(Path(path).name, "json", f"unreadable raw-image JSON ({e})"[:300]) from None
    if not isinstance(d, dict):
        raise InputError(Path(path).name, "json", "not a JSON object")
    png = png_for(Path(path))
    pid = png.stem if png.is_file() else str(d.get("imageid") or Path(path).stem)

    def req(key):
        if key not in d or d[key] is None:
            raise InputError(pid, key, "missing")
        return d[key]

    model = parse_model_string(pid, req("camera_model_type"), req("camera_model_component_list"))
    site = int(_num(pid, "site", req("site")))
    drive = int(_num(pid, "drive", req("drive")))
    sclk = _num(pid, "sclk", req("sclk"))
    instrument = str(req("instrument")).strip().upper()
    xyz = _vec(pid, "xyz", str(req("xyz")))
    rect = req("subframe_rect")
    if not isinstance(rect, list) or len(rect) != 4:
        raise InputError(pid, "subframe_rect", f"must be [first_sample, first_line, samples, lines], got {rect!r}"[:200])
    rect = [_num(pid, "subframe_rect", x) for x in rect]
    scale = _num(pid, "scale_factor", req("scale_factor"))
    if scale <= 0:
        raise InputError(pid, "scale_factor", f"must be positive, got {scale!r}")
    w_exp, h_exp = rect[2] / scale, rect[3] / scale
    dim = d.get("dimension")
    if dim is not None:
        m = re.match(r"^\(\s*(\d+)\s*,\s*(\d+)\s*\)$", str(dim).strip())
        if not m:
            raise InputError(pid, "dimension", f"not '(width,height)': {dim!r}")
        if (int(m.group(1)), int(m.group(2))) != (w_exp, h_exp):
            raise InputError(pid, "dimension", f"{dim} disagrees with subframe_rect {rect} at scale {scale:g}")
    if not png.is_file():
        raise InputError(pid, "image", f"the PNG {png.name} beside the JSON is missing")
    px = read_picture(png, pid, "image")
    if px.shape != (h_exp, w_exp):
        raise InputError(pid, "image", f"{png.name} is {px.shape[1]}x{px.shape[0]} pixels, but subframe_rect "
                                       f"{[int(x) for x in rect]} at scale {scale:g} says {int(w_exp)}x{int(h_exp)}")
    rover = FrameRef("ROVER_NAV_FRAME", (site, drive))
    site_frame = FrameRef("SITE_FRAME", (site,))
    T_site_rover = RigidTransform(np.eye(3), xyz)
    graph = FrameGraph()
    graph.add(T_site_rover, rover, site_frame)
    frame_id = "LEFT" if "LEFT" in instrument else "RIGHT" if "RIGHT" in instrument else ""
    geom = ProductGeometry(
        product_id=pid, label_flavour="M2020-JSON", mission="M2020", instrument_id=instrument, frame_id=frame_id,
        sclk_s=sclk, sol=int(_num(pid, "sol", d["sol"])) if d.get("sol") is not None else None,
        width=int(w_exp), height=int(h_exp), bands=1, sample_bits=8, model=model, model_frame=rover,
        rover_frame=rover, rover_reference=site_frame, T_reference_rover=T_site_rover, frames=graph,
    )
    return ProductRead(geom, px, [Path(path), png], pose_source="m2020-raw-json (position only)",
                       sigma_yaw_rad=math.pi)
