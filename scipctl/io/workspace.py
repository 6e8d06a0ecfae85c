"""Workspaces: an ingested downlink plus the products scipctl makes from it (docs/workspace.md).

Layout::

    WS/downlink.yaml, WS/images/*.png     # a container-B downlink (WS is itself a valid downlink)
    WS/scipctl/workspace.json             # marker + provenance + ingest summary
    WS/scipctl/<name>.json                # products of other commands (e.g. targets.json)

A raw downlink (an ``.mcap`` file, or a downlink directory that was not made
by ``scipctl ingest``) can be used directly; its products then live in a
sidecar directory ``<SRC>.scipctl/`` next to it (``sol42.mcap.scipctl/``),
so the input is never modified. When that folder is not writable, or the
operator gives ``--products-dir``, they live elsewhere (``product_store``).

API::

    create_workspace(dl, out, summary=None) -> Path     # atomic
    open_source(path, products_root=None) -> Source
    Source.downlink / .path / .workspace_dir / .home_products_dir / .products_dir
    Source.load_json(name, default=None) / .save_json(name, obj) / .product_path(name) / .location_note()
"""

from __future__ import annotations

import json
import re
from dataclasses import dataclass, field
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
    """The home of a raw downlink ``src``'s products: ``<src>.scipctl/`` next to it (see product_store for the others)."""
    p = Path(src)
    return p.parent / (p.name + SIDECAR_SUFFIX)


@dataclass
class Source:
    """A downlink opened for a command: the downlink, and where the command's products are read and written.

    ``products_root``: the operator's ``--products-dir`` (or ``SCIPCTL_PRODUCTS_DIR``), None if not given.
    ``read_from`` / ``written_to`` map product names to the files this object read or wrote.
    """

    downlink: Downlink
    path: Path
    workspace_dir: Optional[Path]  # None for a raw downlink
    products_root: Optional[Path] = None
    read_from: dict = field(default_factory=dict)
    written_to: dict = field(default_factory=dict)
    _note: Optional[str] = field(default=None, repr=False)

    @property
    def is_workspace(self) -> bool:
        return self.workspace_dir is not None

    @property
    def home_products_dir(self) -> Path:
        """``WS/scipctl/`` for a workspace, ``<SRC>.scipctl/`` for a raw downlink (may not exist yet)."""
        if self.workspace_dir is not None:
            return self.workspace_dir / PRODUCTS_DIR
        return sidecar_dir(self.path)

    @property
    def places(self):
        """The :class:`~scipctl.io.product_store.ProductPlaces` of this source (home, explicit, fallback)."""
        from .product_store import ProductPlaces

        return ProductPlaces.for_source(self.path, self.home_products_dir, self.is_workspace, self.products_root)

    @property
    def products_dir(self) -> Path:
        """Where new products go: the ``--products-dir`` folder if given, else the home if writable, else
        (raw downlink) the per-user fallback. Never raises: when nowhere is writable this is the home, and
        :meth:`check_writable` / :meth:`save_json` say why."""
        places = self.places
        try:
            return places.write_target()[0]
        except InputError:
            return places.explicit or places.home

    def check_writable(self) -> Path:
        """The directory new products will go to; InputError (exit 2) naming the path if none is writable.
        Commands that write products call this before their work."""
        return self.places.write_target()[0]

    def _name(self, name: str) -> str:
        if not isinstance(name, str) or not _NAME_RE.match(name) or name == MARKER:
            raise InputError(str(name), "name", "product names are plain file names (letters, digits, . _ -), not workspace.json")
        return name

    def product_path(self, name: str) -> Optional[Path]:
        """The file product ``name`` is read from (its most recently written copy), or None if there is none."""
        return self.places.find(self._name(name))

    def product_names(self) -> list:
        """Names of the products present in any of this source's places (workspace.json excluded)."""
        return [n for n in self.places.names() if n != MARKER and _NAME_RE.match(n)]

    def load_json(self, name: str, default: Any = None) -> Any:
        """The JSON product ``name`` (e.g. ``"targets.json"``), or ``default`` if there is none yet."""
        f = self.product_path(name)
        if f is None:
            return default
        try:
            text = f.read_text(encoding="utf-8")
        except FileNotFoundError:
            return default
        except (OSError, UnicodeDecodeError) as e:
            raise InputError(str(f), "file", f"cannot read: {getattr(e, 'strerror', None) or e}") from None
        try:
            doc = json.loads(text)
        except json.JSONDecodeError as e:
            raise InputError(str(f), "json", f"malformed JSON ({e})") from None
        self.read_from[name] = f
        return doc

    def save_json(self, name: str, obj: Any) -> Path:
        """Write ``obj`` as the JSON product ``name`` atomically (see :meth:`products_dir` for where); returns the path.

        A raw downlink whose home refuses the write (EACCES, EPERM, EROFS) falls back to the per-user folder.
        """
        from .atomic import atomic_write_text
        from .product_store import is_unwritable_error

        name = self._name(name)
        text = dumps(obj)
        places = self.places
        target, why = places.write_target()
        try:
            atomic_write_text(target / name, text)
        except OSError as e:
            if not (target == places.home and is_unwritable_error(e)):
                raise InputError(str(target / name), "file", f"cannot write: {e.strerror or e}") from None
            target, why = places.fallback_target(f" ({e.strerror or e})")
            try:
                atomic_write_text(target / name, text)
            except OSError as e2:
                raise InputError(str(target / name), "file", f"cannot write: {e2.strerror or e2}") from None
        f = target / name
        self.written_to[name] = f
        if why is not None:
            self._note = f"products of {self.path} go to {target}/ ({why})"
        return f

    def location_note(self) -> Optional[str]:
        """One line saying where products went when that is not their home (None when they went home)."""
        return self._note

    def workspace_info(self) -> Optional[dict]:
        """The parsed ``workspace.json`` (None for a raw downlink)."""
        if self.workspace_dir is None:
            return None
        return read_marker(self.workspace_dir)


def read_marker(ws) -> dict:
    """The parsed ``WS/scipctl/workspace.json``; InputError if unreadable."""
    f = Path(ws) / PRODUCTS_DIR / MARKER
    try:
        return json.loads(f.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as e:
        raise InputError(str(f), "json", f"unreadable workspace marker ({e})") from None


def open_source(path, validate: bool = True, products_root=None) -> Source:
    """Open a workspace or a raw downlink (``.mcap`` or directory); reads and validates the downlink.

    ``products_root``: the operator's products directory (``--products-dir``), None for the usual places.
    """
    from .downlink import read_downlink

    p = Path(path)
    dl = read_downlink(p, validate=validate)
    ws = p if is_workspace(p) else None
    source = Source(downlink=dl, path=p, workspace_dir=ws, products_root=None if products_root is None else Path(products_root))
    source.places  # noqa: B018  (checks --products-dir now: InputError if it is a file)
    return source
