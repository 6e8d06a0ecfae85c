"""Read a rules file (YAML): flight-rule limits and approach parameters (docs/sequence.md, "Rules file").

This module only reads and type-checks: the file must be a mapping of known sections, each a mapping of known
keys whose values have the kind the caller's spec names. Turning the values into the parameter dataclasses
(and their range checks) is ``scipctl.pipeline.rules``. Every error is an :class:`InputError` naming the file
and the key (``section.key``): one line, CLI exit 2.

YAML is read as ``downlink.yaml`` is (:func:`.downlink_dir.parse_yaml`: YAML 1.2's core schema, so ``1e-3`` is a
number, ``0010`` is 10, ``0o17`` 15, ``off``, ``2001-12-14``, ``12:30`` and ``1_000`` are strings; the same depth
limit, and a value Python cannot build, a 5000-digit integer, is an error naming the file). Kinds: ``number`` (int or
float, finite, not bool), ``number?`` (a number or null), ``int``, ``numbers`` (a list of numbers), ``camera_numbers`` /
``camera_ints`` (a mapping camera name -> number / int).
"""

from __future__ import annotations

import hashlib
import math
from dataclasses import dataclass
from pathlib import Path

from ..errors import InputError

DEFAULT_RULES_PATH = Path(__file__).resolve().parents[1] / "data" / "rules.yaml"
# built-in rules files, by the name ``--rules NAME`` gives (docs/sequence.md, "Rules file")
BUILTIN_RULES = {"default": DEFAULT_RULES_PATH, "m2020": DEFAULT_RULES_PATH.with_name("rules-m2020.yaml")}


def builtin_label(name: str) -> str:
    """How the built-in rules file ``name`` is named in messages and in the sequence's ``rules_used``."""
    return f"{name} (scipctl/data/{BUILTIN_RULES[name].name})"
KINDS = ("number", "number?", "int", "numbers", "camera_numbers", "camera_ints")
#: the cameras a per-camera mapping may name (the chain's: its steps look up these and no others)
RULE_CAMERAS = ("pancam", "navcam", "hazcam")


@dataclass(frozen=True)
class RulesFileContent:
    """A rules file as read: ``values[section][key]`` (only the keys the file gives), its label and SHA-256."""

    label: str  # the path as given, or "default (scipctl/data/rules.yaml)"
    sha256: str  # of the file's bytes
    values: dict


def read_rules_file(path, spec: dict, label: str | None = None) -> RulesFileContent:
    """Read and type-check ``path`` against ``spec`` (``{section: {key: kind}}``, kinds in :data:`KINDS`).

    A top-level ``version: 1`` is allowed (and no other version). :class:`InputError` naming the file and the
    key for an unreadable file, bad YAML, an unknown section or key, or a value of the wrong kind.
    """
    from .downlink_dir import parse_yaml  # YamlLoader, depth limit and errors, as downlink.yaml is read

    name = label or str(path)
    try:
        raw = Path(path).read_bytes()
    except OSError as e:
        raise InputError(name, "rules file", f"cannot read: {e.strerror or e}") from None
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as e:
        raise InputError(name, "rules file", f"not UTF-8 text: {e}") from None
    doc = parse_yaml(text, name, "rules file")
    if doc is None:
        doc = {}
    if not isinstance(doc, dict):
        raise InputError(name, "rules file", f"expected a mapping of sections, got {type(doc).__name__}")
    values = {}
    for section, body in doc.items():
        if section == "version":
            if body != 1 or isinstance(body, bool):
                raise InputError(name, "version", f"unsupported rules file version {body!r} (want 1)")
            continue
        if section not in spec:
            raise InputError(name, str(section), f"unknown section (known: version, {', '.join(spec)})")
        if body is None:
            body = {}
        if not isinstance(body, dict):
            raise InputError(name, str(section), f"expected a mapping of keys, got {type(body).__name__}")
        values[section] = {}
        for key, v in body.items():
            kind = spec[section].get(key)
            if kind is None:
                raise InputError(name, f"{section}.{key}", f"unknown key (known: {', '.join(spec[section])})")
            values[section][key] = _typed(name, f"{section}.{key}", kind, v)
    return RulesFileContent(name, hashlib.sha256(raw).hexdigest(), values)


def _is_number(v) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)


def _is_int(v) -> bool:
    return isinstance(v, int) and not isinstance(v, bool)


def _typed(name: str, key: str, kind: str, v):
    """``v`` checked against ``kind`` (lists become tuples, ints stay ints); InputError naming ``key``."""
    if kind == "number" and _is_number(v):
        return v
    if kind == "number?" and (v is None or _is_number(v)):
        return v
    if kind == "int" and _is_int(v):
        return v
    if kind == "numbers" and isinstance(v, list) and all(_is_number(x) for x in v):
        return tuple(v)
    if kind in ("camera_numbers", "camera_ints") and isinstance(v, dict):
        ok = _is_number if kind == "camera_numbers" else _is_int
        unknown = [k for k in v if k not in RULE_CAMERAS]
        if unknown:  # a typo or another camera would be carried in the rules record and never used
            return _bad(name, f"{key}.{unknown[0]}", f"unknown camera (want one of: {', '.join(RULE_CAMERAS)})")
        if all(isinstance(k, str) and ok(x) for k, x in v.items()):
            return dict(v)
    want = {"number": "a finite number", "number?": "a finite number or null", "int": "an integer",
            "numbers": "a list of finite numbers", "camera_numbers": "a mapping camera -> number",
            "camera_ints": "a mapping camera -> integer"}[kind]
    return _bad(name, key, f"must be {want}, got {v!r}")


def _bad(name, key, message):
    raise InputError(name, key, message)
