"""Workspaces: an ingested downlink plus the products scipctl makes from it (docs/workspace.md).

Layout::

    WS/downlink.yaml, WS/images/*.png     # a container-B downlink (WS is itself a valid downlink)
    WS/scipctl/workspace.json             # marker + provenance + ingest summary
    WS/scipctl/<name>.json                # products of other commands (e.g. targets.json)

A raw downlink (an ``.mcap`` file, or a downlink directory that was not made
by ``scipctl ingest``) can be used directly; its products then live in a
sidecar directory ``<SRC>.scipctl/`` next to it (``sol42.mcap.scipctl/``),
so the input is never modified.

API::

    create_workspace(dl, out, summary=None) -> Path     # atomic
    open_source(path) -> Source
    Source.downlink / .path / .workspace_dir / .products_dir
    Source.load_json(name, default=None) / .save_json(name, obj)
"""

from __future__ import annotations

import json
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Optional

from ..model import Downlink, InputError
from ..jsonutil import json_default

WORKSPACE_FORMAT = 1
PRODUCTS_DIR = "scipctl"
MARKER = "workspace.json"
SIDECAR_SUFFIX = ".scipctl"
_NAME_RE = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._\-]*$")


def is_workspace(path) -> bool:
    p = Path(path)
    return p.is_dir() and (p / PRODUCTS_DIR / MARKER).is_file()


_json_default = json_default


def dumps(obj) -> str:
    return json.dumps(obj, indent=2, sort_keys=True, default=_json_default, allow_nan=False) + "\n"


def create_workspace(dl: Downlink, out, summary: Optional[dict] = None, source_path=None) -> Path:
    """Write ``dl`` as a workspace at ``out`` (atomically; replaces an existing workspace, refuses anything else).

    ``workspace.json`` records ``provenance`` (tool, version, command line,
    the source path and SHA-256, time), the source container and ``summary``.
    """
    from .atomic import atomic_directory
    from .downlink_dir import check_replaceable, write_dir_contents
    from .provenance import provenance

    out = Path(out)
    check_replaceable(out, "a scipctl workspace", f"{PRODUCTS_DIR}/{MARKER}")
    src = str(source_path if source_path is not None else dl.source)
    prov = provenance({"downlink": dl.source_sha256})  # hash already computed while reading
    prov["inputs"]["downlink"]["path"] = src
    doc = {
        "scipctl_workspace": WORKSPACE_FORMAT,
        "source": {"path": src, "sha256": dl.source_sha256},
        "provenance": prov,
        "summary": summary or {},
    }
    text = dumps(doc)
    with atomic_directory(out) as tmp:
        write_dir_contents(dl, tmp)
        (tmp / PRODUCTS_DIR).mkdir()
        (tmp / PRODUCTS_DIR / MARKER).write_text(text, encoding="utf-8")
    return out


def sidecar_dir(src) -> Path:
    """Where products for a raw downlink ``src`` live: ``<src>.scipctl/`` next to it."""
    p = Path(src)
    return p.parent / (p.name + SIDECAR_SUFFIX)


@dataclass
class Source:
    """A downlink opened for a command: the downlink, and where the command's products go."""

    downlink: Downlink
    path: Path
    workspace_dir: Optional[Path]  # None for a raw downlink

    @property
    def is_workspace(self) -> bool:
        return self.workspace_dir is not None

    @property
    def products_dir(self) -> Path:
        """``WS/scipctl/`` for a workspace, ``<SRC>.scipctl/`` for a raw downlink (may not exist yet)."""
        if self.workspace_dir is not None:
            return self.workspace_dir / PRODUCTS_DIR
        return sidecar_dir(self.path)

    def _file(self, name: str) -> Path:
        if not isinstance(name, str) or not _NAME_RE.match(name) or name == MARKER:
            raise InputError(str(name), "name", "product names are plain file names (letters, digits, . _ -), not workspace.json")
        return self.products_dir / name

    def load_json(self, name: str, default: Any = None) -> Any:
        """The JSON product ``name`` (e.g. ``"targets.json"``), or ``default`` if there is none yet."""
        f = self._file(name)
        try:
            text = f.read_text(encoding="utf-8")
        except FileNotFoundError:
            return default
        except (OSError, UnicodeDecodeError) as e:
            raise InputError(str(f), "file", f"cannot read: {getattr(e, 'strerror', None) or e}") from None
        try:
            return json.loads(text)
        except json.JSONDecodeError as e:
            raise InputError(str(f), "json", f"malformed JSON ({e})") from None

    def save_json(self, name: str, obj: Any) -> Path:
        """Write ``obj`` as the JSON product ``name`` atomically; returns the path."""
        from .atomic import atomic_write_text

        f = self._file(name)
        try:
            atomic_write_text(f, dumps(obj))
        except OSError as e:
            raise InputError(str(f), "file", f"cannot write: {e.strerror or e}") from None
        return f

    def workspace_info(self) -> Optional[dict]:
        """The parsed ``workspace.json`` (None for a raw downlink)."""
        if self.workspace_dir is None:
            return None
        f = self.workspace_dir / PRODUCTS_DIR / MARKER
        try:
            return json.loads(f.read_text(encoding="utf-8"))
        except (OSError, UnicodeDecodeError, json.JSONDecodeError) as e:
            raise InputError(str(f), "json", f"unreadable workspace marker ({e})") from None


def open_source(path, validate: bool = True) -> Source:
    """Open a workspace or a raw downlink (``.mcap`` or directory); reads and validates the downlink."""
    from .downlink import read_downlink

    p = Path(path)
    dl = read_downlink(p, validate=validate)
    ws = p if is_workspace(p) else None
    return Source(downlink=dl, path=p, workspace_dir=ws)
