"""How an artifact was made: tool version, command line and the folder it ran in, input hashes, time."""

from __future__ import annotations

import datetime as _dt
import hashlib
import os
import shlex
import sys
from pathlib import Path

from .. import __version__


def sha256_file(path, chunk: int = 1 << 20) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        while True:
            b = f.read(chunk)
            if not b:
                break
            h.update(b)
    return h.hexdigest()


def sha256_path(path) -> str:
    """SHA-256 of a file, or of a directory's files (sorted relative paths and their contents)."""
    p = Path(path)
    if p.is_file():
        return sha256_file(p)
    h = hashlib.sha256()
    for f in sorted(q for q in p.rglob("*") if q.is_file() and not q.name.startswith(".")):
        rel = f.relative_to(p).as_posix()
        if rel.startswith("scipctl/"):  # a workspace's own products do not change its input identity
            continue
        h.update(rel.encode() + b"\0" + sha256_file(f).encode() + b"\n")
    return h.hexdigest()


def command_line() -> str:
    argv = list(sys.argv)
    if argv:
        argv[0] = os.path.basename(argv[0])
    return " ".join(shlex.quote(a) for a in argv)


def provenance(inputs: dict | None = None, deterministic: bool = False) -> dict:
    """A provenance record. ``inputs`` maps a label to a path (hashed) or to a precomputed hash string.

    ``cwd`` is the folder the command ran in (its relative paths are relative to it). With ``deterministic=True``
    the time and the folder are omitted (for byte-identical outputs, wherever the command is run from).
    """
    rec = {"tool": "scipctl", "version": __version__, "command": command_line(), "inputs": {}}
    if not deterministic:
        try:
            rec["cwd"] = os.getcwd()
        except OSError:  # the folder was removed under the command
            rec["cwd"] = None
    for label, val in (inputs or {}).items():
        if isinstance(val, (str, os.PathLike)) and Path(val).exists():
            rec["inputs"][label] = {"path": str(val), "sha256": sha256_path(val)}
        else:
            rec["inputs"][label] = {"sha256": str(val)}
    if not deterministic:
        rec["time_utc"] = _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")
    return rec
