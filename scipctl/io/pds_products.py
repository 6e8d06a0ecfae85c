"""Real rover camera products (PDS3, VICAR, PDS4, Mars 2020 raw JSON) -> an in-memory :class:`Downlink`.

Public API::

    is_product_path(path) -> bool        # a product file, a detached label, or a directory holding products
    read_products(path) -> Downlink      # the same in-memory downlink as from MCAP or a downlink directory

Readers (the field's own where one exists):

* PDS3 products with attached labels (``.IMG``) and detached labels
  (``.LBL``): ``pdr`` reads the label and the pixels (also the VICAR label
  and image inside PDS3-wrapped EDRs);
* plain VICAR files (``LBLSIZE=`` first): ``rms-vicar`` (``pdr`` does not
  read them);
* PDS4 XML labels: :mod:`.pds4_label` (stdlib XML, for the unit attributes);
  the pixels with ``pdr``;
* Mars 2020 raw-image JSON (``*-metadata.json`` + its PNG): :mod:`.m2020_json`.

What each product gives (docs/downlink-format.md, "Real products"): the
camera model moved into the rover frame at acquisition (through the label's
coordinate systems when it names another frame), the pose ``T_site_rover``
from the rover coordinate system, ``(site, drive)`` from its index, the
measured mast azimuth/elevation, camera and eye from ``INSTRUMENT_ID`` /
``FRAME_ID``, the spacecraft clock as ``time_s`` (so left and right eyes of
one exposure pair up), 8-bit pixels as 8-bit and 12-bit-in-16 as 16-bit.

A detached label whose data file is absent takes the raw-image browse
picture of the same product beside it (``<id minus version>_.jpg`` etc.,
the MSL/MER gallery naming) when that picture has the label's size. Files
that are not products (other images, text) in a directory are skipped.
"""

from __future__ import annotations

import hashlib
import re
import warnings
from pathlib import Path
from typing import Optional

import numpy as np

from ..core.frames import FrameRef
from ..core.kinematics import JointAxis, MastGeometry, RoverConfig, RoverPose
from ..core.transforms import RigidTransform
from ..model import Downlink, ImageProduct, InputError, MastAngles
from .pds_label import ProductGeometry, geometry_from_tree, tree_from_mapping, tree_from_vicar_items
from .product_pixels import read_picture, to_single_channel as _to_single_channel
from .product_read import ProductRead

ROVER_FRAMES = ("ROVER_NAV_FRAME", "ROVER_FRAME", "ROVER_MECH_FRAME")
MAST_CAMERAS = {"navcam", "pancam", "mastcam", "mastcamz"}
IMAGE_SUFFIXES = {".png", ".jpg", ".jpeg"}
_CAMERA_PATTERNS = (
    (re.compile(r"^(NAV|NAVCAM|NCAM)"), "navcam"),
    (re.compile(r"^(FHAZ|FRONT_HAZCAM|HAZ_FRONT|FRONT_HAZ)"), "hazcam"),
    (re.compile(r"^(RHAZ|REAR_HAZCAM|HAZ_REAR|REAR_HAZ)"), "rear_hazcam"),
    (re.compile(r"^PANCAM"), "pancam"),
    (re.compile(r"^(MCZ|MASTCAMZ|MASTCAM_Z|ZCAM)"), "mastcamz"),
    (re.compile(r"^(MAST_|MASTCAM)"), "mastcam"),
)


# --------------------------------------------------------------------------- sniffing
def sniff(path: Path) -> Optional[str]:
    """``"pds3"``, ``"vicar"``, ``"pds4"``, ``"m2020-json"`` or ``None`` (not a product file)."""
    try:
        with open(path, "rb") as f:
            head = f.read(4096)
    except OSError:
        return None
    h = head.lstrip()
    if h.startswith(b"PDS_VERSION_ID") or h.startswith(b"ODL_VERSION_ID") or h.startswith(b"CCSD"):
        return "pds3"
    if head.startswith(b"LBLSIZE="):
        return "vicar"
    if h.startswith(b"<?xml") or h.startswith(b"<Product_"):
        return "pds4" if b"Product_Observational" in head or b"pds.nasa.gov/pds4" in head else None
    if path.suffix.lower() == ".json" and h.startswith(b"{") and b"camera_model_component_list" in _read(path):
        return "m2020-json"
    return None


def _read(path: Path) -> bytes:
    try:
        return path.read_bytes()
    except OSError:
        return b""


def is_product_path(path) -> bool:
    """True for a product file or a directory (without ``downlink.yaml``) holding at least one product file."""
    p = Path(path)
    if p.is_file():
        return sniff(p) is not None
    if p.is_dir() and not (p / "downlink.yaml").exists():
        return any(sniff(f) is not None for f in sorted(p.iterdir()) if f.is_file())
    return False


def _browse_for(label: Path, product_id: str) -> Optional[Path]:
    """The gallery browse picture of a product beside its label (``..M1`` -> ``..M_.jpg``; or the id itself)."""
    stems = [product_id, product_id[:-1] + "_", label.stem, label.stem[:-1] + "_"]
    for stem in dict.fromkeys(stems):
        for ext in (".jpg", ".JPG", ".jpeg", ".JPEG", ".png", ".PNG"):
            q = label.parent / (stem + ext)
            if q.is_file():
                return q
    return None


def _pdr_read(path: Path, product: str):
    import pdr

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            return pdr.read(str(path))
    except Exception as e:  # pdr raises many kinds on malformed labels
        raise InputError(product, "label", f"{path.name}: unreadable PDS label ({type(e).__name__}: {e})"[:300]) from None


def _pdr_array(data, key: str, product: str, field_name: str, expect_shape) -> Optional[np.ndarray]:
    """The array object ``key`` of a pdr ``Data``; ``None`` if its data file is absent; error if unreadable."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            arr = data[key]
        except Exception as e:
            arr, exc = None, e
        else:
            exc = None
    msgs = [str(w.message) for w in caught]
    if isinstance(arr, np.ndarray):
        return arr
    if any("not found" in m for m in msgs):
        return None
    why = "; ".join(msgs) or (f"{type(exc).__name__}: {exc}" if exc is not None else "no array")
    raise InputError(product, field_name,
                     f"cannot read the pixels the label describes ({expect_shape}): {why}"[:300])


def _expect(geom: ProductGeometry) -> str:
    return f"{geom.width} samples x {geom.height} lines x {geom.bands} band(s)"


def _check_size(px: np.ndarray, geom: ProductGeometry, field_name: str, source: str) -> None:
    if geom.width is None or geom.height is None:
        raise InputError(geom.product_id, field_name, "the label gives no image size")
    if px.shape != (geom.height, geom.width):
        raise InputError(geom.product_id, field_name,
                         f"{source} is {px.shape[1]}x{px.shape[0]} pixels, but the label says "
                         f"{geom.width}x{geom.height}")


def _read_pds3(path: Path) -> ProductRead:
    data = _pdr_read(path, path.name)
    geom = geometry_from_tree(tree_from_mapping(data.metadata), path.name, "PDS3")
    files = [path]
    ptr = data.metadata.get("^IMAGE")
    target = None
    if isinstance(ptr, (list, tuple)) and ptr and isinstance(ptr[0], str):
        target = path.parent / ptr[0]
    elif isinstance(ptr, str):
        target = path.parent / ptr
    if (ptr is not None or "IMAGE" in data.keys()) and (geom.width is None or geom.height is None):
        # pdr would fail inside its own code ('NoneType' object has no attribute 'get'): say what is missing
        raise InputError(geom.product_id, "IMAGE", f"{path.name}: the label has no IMAGE object with LINES and "
                                                   "LINE_SAMPLES (is the label cut short?)")
    arr = _pdr_array(data, "IMAGE", geom.product_id, "IMAGE", _expect(geom)) if "IMAGE" in data.keys() else None
    if arr is not None:
        px = _to_single_channel(arr, geom.product_id, "IMAGE", path.name)
        if target is not None and target.exists():
            files.append(target)
        _check_size(px, geom, "IMAGE", (target or path).name)
        return ProductRead(geom, px, files)
    browse = _browse_for(path, geom.product_id)
    if browse is None:
        name = target.name if target is not None else path.name
        raise InputError(geom.product_id, "^IMAGE", f"data file {name} not found (and no browse picture beside the label)")
    px = read_picture(browse, geom.product_id, "^IMAGE")
    _check_size(px, geom, "^IMAGE", f"browse picture {browse.name} (data file absent)")
    return ProductRead(geom, px, files + [browse])


def _read_vicar(path: Path) -> ProductRead:
    try:
        import vicar
    except ImportError:
        raise InputError(path.name, "format", "a plain VICAR file needs the optional reader rms-vicar "
                                              "(pip install 'scipctl[vicar]'); PDS3-wrapped VICAR reads without it") from None

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            image = vicar.VicarImage(str(path))  # parses the label once (pyparsing: ~1.5 s per label); pixels lazily
            label = image.label
    except Exception as e:
        raise InputError(path.name, "label", f"unreadable VICAR label ({type(e).__name__}: {e})"[:300]) from None
    geom = geometry_from_tree(tree_from_vicar_items(label.items()), path.name, "VICAR")
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            arr = image.array
    except Exception as e:
        raise InputError(geom.product_id, "image", f"cannot read the pixels the label describes ({_expect(geom)}): "
                                                   f"{type(e).__name__}: {e}"[:300]) from None
    px = _to_single_channel(arr, geom.product_id, "image", path.name)
    _check_size(px, geom, "NS", path.name)
    return ProductRead(geom, px, [path])


def _read_pds4(path: Path) -> ProductRead:
    from .pds4_label import geometry_from_pds4

    geom, arr_desc = geometry_from_pds4(path)
    if arr_desc is None:
        raise InputError(geom.product_id, "File_Area_Observational", "no Array_2D_Image or Array_3D_Image")
    data_file = path.parent / arr_desc.file_name
    if data_file.is_file():
        data = _pdr_read(path, geom.product_id)
        key = arr_desc.local_identifier if arr_desc.local_identifier in data.keys() else None
        arr = _pdr_array(data, key, geom.product_id, "Array_3D_Image", _expect(geom)) if key else None
        if arr is None:
            raise InputError(geom.product_id, "File_Area_Observational.File", f"cannot read the array in {data_file.name}")
        px = _to_single_channel(arr, geom.product_id, "Array_3D_Image", data_file.name)
        _check_size(px, geom, "Axis_Array", data_file.name)
        return ProductRead(geom, px, [path, data_file])
    browse = _browse_for(path, geom.product_id)
    if browse is None:
        raise InputError(geom.product_id, "File_Area_Observational.File.file_name",
                         f"data file {arr_desc.file_name} not found (and no browse picture beside the label)")
    px = read_picture(browse, geom.product_id, "File_Area_Observational.File")
    _check_size(px, geom, "Axis_Array", f"browse picture {browse.name} (data file absent)")
    return ProductRead(geom, px, [path, browse])


def read_product_file(path, kind: Optional[str] = None) -> ProductRead:
    """Read one product file (a product, a detached label, a PDS4 label, or a raw-image JSON)."""
    p = Path(path)
    kind = kind or sniff(p)
    if kind == "pds3":
        return _read_pds3(p)
    if kind == "vicar":
        return _read_vicar(p)
    if kind == "pds4":
        return _read_pds4(p)
    if kind == "m2020-json":
        from .m2020_json import read_m2020_json

        return read_m2020_json(p)
    raise InputError(str(p), "path", "not a PDS3/VICAR/PDS4 product, a detached label or a Mars 2020 raw-image JSON")


# --------------------------------------------------------------------------- geometry -> product
def camera_and_eye(geom: ProductGeometry) -> tuple[str, str]:
    """(camera name, eye) from ``INSTRUMENT_ID`` (``NAV_LEFT_B``, ``FHAZ_RIGHT_A``, ``PANCAM_LEFT``, ``NAVCAM_LEFT``...)
    and ``FRAME_ID``."""
    inst = geom.instrument_id.upper()
    eye = {"LEFT": "left", "RIGHT": "right", "L": "left", "R": "right"}.get(geom.frame_id.upper())
    tokens = re.split(r"[_\s]+", inst)
    if eye is None:
        if "LEFT" in tokens:
            eye = "left"
        elif "RIGHT" in tokens:
            eye = "right"
    if eye is None:
        raise InputError(geom.product_id, "FRAME_ID", f"cannot tell the eye of {inst or 'an unnamed instrument'} "
                                                      f"(FRAME_ID {geom.frame_id!r})")
    for pat, name in _CAMERA_PATTERNS:
        if pat.match(inst):
            return name, eye
    if not inst:
        raise InputError(geom.product_id, "INSTRUMENT_ID", "missing")
    base = [t for t in tokens if t not in ("LEFT", "RIGHT", "A", "B")]
    return "_".join(base).lower() or inst.lower(), eye


def model_in_rover_frame(geom: ProductGeometry):
    """The label's model moved into the rover frame at acquisition: ``model.transformed(T_rover_modelframe)``."""
    pid = geom.product_id
    if geom.model is None:
        f = geom.missing_field.get("model", "GEOMETRIC_CAMERA_MODEL")
        raise InputError(pid, f, "missing: the label has no camera model")
    if geom.rover_frame is None:
        f = geom.missing_field.get("pose", "ROVER_COORDINATE_SYSTEM")
        raise InputError(pid, f, "missing: the label gives no rover pose (rover coordinate system)")
    rover = geom.rover_frame
    graph = geom.frames
    # the local level frame: at the rover origin, axes of the site frame (not a group in MSL labels)
    R_site_rover = geom.T_reference_rover.R
    graph.add(RigidTransform(R_site_rover, np.zeros(3)), rover, FrameRef("LOCAL_LEVEL_FRAME", rover.index))
    frm = geom.model_frame
    if frm.name in ROVER_FRAMES and frm.name == rover.name and not frm.matches(rover):
        raise InputError(pid, "GEOMETRIC_CAMERA_MODEL.REFERENCE_COORD_SYSTEM_INDEX",
                         f"model is in {frm}, another rover position than the label's rover frame {rover}")
    T_rover_model = graph.transform(rover, frm)
    if T_rover_model is None:
        raise InputError(pid, "GEOMETRIC_CAMERA_MODEL.REFERENCE_COORD_SYSTEM_NAME",
                         f"model is in {frm}, a frame the label does not relate to the rover frame {rover}")
    return geom.model.transformed(T_rover_model)


def product_from_read(pr: ProductRead) -> ImageProduct:
    """One read product -> :class:`ImageProduct` (model in the rover frame, pose in the site frame)."""
    from .images import encode_png

    g = pr.geometry
    pid = g.product_id
    if not pid or not pid.strip():  # the downlink's records refuse a blank id: a workspace holding one would not re-read
        raise InputError(pr.files[0].name if pr.files else "product", "PRODUCT_ID", "missing or blank")
    if g.exposure_ms is not None and not g.exposure_ms >= 0:
        raise InputError(pid, "EXPOSURE_DURATION", f"must be >= 0, got {g.exposure_ms!r}")
    camera, eye = camera_and_eye(g)
    model = model_in_rover_frame(g)
    rover = g.rover_frame
    if len(rover.index) < 2:
        raise InputError(pid, "ROVER_COORDINATE_SYSTEM.COORDINATE_SYSTEM_INDEX",
                         f"need at least (site, drive), got {list(rover.index)}")
    site, drive = int(rover.index[0]), int(rover.index[1])
    ref = g.rover_reference
    if ref is None or ref.name != "SITE_FRAME":
        raise InputError(pid, "ROVER_COORDINATE_SYSTEM.REFERENCE_COORD_SYSTEM_NAME",
                         f"the rover pose is relative to {ref}, not a SITE_FRAME")
    if ref.index and ref.index[0] != site:
        raise InputError(pid, "ROVER_COORDINATE_SYSTEM.REFERENCE_COORD_SYSTEM_INDEX",
                         f"pose is in SITE_FRAME {ref.index[0]} but the rover is at site {site}")
    if g.sclk_s is None:
        raise InputError(pid, "SPACECRAFT_CLOCK_START_COUNT", "missing: no acquisition time")
    T_site_rover = g.T_reference_rover
    if g.rover_quat_wxyz is not None:  # keep the label's quaternion digits for writing (downlink.quat_for)
        from .downlink_records import _remember_quat

        _remember_quat(T_site_rover.R, list(g.rover_quat_wxyz))
    pose = RoverPose(T_site_rover, pr.pose_source or f"{g.label_flavour} label", None, pr.sigma_yaw_rad)
    mast = None
    if camera in MAST_CAMERAS and g.mast is not None:
        mast = MastAngles(g.mast.azimuth_rad, g.mast.elevation_rad)
    h, w = pr.pixels.shape
    return ImageProduct(
        product_id=pid, camera=camera, eye=eye, time_s=float(g.sclk_s), site=site, drive=drive, pose=pose,
        camera_model=model, width=int(w), height=int(h), png=encode_png(pr.pixels), mast=mast,
        exposure_ms=g.exposure_ms, gain=None, _pixels=pr.pixels,
    )


# --------------------------------------------------------------------------- file or directory -> downlink
def placeholder_rover_config(name: str) -> RoverConfig:
    """A rover configuration with no cameras: product labels carry pointed models, not the calibration.

    Its mast entry (pan about rover +z, tilt about rover +y, through the origin)
    is a placeholder that no camera uses.
    """
    mast = MastGeometry(JointAxis(np.zeros(3), np.array([0.0, 0.0, 1.0])), JointAxis(np.zeros(3), np.array([0.0, 1.0, 0.0])))
    return RoverConfig(name, mast, {})


_MISSIONS = {"MSL": "MSL", "MARS SCIENCE LABORATORY": "MSL", "MER1": "MER", "MER2": "MER", "MER": "MER",
             "MARS EXPLORATION ROVER": "MER", "MARS2020": "M2020", "MARS 2020": "M2020", "M2020": "M2020",
             "M20": "M2020", "PERSEVERANCE": "M2020"}


def _mission(geom: ProductGeometry) -> str:
    m = geom.mission.upper()
    return _MISSIONS.get(m, geom.mission or "unknown")


def _kind_order(kind: str) -> int:
    # labels that claim other files first: detached labels / PDS4 / JSON before attached products
    return {"m2020-json": 0, "pds4": 0, "pds3": 1, "vicar": 2}[kind]


def read_products(path) -> Downlink:
    """A product file, a detached label, or a directory of them -> :class:`Downlink` (no cross-record validation).

    In a directory, a file used by an earlier product (the ``.IMG`` a
    detached ``.LBL`` points into, the PNG of a raw-image JSON) is not read
    again; detached labels (``.LBL``) are read before the attached ``.IMG``.
    """
    p = Path(path)
    if p.is_file():
        kinds = [(p, sniff(p))]
        if kinds[0][1] is None:
            raise InputError(str(p), "path", "not a PDS3/VICAR/PDS4 product, a detached label or a Mars 2020 raw-image JSON")
    else:
        listed = [f for f in sorted(p.iterdir()) if f.is_file() and not f.name.startswith(".")]
        kinds = [(f, sniff(f)) for f in listed]
        kinds = [(f, k) for f, k in kinds if k is not None]
        if not kinds:
            raise InputError(str(p), "path", "no PDS3/VICAR/PDS4 product, detached label or Mars 2020 raw-image JSON here")
        # detached labels (.LBL) before the data files they point into
        kinds.sort(key=lambda fk: (_kind_order(fk[1]), 0 if fk[0].suffix.lower() in (".lbl", ".xml", ".json") else 1, fk[0].name))
    used: set = set()
    reads = []
    for f, kind in kinds:
        if f.resolve() in used:
            continue
        pr = read_product_file(f, kind)
        used.update(x.resolve() for x in pr.files)
        reads.append(pr)
    images = [product_from_read(pr) for pr in reads]
    missions = sorted({_mission(pr.geometry) for pr in reads})
    if len(missions) > 1:
        raise InputError(str(p), "mission", f"products of more than one mission here ({', '.join(missions)})")
    sols = [pr.geometry.sol for pr in reads if pr.geometry.sol is not None]
    h = hashlib.sha256()
    from .provenance import sha256_file

    files = sorted({x.resolve() for pr in reads for x in pr.files})
    for f in files:
        h.update(f.name.encode() + b"\0" + sha256_file(f).encode() + b"\n")
    mission = missions[0]
    unread = [] if p.is_file() else [f.name for f in listed if f.resolve() not in used]
    return Downlink(
        mission=mission, sol=min(sols) if sols else 0,
        rover_config=placeholder_rover_config(f"{mission} (from product labels; no camera calibration)"),
        images=images, source=str(p), source_sha256=h.hexdigest(), unread_files=unread,
    )
