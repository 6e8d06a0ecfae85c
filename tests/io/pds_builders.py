"""Small PDS3 products of each label flavour, written in a test's tmp_path (no real data copied).

``pds3_product(dir, name, ...)`` writes a product with an attached label (or
a detached ``.LBL`` + raw ``.IMG``) whose geometry groups follow the
flavour's spelling:

* ``"MSL"``: attached-label groups (``GEOMETRIC_CAMERA_MODEL``,
  ``ROVER_COORDINATE_SYSTEM``, ``RSM_ARTICULATION_STATE``), ``ROVER_NAV_FRAME``;
* ``"MSL-archive"``: detached-archive groups (``..._PARMS``,
  ``ROVER_COORD_SYSTEM_PARMS``) with ``MSL:`` namespaced keys;
* ``"MER"``: ``ROVER_FRAME``, ``PMA_ARTICULATION_STATE``;
* ``"MSSS"``: ``ROVER_COORDINATE_SYSTEM_PARMS`` without a site index (the
  ``ROVER_MOTION_COUNTER`` has it).

Values carry units (``<rad>``, ``<ms>``), the rover quaternion is split over
two lines, and optional fields can hold the ``1e+30`` filler.
"""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import numpy as np

from scipctl.core.camera import CameraModel

FLAVOURS = {
    "MSL": dict(model="GEOMETRIC_CAMERA_MODEL", rover="ROVER_COORDINATE_SYSTEM", mast="RSM_ARTICULATION_STATE",
                rsm_cs="RSM_COORDINATE_SYSTEM", frame="ROVER_NAV_FRAME", host="MSL", ns=""),
    "MSL-archive": dict(model="GEOMETRIC_CAMERA_MODEL_PARMS", rover="ROVER_COORD_SYSTEM_PARMS",
                        mast="RSM_ARTICULATION_STATE_PARMS", rsm_cs="RSM_COORD_SYSTEM_PARMS", frame="ROVER_NAV_FRAME",
                        host="MSL", ns="MSL:"),
    "MER": dict(model="GEOMETRIC_CAMERA_MODEL", rover="ROVER_COORDINATE_SYSTEM", mast="PMA_ARTICULATION_STATE",
                rsm_cs="PMA_COORDINATE_SYSTEM", frame="ROVER_FRAME", host="MER2", ns=""),
    "MSSS": dict(model="GEOMETRIC_CAMERA_MODEL_PARMS", rover="ROVER_COORDINATE_SYSTEM_PARMS",
                 mast="RSM_ARTICULATION_STATE_PARMS", rsm_cs="RSM_COORD_SYSTEM_PARMS", frame="ROVER_NAV_FRAME",
                 host="MSL", ns=""),
}


def fmt(x) -> str:
    return repr(float(x))


def vec(v) -> str:
    return "(" + ",".join(fmt(x) for x in v) + ")"


def model_group(model: CameraModel, group: str, frame: str, index: str, ns: str = "") -> str:
    ids = list(model.kind) + (["T", "P"] if model.kind == "CAHVORE" else [])
    lines = [f"GROUP = {group}", f"  MODEL_TYPE = {model.kind}",
             "  MODEL_COMPONENT_ID = (" + ",".join(f'"{i}"' for i in ids) + ")"]
    for n, cid in enumerate(ids, start=1):
        if cid == "T":
            val = fmt(model.cahvore_type)
        elif cid == "P":
            val = fmt(model.linearity)
        else:
            val = vec(getattr(model, cid))
        lines.append(f"  MODEL_COMPONENT_{n} = {val}")
    lines += [f"  {ns}MODEL_TRANSFORM_VECTOR = (0.0,0.0,0.0)", f"  {ns}MODEL_TRANSFORM_QUATERNION = (1.0,0.0,0.0,0.0)",
              f'  REFERENCE_COORD_SYSTEM_NAME = "{frame}"', f"  REFERENCE_COORD_SYSTEM_INDEX = {index}",
              f"END_GROUP = {group}"]
    return "\n".join(lines)


def cs_group(group: str, name: str, index: Optional[str], offset, quat, ref_name: str, ref_index: Optional[str]) -> str:
    q = [fmt(x) for x in quat]
    lines = [f"GROUP = {group}", f'  COORDINATE_SYSTEM_NAME = "{name}"']
    if index is not None:
        lines.append(f"  COORDINATE_SYSTEM_INDEX = {index}")
    lines += [f"  ORIGIN_OFFSET_VECTOR = {vec(offset)}",
              f"  ORIGIN_ROTATION_QUATERNION = ({q[0]},{q[1]},\n                                {q[2]},{q[3]})",
              f'  REFERENCE_COORD_SYSTEM_NAME = "{ref_name}"']
    if ref_index is not None:
        lines.append(f"  REFERENCE_COORD_SYSTEM_INDEX = {ref_index}")
    lines.append(f"END_GROUP = {group}")
    return "\n".join(lines)


def pds3_product(
    directory: Path,
    name: str,
    pixels: np.ndarray,
    model: Optional[CameraModel],
    *,
    flavour: str = "MSL",
    instrument: str = "NAV_LEFT_B",
    frame_id: str = "LEFT",
    sclk: str = "516721703.665",
    site: int = 54,
    drive: int = 992,
    rover_offset=(9.57832, -9.24059, -0.301764),
    rover_quat=(0.0217046, 0.0118624, -0.0386198, -0.998948),
    model_frame: Optional[str] = None,
    model_index: Optional[str] = None,
    extra_groups: str = "",
    mast_angles_rad=(4.73721, 0.769993),
    exposure: str = "409.6 <ms>",
    detached: bool = False,
    label_lines: Optional[int] = None,
    label_samples: Optional[int] = None,
    truncate_to: Optional[int] = None,
) -> Path:
    """Write one product; returns the path to read (the ``.IMG``, or the ``.LBL`` when ``detached``)."""
    fl = FLAVOURS[flavour]
    ns = fl["ns"]
    idx = f"({site},{drive},12,14,0,0,72,54,0,0)"
    h, w = pixels.shape
    bits = pixels.dtype.itemsize * 8
    stype = "UNSIGNED_INTEGER" if bits == 8 else "MSB_INTEGER"
    groups = []
    if model is not None:
        groups.append(model_group(model, fl["model"], model_frame or fl["frame"], model_index or idx, ns))
    rover_index = None if flavour == "MSSS" else idx
    ref_index = None if flavour == "MSSS" else str(site)
    groups.append(cs_group(fl["rover"], fl["frame"], rover_index, rover_offset, rover_quat, "SITE_FRAME", ref_index))
    names = ("AZIMUTH-MEASURED", "ELEVATION-MEASURED", "AZIMUTH-REQUESTED", "ELEVATION-REQUESTED")
    ang = [mast_angles_rad[0], mast_angles_rad[1], 1e30, 0.0]  # a 1e+30 filler among the optional angles
    groups.append("\n".join([
        f"GROUP = {fl['mast']}", '  ARTICULATION_DEVICE_ID = "RSM"',
        "  ARTICULATION_DEVICE_ANGLE = (" + ",\n     ".join(f"{a!r} <rad>" for a in ang) + ")",
        "  ARTICULATION_DEVICE_ANGLE_NAME = (" + ",".join(f'"{n}"' for n in names) + ")",
        f"END_GROUP = {fl['mast']}"]))
    groups.append("\n".join(["GROUP = INSTRUMENT_STATE_PARMS", f"  EXPOSURE_DURATION = {exposure}",
                             "  AZIMUTH_FOV = 1.0e+30 <deg>", "END_GROUP = INSTRUMENT_STATE_PARMS"]))
    if extra_groups:
        groups.append(extra_groups)
    record = 2 * w if bits == 16 else w
    record = max(record, 512)
    img_obj = "\n".join(["OBJECT = IMAGE", f"  LINES = {label_lines or h}", f"  LINE_SAMPLES = {label_samples or w}",
                         f"  SAMPLE_TYPE = {stype}", f"  SAMPLE_BITS = {bits}", "  BANDS = 1",
                         "  BAND_STORAGE_TYPE = BAND_SEQUENTIAL", "END_OBJECT = IMAGE"])
    motion = f"ROVER_MOTION_COUNTER = {idx}\n" if flavour == "MSSS" else ""

    raw = pixels.astype(">i2" if bits == 16 else "u1").tobytes()
    n_data = -(-len(raw) // record)
    data = raw.ljust(n_data * record, b"\0")  # lines are contiguous; the file ends on a record boundary
    def body(ptr: str, label_records: int) -> str:
        return "\n".join([
            "PDS_VERSION_ID = PDS3", "RECORD_TYPE = FIXED_LENGTH", f"RECORD_BYTES = {record}",
            f"FILE_RECORDS = {label_records + n_data}", f"LABEL_RECORDS = {label_records}", f"^IMAGE = {ptr}",
            f'INSTRUMENT_HOST_ID = "{fl["host"]}"', f'INSTRUMENT_ID = "{instrument}"', f'FRAME_ID = "{frame_id}"',
            "PLANET_DAY_NUMBER = 1343", f'SPACECRAFT_CLOCK_START_COUNT = "{sclk}"', f'PRODUCT_ID = "{name}"',
            motion + "/* geometry */", *groups, img_obj, "END"]) + "\r\n"

    directory = Path(directory)
    if detached:
        img = directory / f"{name}.IMG"
        img.write_bytes(data if truncate_to is None else data[:truncate_to])
        lbl = directory / f"{name}.LBL"
        lbl.write_text(body(f'("{name}.IMG",1)', 0).replace("FILE_RECORDS", "/* detached */ FILE_RECORDS"), encoding="ascii")
        return lbl
    n_label = 1
    while True:
        text = body(str(n_label + 1), n_label).encode("ascii")
        if len(text) <= n_label * record:
            break
        n_label = -(-len(text) // record)
    blob = text.ljust(n_label * record, b" ") + data
    out = directory / f"{name}.IMG"
    out.write_bytes(blob if truncate_to is None else blob[:truncate_to])
    return out
