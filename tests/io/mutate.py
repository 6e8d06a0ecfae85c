"""Seeded mutations of valid downlinks, for the bad-input property tests.

Used by ``tests/io/test_bad_input_property.py`` (``read_downlink``) and
``tests/commands/test_bad_input_cli.py`` (``scipctl ingest`` / ``info``).
Every mutation draws from a ``numpy.random.Generator`` and returns a short
description, so that a failing case can be named and replayed from its seed.

* :func:`mutate_bytes` - truncate, flip bits, zero-fill, duplicate or delete a range;
* :func:`mutate_tree` - 1 to 3 edits of a JSON/YAML record tree: delete a key
  or item, nudge a number, or put an odd value in its place (wrong types,
  NaN/inf, huge numbers, strings with line breaks or NUL, ...);
  :func:`dump_json` / :func:`dump_yaml` write the tree, splicing in values
  Python will not print (a 5000-digit integer, a 5000-deep list);
* :func:`odd_png` - image bytes that are not a valid product image;
* :func:`error_problems` - what is wrong with an error as a bad-input report.
"""

from __future__ import annotations

import copy
import json
import math
import struct
import zlib

import numpy as np

import yaml

from scipctl.io.downlink_dir import PyYamlDumper
from scipctl.io.images import encode_png

# --------------------------------------------------------------------------- bytes
BYTE_OPS = ("truncate", "flip", "zero", "duplicate", "delete")


def mutate_bytes(data: bytes, rng: np.random.Generator, op: str | None = None) -> tuple[bytes, str]:
    """One byte-level mutation of ``data`` (``op``: one of :data:`BYTE_OPS`, else drawn) -> (new bytes, description)."""
    op = op or BYTE_OPS[rng.integers(len(BYTE_OPS))]
    b, n = bytearray(data), len(data)
    a = int(rng.integers(0, n))
    length = int(rng.integers(1, 257))
    if op == "truncate":
        return bytes(b[:a]), f"truncate at {a}/{n}"
    if op == "flip":
        bits = sorted({int(x) for x in rng.integers(0, 8 * n, size=int(rng.integers(1, 4)))})
        for bit in bits:
            b[bit // 8] ^= 1 << (bit % 8)
        return bytes(b), f"flip bits {bits}"
    if op == "zero":
        b[a:a + length] = bytes(len(b[a:a + length]))
        return bytes(b), f"zero [{a}:{a + length}]"
    if op == "duplicate":
        b[a:a] = b[a:a + length]
        return bytes(b), f"duplicate [{a}:{a + length}]"
    if op == "delete":
        del b[a:a + length]
        return bytes(b), f"delete [{a}:{a + length}]"
    raise ValueError(op)


# --------------------------------------------------------------------------- record trees
HUGE_INT, DEEP = "ZZHUGEINTZZ", "ZZDEEPZZ"  # placeholders, spliced into the written text
_SPLICE = {HUGE_INT: "9" * 5000, DEEP: "[" * 5000 + "]" * 5000}

ODD_VALUES = (
    None, True, False, "", "x", "1.5", "0042", "line\nbreak", "para\u2028sep", "nul\x00byte", "\ud800",
    [], {}, [1, 2], [math.nan] * 3, {"x": 1}, 0, -1, 1.5, 2**64, 10**30, 10**400, 1e308, -1e308, 5e-324,
    math.nan, math.inf, -math.inf, HUGE_INT, DEEP,
)


def _slots(node, path=()):
    """Every (container, key, path) below ``node``, depth first."""
    if isinstance(node, dict):
        items = list(node.items())
    elif isinstance(node, list):
        items = list(enumerate(node))
    else:
        return
    for k, v in items:
        yield node, k, path + (k,)
        yield from _slots(v, path + (k,))


def _nudgeable(v) -> bool:
    return (isinstance(v, float) and math.isfinite(v)) or (type(v) is int and abs(v) < 2**53)


def mutate_tree(root, rng: np.random.Generator, max_edits: int = 3) -> str:
    """Edit the dict/list tree ``root`` in place (1..``max_edits`` edits) -> description."""
    done = []
    for _ in range(int(rng.integers(1, max_edits + 1))):
        slots = list(_slots(root))
        if not slots:
            break
        parent, key, path = slots[int(rng.integers(len(slots)))]
        where = ".".join(str(p) for p in path)
        r = rng.random()
        if r < 0.25:
            del parent[key]
            done.append(f"delete {where}")
        elif r < 0.4 and _nudgeable(parent[key]):
            old = parent[key]
            factor = float(rng.choice([-1.0, 1.0])) * 10.0 ** float(rng.uniform(-12, 3))
            parent[key] = old + factor * (abs(old) if old else 1.0)
            done.append(f"nudge {where} {old!r} -> {parent[key]!r}")
        else:
            v = ODD_VALUES[int(rng.integers(len(ODD_VALUES)))]
            parent[key] = copy.deepcopy(v)  # (later edits may change it in place)
            done.append(f"set {where} = {v!r:.30}")
    return "; ".join(done)


def _splice(text: str, quoted: bool) -> str:
    for k, v in _SPLICE.items():
        text = text.replace(f'"{k}"' if quoted else k, v)
    return text


def dump_json(obj) -> bytes:
    """JSON text of ``obj`` (NaN/Infinity tokens as Python writes them; placeholders spliced in)."""
    return _splice(json.dumps(obj), quoted=True).encode("utf-8")


def dump_yaml(obj) -> str:
    """YAML text of ``obj`` with scipctl's dumper (``.nan``/``.inf``; a string quoted wherever a YAML 1.1 or 1.2
    reader would type it otherwise), non-ASCII escaped so that strings no UTF-8 file holds (a lone surrogate) are
    written too; placeholders spliced in."""
    return _splice(yaml.dump(obj, Dumper=PyYamlDumper, sort_keys=False, width=4096), quoted=False)


# --------------------------------------------------------------------------- images
PNG_ODDITIES = ("taller", "narrower", "colour", "alpha", "grey+alpha", "ihdr-size", "crc", "empty", "jpeg",
                "text", "tiny", "16-bit")


def _png_chunk(ctype: bytes, data: bytes) -> bytes:
    return struct.pack(">I", len(data)) + ctype + data + struct.pack(">I", zlib.crc32(ctype + data))


def odd_png(rng: np.random.Generator, width: int, height: int) -> tuple[bytes, str]:
    """Image bytes for a ``width`` x ``height`` single-channel product that are wrong in some way -> (bytes, kind).

    ``16-bit`` is the one harmless kind (a 16-bit image of the right size is valid).
    """
    import cv2

    kind = PNG_ODDITIES[int(rng.integers(len(PNG_ODDITIES)))]
    grey = rng.integers(0, 256, size=(height, width), dtype=np.uint8)
    if kind == "taller":
        return encode_png(np.vstack([grey, grey[:1]])), kind
    if kind == "narrower":
        return encode_png(grey[:, :-1]), kind
    if kind == "colour":
        return cv2.imencode(".png", np.dstack([grey] * 3))[1].tobytes(), kind
    if kind == "alpha":
        return cv2.imencode(".png", np.dstack([grey] * 4))[1].tobytes(), kind
    if kind == "grey+alpha":  # colour type 4, which OpenCV cannot write: built by hand
        raw = b"".join(b"\x00" + np.dstack([grey, grey])[y].tobytes() for y in range(height))
        return (b"\x89PNG\r\n\x1a\n" + _png_chunk(b"IHDR", struct.pack(">IIBBBBB", width, height, 8, 4, 0, 0, 0))
                + _png_chunk(b"IDAT", zlib.compress(raw)) + _png_chunk(b"IEND", b"")), kind
    if kind == "ihdr-size":  # the header claims another size; its CRC is made to match
        png = bytearray(encode_png(grey))
        png[16:24] = struct.pack(">II", width * 300, height * 300)
        png[29:33] = struct.pack(">I", zlib.crc32(bytes(png[12:29])))
        return bytes(png), kind
    if kind == "crc":
        png = bytearray(encode_png(grey))
        png[-5] ^= 0x01  # IEND's CRC
        return bytes(png), kind
    if kind == "empty":
        return b"", kind
    if kind == "jpeg":
        return cv2.imencode(".jpg", grey)[1].tobytes(), kind
    if kind == "text":
        return b"not an image\n", kind
    if kind == "tiny":
        return encode_png(grey[:1, :1]), kind
    if kind == "16-bit":
        return encode_png(grey.astype(np.uint16) * 257), kind
    raise ValueError(kind)


# --------------------------------------------------------------------------- the report
def error_problems(e) -> list:
    """What is wrong with the InputError ``e`` as a bad-input report ([] if nothing): it must print as one
    line (no line breaks or other control characters) naming a product or file and a field."""
    s = str(e)
    out = []
    if not (isinstance(e.product, str) and e.product.strip()):
        out.append(f"names no product or file ({e.product!r})")
    if not (isinstance(e.field, str) and e.field.strip()):
        out.append(f"names no field ({e.field!r})")
    if not s.isprintable():
        out.append("is not one printable line")
    return out
