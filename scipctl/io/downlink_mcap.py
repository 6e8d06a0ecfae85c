"""Container A: a downlink as one MCAP file (JSON messages, JSON-Schema schemas).

Topics (docs/downlink-format.md): ``/downlink/image`` (``scip.ImageProduct``),
``/downlink/rover_config`` (``scip.RoverConfig``, exactly one),
``/downlink/targets`` (``scip.TargetMarks``), ``/truth/image``
(``scip.ImageTruth``), ``/truth/targets`` (``scip.TargetTruth``); metadata
record ``scip.downlink`` = ``{format_version: "1", mission, sol}`` (strings).
Image messages carry ``image: {format: "png", data: <base64>}`` and
``log_time = round(time_s * 1e9)``. Other topics and keys are ignored.
"""

from __future__ import annotations

import base64
import binascii
import hashlib
import io
import json
import re
from pathlib import Path

from ..model import Downlink, InputError
from . import downlink_records as P

MCAP_MAGIC = b"\x89MCAP0\r\n"

TOPIC_IMAGE = "/downlink/image"
TOPIC_ROVER_CONFIG = "/downlink/rover_config"
TOPIC_TARGETS = "/downlink/targets"
TOPIC_TRUTH_IMAGE = "/truth/image"
TOPIC_TRUTH_TARGETS = "/truth/targets"
METADATA_NAME = "scip.downlink"

_VEC3 = {"type": "array", "items": {"type": "number"}, "minItems": 3, "maxItems": 3}
_CAMERA_MODEL = {
    "type": "object",
    "required": ["type", "C", "A", "H", "V"],
    "properties": {
        "type": {"enum": ["CAHV", "CAHVOR", "CAHVORE"]},
        "C": _VEC3, "A": _VEC3, "H": _VEC3, "V": _VEC3, "O": _VEC3, "R": _VEC3, "E": _VEC3,
        "cahvore_type": {"enum": [1, 2, 3]},
        "linearity": {"type": "number"},
    },
}
_POSE = {
    "type": "object",
    "required": ["position_m", "orientation_wxyz", "source"],
    "properties": {
        "position_m": _VEC3,
        "orientation_wxyz": {"type": "array", "items": {"type": "number"}, "minItems": 4, "maxItems": 4},
        "source": {"type": "string"},
        "sigma_position_m": {"type": "number", "minimum": 0},
        "sigma_yaw_rad": {"type": "number", "minimum": 0},
    },
}
_SPEC = {"type": "object", "required": ["camera_model", "width", "height"],
         "properties": {"camera_model": _CAMERA_MODEL, "width": {"type": "integer", "minimum": 1},
                        "height": {"type": "integer", "minimum": 1}}}
_JOINT = {"type": "object", "required": ["origin_m", "axis"], "properties": {"origin_m": _VEC3, "axis": _VEC3}}
_DRAFT = "https://json-schema.org/draft/2020-12/schema"

SCHEMAS = {
    "scip.ImageProduct": {
        "$schema": _DRAFT,
        "title": "scip.ImageProduct",
        "type": "object",
        "required": ["product_id", "camera", "eye", "time_s", "position", "pose", "camera_model", "width", "height", "image"],
        "properties": {
            "product_id": {"type": "string", "minLength": 1},
            "camera": {"type": "string"},
            "eye": {"enum": ["left", "right"]},
            "time_s": {"type": "number"},
            "position": {"type": "object", "required": ["site", "drive"],
                         "properties": {"site": {"type": "integer"}, "drive": {"type": "integer"}}},
            "pose": _POSE,
            "mast": {"type": "object", "required": ["pan_rad", "tilt_rad"],
                     "properties": {"pan_rad": {"type": "number"}, "tilt_rad": {"type": "number"}}},
            "camera_model": _CAMERA_MODEL,
            "width": {"type": "integer", "minimum": 1},
            "height": {"type": "integer", "minimum": 1},
            "exposure_ms": {"type": "number", "minimum": 0},
            "gain": {"type": "number"},
            "image": {"type": "object", "required": ["format", "data"],
                      "properties": {"format": {"const": "png"}, "data": {"type": "string", "contentEncoding": "base64"}}},
        },
    },
    "scip.RoverConfig": {
        "$schema": _DRAFT,
        "title": "scip.RoverConfig",
        "type": "object",
        "required": ["mast", "cameras"],
        "properties": {
            "name": {"type": "string"},
            "mast": {"type": "object", "required": ["pan", "tilt"], "properties": {"pan": _JOINT, "tilt": _JOINT}},
            "cameras": {"type": "object", "additionalProperties": {
                "type": "object", "required": ["mount", "left", "right"],
                "properties": {"mount": {"enum": ["mast", "body"]}, "left": _SPEC, "right": _SPEC}}},
        },
    },
    "scip.TargetMarks": {
        "$schema": _DRAFT,
        "title": "scip.TargetMarks",
        "type": "object",
        "required": ["id"],
        "properties": {
            "id": {"type": "string"},
            "kind": {"type": "string"},
            "description": {"type": "string"},
            "marks": {"type": "array", "items": {
                "type": "object", "required": ["product_id", "u", "v"],
                "properties": {"product_id": {"type": "string"}, "u": {"type": "number"}, "v": {"type": "number"},
                               "sigma_px": {"type": "number", "minimum": 0}}}},
        },
    },
    "scip.ImageTruth": {
        "$schema": _DRAFT,
        "title": "scip.ImageTruth",
        "type": "object",
        "required": ["product_id", "pose", "camera_model"],
        "properties": {"product_id": {"type": "string"}, "pose": _POSE, "camera_model": _CAMERA_MODEL},
    },
    "scip.TargetTruth": {
        "$schema": _DRAFT,
        "title": "scip.TargetTruth",
        "type": "object",
        "required": ["id", "xyz_site_m"],
        "properties": {"id": {"type": "string"}, "xyz_site_m": _VEC3},
    },
}

TOPIC_SCHEMAS = {
    TOPIC_IMAGE: "scip.ImageProduct",
    TOPIC_ROVER_CONFIG: "scip.RoverConfig",
    TOPIC_TARGETS: "scip.TargetMarks",
    TOPIC_TRUTH_IMAGE: "scip.ImageTruth",
    TOPIC_TRUTH_TARGETS: "scip.TargetTruth",
}


# --------------------------------------------------------------------------- reading
def _raw_records(name: str, data: bytes):
    """All messages on our topics and all metadata records, in one linear pass; InputError if not a complete MCAP."""
    from mcap.records import Channel, Message, Metadata
    from mcap.stream_reader import StreamReader

    if not data.startswith(MCAP_MAGIC):
        raise InputError(name, "file", "not an MCAP file (bad magic bytes)")
    messages = {t: [] for t in TOPIC_SCHEMAS}
    metadata = []
    channels = {}
    try:
        for rec in StreamReader(io.BytesIO(data), validate_crcs=True).records:
            if isinstance(rec, Channel):
                channels[rec.id] = rec
            elif isinstance(rec, Message):
                ch = channels.get(rec.channel_id)
                if ch is None:
                    raise InputError(name, "file", f"message on unknown channel id {rec.channel_id} (corrupt MCAP)")
                if ch.topic in messages:
                    messages[ch.topic].append((ch.message_encoding, rec.log_time, rec.data))
            elif isinstance(rec, Metadata):
                metadata.append((rec.name, dict(rec.metadata)))
    except InputError:
        raise
    except Exception as e:  # mcap raises many kinds (EndOfFile, struct.error, CRC, ...) on damaged files
        detail = f"{type(e).__name__}: {str(e)[:120]}" if str(e).strip() else type(e).__name__
        raise InputError(name, "file", f"truncated or corrupt MCAP ({detail})") from None
    return messages, metadata


def _decode_json(name: str, topic: str, index: int, encoding: str, data: bytes):
    if encoding != "json":
        raise InputError(name, f"{topic}[{index}]", f"message encoding is {encoding!r}, the format requires 'json'")
    try:
        return json.loads(data)
    except (UnicodeDecodeError, json.JSONDecodeError) as e:
        raise InputError(name, f"{topic}[{index}]", f"message is not valid JSON ({e})") from None
    except (ValueError, RecursionError) as e:  # valid JSON Python will not read: >4300-digit integers, deep nesting
        raise InputError(name, f"{topic}[{index}]", f"message cannot be read as JSON ({str(e)[:120]})") from None


_B64_SPACE = re.compile(r"[ \t\r\n]+")


def _image_bytes(d, label: str) -> bytes:
    fs = P.Fields(d, label, "")
    img = fs.map_("image")
    fmt = img.str_("format")
    if fmt.lower() != "png":
        raise img.err("format", f"must be 'png', got {fmt!r}")
    # MIME-style base64 (RFC 2045: lines of 76, as Python's encodebytes, OpenSSL and Java's MIME encoder write
    # it) is base64 too: ASCII whitespace is dropped; any other character outside the alphabet is an error
    data = _B64_SPACE.sub("", img.str_("data"))
    try:
        return base64.b64decode(data, validate=True)
    except (binascii.Error, ValueError) as e:
        raise img.err("data", f"not valid base64 ({e})") from None


def read_mcap(path: Path) -> Downlink:
    """Read container A into a :class:`Downlink` (no cross-record validation; see :func:`validate.validate_downlink`)."""
    name = str(path)
    try:
        data = path.read_bytes()
    except OSError as e:
        raise InputError(name, "file", e.strerror or str(e)) from None
    messages, metadata = _raw_records(name, data)

    meta = [m for n, m in metadata if n == METADATA_NAME]
    if not meta:
        raise InputError(name, f"metadata {METADATA_NAME}", "missing (needs format_version, mission, sol)")
    if any(m != meta[0] for m in meta[1:]):
        raise InputError(name, f"metadata {METADATA_NAME}", "more than one record, and they disagree")
    meta = meta[0]
    where = f"{name}: metadata {METADATA_NAME}"
    for key in ("format_version", "mission", "sol"):
        if key not in meta:
            raise InputError(where, key, "missing")
    fmt_version = P.check_format_version(meta["format_version"], where)
    try:
        sol = int(meta["sol"].strip())
    except ValueError:
        raise InputError(where, "sol", f"not an integer: {meta['sol']!r}") from None

    for topic in (TOPIC_IMAGE, TOPIC_ROVER_CONFIG):
        if not messages[topic]:
            raise InputError(name, topic, "required topic has no messages")
    if len(messages[TOPIC_ROVER_CONFIG]) != 1:
        raise InputError(name, TOPIC_ROVER_CONFIG, f"exactly one message required, found {len(messages[TOPIC_ROVER_CONFIG])}")

    enc, _, raw = messages[TOPIC_ROVER_CONFIG][0]
    rover_config = P.rover_config_from_plain(_decode_json(name, TOPIC_ROVER_CONFIG, 0, enc, raw))

    images = []
    for i, (enc, _log_time, raw) in enumerate(messages[TOPIC_IMAGE]):  # log_time is informative; time_s rules
        d = _decode_json(name, TOPIC_IMAGE, i, enc, raw)
        label = P.product_label(d, i, TOPIC_IMAGE)
        png = _image_bytes(d, label)
        images.append(P.product_from_plain(d, png, rover_config, label))

    targets = [P.target_from_plain(_decode_json(name, TOPIC_TARGETS, i, enc, raw), f"{TOPIC_TARGETS}[{i}]")
               for i, (enc, _, raw) in enumerate(messages[TOPIC_TARGETS])]
    truth_images = [P.truth_image_from_plain(_decode_json(name, TOPIC_TRUTH_IMAGE, i, enc, raw), f"{TOPIC_TRUTH_IMAGE}[{i}]")
                    for i, (enc, _, raw) in enumerate(messages[TOPIC_TRUTH_IMAGE])]
    truth_targets = [P.truth_target_from_plain(_decode_json(name, TOPIC_TRUTH_TARGETS, i, enc, raw), f"{TOPIC_TRUTH_TARGETS}[{i}]")
                     for i, (enc, _, raw) in enumerate(messages[TOPIC_TRUTH_TARGETS])]
    return Downlink(
        mission=meta["mission"], sol=sol, rover_config=rover_config, images=images, targets=targets,
        truth_images=truth_images, truth_targets=truth_targets, format_version=fmt_version,
        source=name, source_sha256=hashlib.sha256(data).hexdigest(),
    )


# --------------------------------------------------------------------------- writing
def _dumps(obj) -> bytes:
    return json.dumps(obj, separators=(",", ":"), allow_nan=False).encode("utf-8")


def log_time_ns(time_s: float) -> int:
    """``round(time_s * 1e9)``, clamped to the unsigned 64-bit range MCAP allows."""
    return min(max(int(round(float(time_s) * 1e9)), 0), 2**64 - 1)


def mcap_bytes(dl: Downlink) -> bytes:
    """The MCAP encoding of ``dl`` (deterministic: same downlink, same bytes)."""
    from mcap.writer import CompressionType, Writer

    from .. import __version__

    buf = io.BytesIO()
    w = Writer(buf, compression=CompressionType.ZSTD)
    w.start(profile="", library=f"scipctl {__version__}")
    channels = {}
    for topic, schema_name in TOPIC_SCHEMAS.items():
        sid = w.register_schema(schema_name, "jsonschema", json.dumps(SCHEMAS[schema_name], sort_keys=True).encode())
        channels[topic] = w.register_channel(topic, "json", sid)
    w.add_metadata(METADATA_NAME, {"format_version": str(dl.format_version), "mission": str(dl.mission), "sol": str(int(dl.sol))})

    t0 = min((log_time_ns(im.time_s) for im in dl.images), default=0)
    w.add_message(channels[TOPIC_ROVER_CONFIG], t0, _dumps(P.rover_config_to_plain(dl.rover_config)), t0)
    for im in dl.images:
        rec = P.product_to_plain(im)
        rec["image"] = {"format": "png", "data": base64.b64encode(im.png).decode("ascii")}
        t = log_time_ns(im.time_s)
        w.add_message(channels[TOPIC_IMAGE], t, _dumps(rec), t)
    for topic, items, conv in (
        (TOPIC_TARGETS, dl.targets, P.target_to_plain),
        (TOPIC_TRUTH_IMAGE, dl.truth_images, P.truth_image_to_plain),
        (TOPIC_TRUTH_TARGETS, dl.truth_targets, P.truth_target_to_plain),
    ):
        for it in items:
            w.add_message(channels[topic], t0, _dumps(conv(it)), t0)
    w.finish()
    return buf.getvalue()


def write_mcap(dl: Downlink, path: Path) -> Path:
    from .atomic import atomic_write_bytes

    if path.is_dir():
        raise InputError(str(path), "path", "is a directory; an MCAP downlink is a file")
    atomic_write_bytes(path, mcap_bytes(dl))
    return path
