"""Read and write downlinks (format version 1; docs/downlink-format.md).

Public API::

    read_downlink(path, validate=True) -> Downlink        # .mcap file or directory (also a workspace)
    write_downlink(dl, path, container="mcap" | "dir")    # atomic
    downlink_differences(a, b) -> list[str]               # [] when the content is identical (to the bit)

Both containers carry the same plain-data records (the tables of the format
document); :mod:`.downlink_records` converts between those records and
:mod:`scipctl.model` objects (its public functions are re-exported here).
The containers themselves are in :mod:`.downlink_mcap` and :mod:`.downlink_dir`,
the cross-record checks in :mod:`.validate`. Imports go one way: this module ->
containers -> records.
"""

from __future__ import annotations

import hashlib
from pathlib import Path

from ..core.kinematics import RoverPose
from ..errors import InputError
from ..model import Downlink
from .downlink_mcap import MCAP_MAGIC
from .downlink_records import (  # noqa: F401  (re-exported: the record conversions' public names)
    QUAT_NORM_TOL,
    Fields,
    ModelFileResolver,
    axis_for,
    camera_model_from_plain,
    camera_model_to_plain,
    check_format_version,
    model_slot_from_plain,
    pose_from_plain,
    pose_to_plain,
    product_from_plain,
    product_label,
    product_to_plain,
    quat_for,
    rover_config_from_plain,
    rover_config_to_plain,
    target_from_plain,
    target_to_plain,
    truth_image_from_plain,
    truth_image_to_plain,
    truth_target_from_plain,
    truth_target_to_plain,
)

# --------------------------------------------------------------------------- public API
def detect_container(path) -> str:
    """``"mcap"``, ``"dir"`` or ``"products"`` (real PDS/VICAR/raw-JSON products, :mod:`.pds_products`)
    for an existing downlink path; :class:`InputError` otherwise."""
    p = Path(path)
    if p.is_dir():
        if not (p / "downlink.yaml").exists():
            from .pds_products import is_product_path

            if is_product_path(p):
                return "products"
        return "dir"
    if p.is_file():
        if p.name == "downlink.yaml":
            return "dir"
        with open(p, "rb") as f:
            magic = f.read(len(MCAP_MAGIC))
        if not magic:
            raise InputError(str(p), "file", "empty file (0 bytes)")
        if magic != MCAP_MAGIC:
            from .pds_products import is_product_path

            if is_product_path(p):
                return "products"
            if p.suffix.lower() != ".mcap":  # an MCAP file by name is read as one, and its header said bad
                raise InputError(str(p), "file", "not a downlink: neither an MCAP file (container A) nor a real "
                                 "product scipctl reads (PDS3, VICAR, PDS4 label, Mars 2020 raw JSON; "
                                 "docs/downlink-format.md)")
        return "mcap"
    if not p.exists():
        raise InputError(str(p), "path", "no such file or directory")
    raise InputError(str(p), "path", "not a regular file or directory")


def read_downlink(path, validate: bool = True) -> Downlink:
    """Read a downlink: an MCAP file (container A), a directory with ``downlink.yaml`` (container B, also a
    workspace), or real rover products (a PDS3/VICAR/PDS4 product, a detached label, a Mars 2020 raw-image
    JSON, or a directory of them; :mod:`.pds_products`).

    With ``validate`` (default) every cross-record rule of the format is
    checked and every PNG decoded once (cached in ``ImageProduct.pixels``).
    Sets ``Downlink.source`` (the path) and ``source_sha256``.
    """
    p = Path(path)
    kind = detect_container(p)
    if kind == "dir":
        from .downlink_dir import read_dir

        dl = read_dir(p.parent if p.is_file() else p)
    elif kind == "products":
        from .pds_products import read_products

        dl = read_products(p)
    else:
        from .downlink_mcap import read_mcap

        dl = read_mcap(p)
    if validate:
        from .validate import validate_downlink

        validate_downlink(dl)
    return dl


def write_downlink(dl: Downlink, path, container: str = "mcap") -> Path:
    """Write ``dl`` to ``path`` atomically as ``container`` ``"mcap"`` (one file) or ``"dir"`` (a directory).

    Structural rules are checked first (unique ids, references); pixels are
    not re-decoded. A directory target is replaced only if it is absent,
    empty, or already a downlink directory. Returns the path written.
    """
    from .validate import validate_downlink

    validate_downlink(dl, check_pixels=False)
    if container == "mcap":
        from .downlink_mcap import write_mcap

        return write_mcap(dl, Path(path))
    if container == "dir":
        from .downlink_dir import write_dir

        return write_dir(dl, Path(path))
    raise ValueError(f"container must be 'mcap' or 'dir', got {container!r}")


# --------------------------------------------------------------------------- comparison
def content_record(dl: Downlink) -> dict:
    """Everything a downlink says, as plain data with exact floats and PNG hashes (for comparisons)."""

    def pose_bits(p: RoverPose):
        return {"R": p.T_site_rover.R.tolist(), "t": p.T_site_rover.t.tolist(), "source": p.source,
                "sigma_position_m": p.sigma_position_m, "sigma_yaw_rad": p.sigma_yaw_rad}

    images = []
    for im in dl.images:
        rec = product_to_plain(im)
        rec["pose"] = pose_bits(im.pose)
        rec["png_sha256"] = hashlib.sha256(im.png).hexdigest()
        images.append(rec)
    truth_images = []
    for t in dl.truth_images:
        rec = truth_image_to_plain(t)
        rec["pose"] = pose_bits(t.pose)
        truth_images.append(rec)
    return {
        "format_version": dl.format_version,
        "mission": dl.mission,
        "sol": int(dl.sol),
        "rover_config": rover_config_to_plain(dl.rover_config),
        "images": images,
        "targets": [target_to_plain(t) for t in dl.targets],
        "truth_images": truth_images,
        "truth_targets": [truth_target_to_plain(t) for t in dl.truth_targets],
    }


def downlink_differences(a: Downlink, b: Downlink) -> list[str]:
    """Human-readable differences between two downlinks' content (``[]`` when identical to the bit; order matters)."""
    ra, rb = content_record(a), content_record(b)
    diffs: list[str] = []

    def walk(x, y, where):
        if len(diffs) > 20:
            return
        if isinstance(x, dict) and isinstance(y, dict):
            for k in sorted(set(x) | set(y), key=str):
                if k not in x or k not in y:
                    diffs.append(f"{where}.{k}: only in {'b' if k not in x else 'a'}")
                else:
                    walk(x[k], y[k], f"{where}.{k}")
        elif isinstance(x, list) and isinstance(y, list):
            if len(x) != len(y):
                diffs.append(f"{where}: length {len(x)} != {len(y)}")
            for i, (xi, yi) in enumerate(zip(x, y)):
                walk(xi, yi, f"{where}[{i}]")
        elif type(x) is not type(y) or x != y:
            diffs.append(f"{where}: {x!r} != {y!r}")

    walk(ra, rb, "downlink")
    return diffs
