"""What code computed a saved result: a SHA-256 of the package's own files that computed it and of the libraries'
versions, so that a result saved by one command is taken back by another only when the same code would make it
again (the stereo self-calibration's fits, the chains a report takes from ``handoff.json``)."""

from __future__ import annotations

import hashlib
from functools import cache
from importlib import metadata
from pathlib import Path

__all__ = ["code_identity"]

PACKAGE = Path(__file__).resolve().parents[1]  # scipctl/
SUFFIXES = (".py", ".json", ".yaml")  # code, and the packaged models and rules
# the distributions whose numerics the results depend on (their versions, not their files)
LIBRARIES = ("numpy", "scipy", "opencv-python-headless", "open3d")


@cache
def code_identity(parts: tuple) -> str:
    """SHA-256 (hex) of every file (``.py``, ``.json``, ``.yaml``) under ``parts``, paths relative to the ``scipctl``
    package (folders, searched recursively, or single files), with each file's relative path, and of the installed
    versions of :data:`LIBRARIES`. ValueError naming a part that is not in the package."""
    h = hashlib.sha256()
    for part in parts:
        p = PACKAGE / part
        if p.is_dir():
            files = sorted(f for f in p.rglob("*") if f.is_file() and f.suffix in SUFFIXES
                           and "__pycache__" not in f.parts)
        elif p.is_file():
            files = [p]
        else:
            raise ValueError(f"code_identity: {part!r} is not a file or folder of the scipctl package")
        for f in files:
            h.update(f.relative_to(PACKAGE).as_posix().encode() + b"\0" + f.read_bytes() + b"\0")
    for lib in LIBRARIES:
        try:
            version = metadata.version(lib)
        except metadata.PackageNotFoundError:
            version = "absent"
        h.update(f"{lib} {version}\n".encode())
    return h.hexdigest()
