"""Read and write JPL ``cmod`` camera-model text files (``.cahv``, ``.cahvor``, ``.cahvore``).

The layout is the one JPL's ``cmod_*_stdio.c`` and mrcal write::

    # comment
    Model = CAHVORE3,0.37 = general        # or CAHV / CAHVOR / CAHVORE1 / CAHVORE2
    Dimensions = 1024 1024                  # width height
    C = x y z
    A = ...   H = ...   V = ...   O = ...   R = ...   E = ...
    S =                                     # covariance: N numeric lines follow (ignored)
    Hs = ...  Hc = ...  Vs = ...  Vc = ...  Theta = ... (deg)   # derived; ignored on read
    S internal =                            # 5 numeric lines (ignored)

Reading tolerates comments, blank lines, covariance blocks, derived terms
and unknown ``key = value`` lines. Without a ``Model`` line the kind is
inferred from the vectors present (E -> CAHVORE type 1, O/R -> CAHVOR, else
CAHV). Writing uses ``repr`` floats (shortest exact form), so
``read_cmod(format_cmod(m))`` reproduces ``m`` to the bit.

Errors are :class:`scipctl.model.InputError` ``(file, field, message)``.
"""

from __future__ import annotations

import math
import os
import re
from pathlib import Path
from typing import Optional, Union

import numpy as np

from ..core.camera import CameraModel, CameraModelError
from ..model import InputError

_KEY_LINE = re.compile(r"^([A-Za-z][A-Za-z0-9_ ]*?)\s*=\s*(.*?)\s*$")
_NUMERIC_LINE = re.compile(r"^[\s0-9eE+\-.,]+$")
_VECTORS = ("C", "A", "H", "V", "O", "R", "E")
_KNOWN_SINGLE = set(_VECTORS) | {"Model", "Dimensions"}
_MODEL_RE = re.compile(r"^(CAHVORE|CAHVOR|CAHV)([0-9]*)\s*(?:,\s*([^\s=]+))?\s*(?:=.*)?$", re.IGNORECASE)

_MODEL_LINES = {
    "CAHV": "CAHV = perspective, linear",
    "CAHVOR": "CAHVOR = perspective, distortion",
    1: "CAHVORE1 = perspective, distortion, pupil",
    2: "CAHVORE2 = fish-eye",
}


def _fmt(x) -> str:
    """Shortest decimal form that reads back to the identical double."""
    return repr(float(x))


def _parse_numbers(name: str, field: str, text: str, n: int, kind=float) -> list:
    parts = text.replace(",", " ").split()
    if len(parts) != n:
        raise InputError(name, field, f"expected {n} numbers, got {len(parts)} ({text!r})")
    out = []
    for p in parts:
        try:
            val = kind(p)
        except ValueError:
            raise InputError(name, field, f"not a number: {p!r}") from None
        if kind is float and not math.isfinite(val):
            raise InputError(name, field, f"not finite: {p!r}")
        out.append(val)
    return out


def _parse_model_line(name: str, text: str) -> tuple[str, Optional[int], Optional[float]]:
    """``'CAHVORE3,0.37 = general'`` -> ``('CAHVORE', 3, 0.37)``."""
    m = _MODEL_RE.match(text.strip())
    if not m:
        raise InputError(name, "Model", f"unknown model {text!r} (want CAHV, CAHVOR, CAHVORE1, CAHVORE2 or CAHVORE3,<linearity>)")
    kind, digits, parm = m.group(1).upper(), m.group(2), m.group(3)
    if kind != "CAHVORE":
        if digits or parm:
            raise InputError(name, "Model", f"unexpected type/parameter on {kind}: {text!r}")
        return kind, None, None
    if not digits:
        raise InputError(name, "Model", f"CAHVORE needs a type (CAHVORE1, CAHVORE2 or CAHVORE3,<linearity>): {text!r}")
    mtype = int(digits)
    if mtype not in (1, 2, 3):
        raise InputError(name, "Model", f"CAHVORE type must be 1, 2 or 3, got {mtype}")
    lin = None
    if parm is not None:
        try:
            lin = float(parm)
        except ValueError:
            raise InputError(name, "Model", f"linearity is not a number: {parm!r}") from None
        if not math.isfinite(lin):
            raise InputError(name, "Model", f"linearity is not finite: {parm!r}")
    if mtype == 3 and lin is None:
        raise InputError(name, "Model", "CAHVORE3 needs a linearity: 'CAHVORE3,<linearity> = general'")
    if mtype in (1, 2) and lin is not None and lin != {1: 1.0, 2: 0.0}[mtype]:
        raise InputError(name, "Model", f"CAHVORE{mtype} implies linearity {'1' if mtype == 1 else '0'}, file says {lin!r}")
    return kind, mtype, lin


def _looks_like_path(x) -> bool:
    if isinstance(x, os.PathLike):
        return True
    return isinstance(x, str) and "\n" not in x and "=" not in x


def read_cmod(path_or_text: Union[str, os.PathLike], name: Optional[str] = None) -> tuple[CameraModel, Optional[tuple[int, int]]]:
    """Parse a JPL cmod file (a path, or the file's text) -> ``(CameraModel, (width, height) or None)``.

    ``name`` labels errors (default: the path, or ``"<cmod text>"``). Raises
    :class:`InputError` ``(name, field, message)`` for unreadable files,
    malformed lines, missing/conflicting vectors or a degenerate model.
    """
    if _looks_like_path(path_or_text):
        label = name or str(path_or_text)
        try:
            text = Path(path_or_text).read_text(encoding="utf-8-sig", errors="strict")
        except FileNotFoundError:
            raise InputError(label, "file", "no such file") from None
        except IsADirectoryError:
            raise InputError(label, "file", "is a directory, not a cmod file") from None
        except UnicodeDecodeError:
            raise InputError(label, "file", "not a text file") from None
        except ValueError as e:  # a NUL in the path
            raise InputError(label, "file", str(e)) from None
        except OSError as e:
            raise InputError(label, "file", e.strerror or str(e)) from None
    else:
        label = name or "<cmod text>"
        text = str(path_or_text)
    return _parse(text, label)


def _parse(text: str, name: str) -> tuple[CameraModel, Optional[tuple[int, int]]]:
    fields: dict[str, str] = {}
    current = None  # key whose numeric continuation lines we are in (covariance blocks)
    for lineno, raw in enumerate(text.splitlines(), start=1):
        line = raw.strip()
        if not line or line.startswith("#"):
            continue
        m = _KEY_LINE.match(line)
        if m:
            key = " ".join(m.group(1).split())
            value = m.group(2)
            # a trailing comment on a value line ("C = 1 2 3  # metres") is allowed
            if "#" in value:
                value = value.split("#", 1)[0].strip()
            key_norm = key.upper() if key.upper() in _VECTORS else key
            if key_norm.lower() == "model":
                key_norm = "Model"
            elif key_norm.lower() == "dimensions":
                key_norm = "Dimensions"
            if key_norm in _KNOWN_SINGLE:
                if key_norm in fields:
                    raise InputError(name, key_norm, f"given more than once (line {lineno})")
                fields[key_norm] = value
            current = key_norm
            continue
        if _NUMERIC_LINE.match(line) and current is not None:
            continue  # continuation of a block such as "S =" (covariance): ignored
        raise InputError(name, f"line {lineno}", f"cannot parse {line[:60]!r} (expected 'key = value')")

    for k in "CAHV":
        if k not in fields:
            raise InputError(name, k, "missing (every CAHV-family model needs C, A, H and V)")
    vec = {k: _parse_numbers(name, k, fields[k], 3) for k in _VECTORS if k in fields}

    if "Model" in fields:
        kind, mtype, lin = _parse_model_line(name, fields["Model"])
    else:  # infer from the vectors present
        kind = "CAHVORE" if "E" in vec else ("CAHVOR" if ("O" in vec or "R" in vec) else "CAHV")
        mtype, lin = (1, None) if kind == "CAHVORE" else (None, None)

    need = {"CAHV": "CAHV", "CAHVOR": "CAHVOR", "CAHVORE": "CAHVORE"}[kind]
    for k in need:
        if k not in vec:
            raise InputError(name, k, f"missing (required for {kind})")
    for k in _VECTORS:
        if k in vec and k not in need:
            raise InputError(name, k, f"present, but Model says {kind} (contradiction)")

    dims = None
    if "Dimensions" in fields:
        w, h = _parse_numbers(name, "Dimensions", fields["Dimensions"], 2, kind=float)
        if w != int(w) or h != int(h) or w <= 0 or h <= 0:
            raise InputError(name, "Dimensions", f"expected two positive integers, got {fields['Dimensions']!r}")
        dims = (int(w), int(h))

    try:
        model = CameraModel(
            kind,
            *(np.array(vec[k]) for k in "CAHV"),
            O=vec.get("O"),
            R=vec.get("R"),
            E=vec.get("E"),
            cahvore_type=mtype,
            linearity=lin,
        )
    except CameraModelError as e:
        raise InputError(name, e.field, _cm_message(e)) from None
    return model, dims


def _cm_message(e: CameraModelError) -> str:
    s = str(e)
    prefix = f"{e.field}: "
    return s[len(prefix):] if s.startswith(prefix) else s


def model_line(model: CameraModel) -> str:
    """The value of the ``Model =`` line for ``model`` (JPL spelling)."""
    if model.kind != "CAHVORE":
        return _MODEL_LINES[model.kind]
    if model.cahvore_type == 3:
        return f"CAHVORE3,{_fmt(model.linearity)} = general"
    return _MODEL_LINES[model.cahvore_type]


def format_cmod(model: CameraModel, width: Optional[int] = None, height: Optional[int] = None, comment: Optional[str] = None) -> str:
    """The cmod text for ``model`` (full precision). ``Dimensions`` is written when both sizes are given.

    Derived ``Hs``/``Hc``/``Vs``/``Vc``/``Theta`` lines are written for people
    (mrcal and JPL tools read them as-is; :func:`read_cmod` ignores them).
    """
    if (width is None) != (height is None):
        raise ValueError("format_cmod: give both width and height, or neither")
    lines = []
    if comment:
        lines += [f"# {c}" for c in str(comment).splitlines()]
    lines.append(f"Model = {model_line(model)}")
    if width is not None:
        w, h = int(width), int(height)
        if w <= 0 or h <= 0:
            raise ValueError(f"format_cmod: width/height must be positive, got {width}, {height}")
        lines.append(f"Dimensions = {w} {h}")
    for k in _VECTORS:
        val = getattr(model, k)
        if val is not None:
            lines.append(f"{k} = " + " ".join(_fmt(x) for x in val))
    th = model.theta_rad
    lines += [
        f"Hs = {_fmt(model.hs)}",
        f"Hc = {_fmt(model.hc)}",
        f"Vs = {_fmt(model.vs)}",
        f"Vc = {_fmt(model.vc)}",
        f"Theta = {_fmt(th)} ({math.degrees(th):.6f} deg)",
    ]
    return "\n".join(lines) + "\n"


def write_cmod(path, model: CameraModel, width: int, height: int, comment: Optional[str] = None) -> None:
    """Write ``model`` to ``path`` atomically (with ``Dimensions = width height``)."""
    from .atomic import atomic_write_text

    atomic_write_text(path, format_cmod(model, width, height, comment))


def cmod_suffix(model: CameraModel) -> str:
    """Conventional file suffix for ``model``: ``.cahv``, ``.cahvor`` or ``.cahvore``."""
    return "." + model.kind.lower()
