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

Re-ingesting onto an existing workspace keeps its products when the downlink
is the same, and refuses (or, forced, sets them aside) when it is not.

API::

    create_workspace(dl, out, summary=None, source_path=None, force=False) -> Path   # atomic
    write_workspace(...) -> WorkspaceWritten     # the same, and what was kept / set aside
    open_source(path, products_root=None) -> Source
    Source.downlink / .path / .workspace_dir / .home_products_dir / .products_dir
    Source.load_json(name, default=None) / .save_json(name, obj) / .product_path(name) / .location_note()
"""

from __future__ import annotations

import json
import os
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Optional

from ..model import Downlink, InputError
from ..jsonutil import json_default

WORKSPACE_FORMAT = 1
PRODUCTS_DIR = "scipctl"
MARKER = "workspace.json"
SIDECAR_SUFFIX = ".scipctl"
SUPERSEDED_PREFIX = "superseded-"  # WS/scipctl/superseded-<UTC time>/: products set aside by ingest --force
_NAME_RE = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._\-]*$")


def is_workspace(path) -> bool:
    p = Path(path)
    return p.is_dir() and (p / PRODUCTS_DIR / MARKER).is_file()


_json_default = json_default


def dumps(obj) -> str:
    return json.dumps(obj, indent=2, sort_keys=True, default=_json_default, allow_nan=False) + "\n"


@dataclass
class WorkspaceWritten:
    """What :func:`write_workspace` did.

    ``kept_products``: names of the entries of the previous ``WS/scipctl/`` carried into the new workspace
    (all but ``workspace.json``). ``superseded_products``: names set aside (``--force`` onto a workspace made
    from a different downlink) into ``superseded_dir`` (``WS/scipctl/superseded-<UTC time>/``).
    ``previous_source``: the ``source`` record of the replaced workspace (None for a new one).
    """

    path: Path
    replaced: bool
    kept_products: list
    superseded_products: list
    superseded_dir: Optional[Path]
    previous_source: Optional[dict]


def create_workspace(dl: Downlink, out, summary: Optional[dict] = None, source_path=None, force: bool = False) -> Path:
    """Write ``dl`` as a workspace at ``out``; returns ``out``. See :func:`write_workspace`."""
    return write_workspace(dl, out, summary, source_path=source_path, force=force).path


def write_workspace(dl: Downlink, out, summary: Optional[dict] = None, source_path=None,
                    force: bool = False) -> WorkspaceWritten:
    """Write ``dl`` as a workspace at ``out``, atomically (docs/workspace.md, "Rules").

    ``out`` may be missing, an empty directory or an existing workspace; anything else is refused. The
    products of an existing workspace (everything in ``WS/scipctl/`` but ``workspace.json``) are carried
    into the new one when it holds the same downlink: re-ingest in place, the same source SHA-256 as
    recorded, or byte-identical downlink files. Otherwise InputError (nothing changed), unless ``force``:
    then the old products are moved to ``WS/scipctl/superseded-<UTC time>/`` with the old marker.

    ``workspace.json`` records ``provenance`` (tool, version, command line, the source path and SHA-256,
    time), the source, ``summary``, ``kept_products`` and, after ``force``, what was superseded.
    """
    from .atomic import atomic_directory, recover_interrupted
    from .downlink_dir import check_replaceable, write_dir_contents
    from .provenance import provenance

    out = Path(out)
    recover_interrupted(out)  # a replacement killed between its renames: the previous workspace, with its products
    check_replaceable(out, "a scipctl workspace", f"{PRODUCTS_DIR}/{MARKER}")
    if not out.exists():
        from .product_store import nearest_existing

        if not nearest_existing(out.parent).is_dir():  # `-o FILE/ws`: the mkdir's "File exists" named nothing
            raise InputError(str(out), "output", f"cannot write the workspace: {nearest_existing(out.parent)} is "
                             "not a folder; nothing was changed")
    src = str(source_path if source_path is not None else dl.source)
    replaced = is_workspace(out)
    entries = _product_entries(out) if replaced else []
    previous = None
    if replaced:
        try:
            previous = read_marker(out).get("source")
        except (InputError, AttributeError):
            previous = None
    prov = provenance({"downlink": dl.source_sha256})  # hash already computed while reading
    prov["inputs"]["downlink"]["path"] = src
    doc = {
        "scipctl_workspace": WORKSPACE_FORMAT,
        "source": {"path": src, "sha256": dl.source_sha256},
        "provenance": prov,
        "summary": summary or {},
    }
    done = WorkspaceWritten(out, replaced, [], [], None, previous if isinstance(previous, dict) else None)
    try:
        with atomic_directory(out) as tmp:
            write_dir_contents(dl, tmp)
            (tmp / PRODUCTS_DIR).mkdir()
            live = [n for n in entries if not _is_superseded(out, n)]  # products commands still read
            if entries:
                if not live or _same_downlink(dl, out, tmp, source_path, done.previous_source):
                    _carry(out, tmp, entries, done.kept_products)
                elif not force:
                    raise InputError(str(out), "source", _different_message(out, src, done.previous_source, live))
                else:
                    _supersede(out, tmp, entries, live, done)
            doc["kept_products"] = done.kept_products
            if done.superseded_dir is not None:
                doc["superseded"] = {"dir": done.superseded_dir.name, "products": done.superseded_products,
                                     "previous_source": done.previous_source}
            (tmp / PRODUCTS_DIR / MARKER).write_text(dumps(doc), encoding="utf-8")
    except OSError as e:  # named by the workspace asked for, not by the temporary folder beside it
        raise InputError(str(out), "output", f"cannot write the workspace: {e.strerror or e}; nothing was changed") from None
    if done.superseded_dir is not None:
        done.superseded_dir = out / PRODUCTS_DIR / done.superseded_dir.name
    return done


def _product_entries(ws: Path) -> list:
    """Names of everything in ``WS/scipctl/`` except the marker (products, and folders such as superseded-*)."""
    try:
        return sorted(p.name for p in (ws / PRODUCTS_DIR).iterdir() if p.name != MARKER)
    except OSError as e:
        raise InputError(str(ws / PRODUCTS_DIR), "products", f"cannot list: {e.strerror or e}") from None


def _same_downlink(dl: Downlink, out: Path, new_tmp: Path, source_path, previous: Optional[dict]) -> bool:
    """Whether the workspace at ``out`` holds the downlink ``dl`` (so its products stay valid)."""
    from .provenance import sha256_path

    if source_path is not None and Path(source_path).resolve() == out.resolve():
        return True  # re-ingest in place
    if previous and previous.get("sha256") == dl.source_sha256:
        return True  # the same source file or directory as last time
    return sha256_path(new_tmp) == sha256_path(out)  # the same downlink from another container / path


def _copy_entry(src: Path, dst: Path) -> None:
    import shutil

    if src.is_dir() and not src.is_symlink():
        shutil.copytree(src, dst, symlinks=True)
    else:
        shutil.copy2(src, dst, follow_symlinks=False)


def _carry(out: Path, tmp: Path, names: list, kept: list) -> None:
    for n in names:
        _copy_entry(out / PRODUCTS_DIR / n, tmp / PRODUCTS_DIR / n)
        kept.append(n)


def _is_superseded(ws: Path, name: str) -> bool:
    return name.startswith(SUPERSEDED_PREFIX) and (ws / PRODUCTS_DIR / name).is_dir()


def _supersede(out: Path, tmp: Path, entries: list, live: list, done: WorkspaceWritten) -> None:
    """Move (copy, inside the atomic swap) the ``live`` products to ``superseded-<UTC time>/`` with the old
    marker; earlier superseded folders are carried as they are."""
    import datetime as _dt

    _carry(out, tmp, [n for n in entries if n not in live], done.kept_products)
    stamp = _dt.datetime.now(_dt.timezone.utc).strftime("%Y%m%dT%H%M%SZ")
    name, i = SUPERSEDED_PREFIX + stamp, 1
    while name in entries:
        i += 1
        name = f"{SUPERSEDED_PREFIX}{stamp}-{i}"
    sup = tmp / PRODUCTS_DIR / name
    sup.mkdir()
    for n in live:
        _copy_entry(out / PRODUCTS_DIR / n, sup / n)
        done.superseded_products.append(n)
    if (out / PRODUCTS_DIR / MARKER).is_file():
        _copy_entry(out / PRODUCTS_DIR / MARKER, sup / MARKER)
    done.superseded_dir = sup


def _different_message(out: Path, src: str, previous: Optional[dict], entries: list) -> str:
    was = "an unknown downlink"
    if previous:
        was = f"{previous.get('path', '?')} (sha256 {str(previous.get('sha256', '?'))[:12]}...)"
    return (f"was made from a different downlink, {was}, and holds products ({', '.join(entries)}) that may not be "
            f"valid for {src}; nothing was changed. Use --force to replace it (its products are then set aside in "
            f"{out / PRODUCTS_DIR}/{SUPERSEDED_PREFIX}<UTC time>/), or ingest to another -o")


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

    def update_json(self, name: str, update: Callable[[Any], Any], default: Any = None) -> tuple:
        """Read the JSON product ``name`` (``default`` when there is none), pass it to ``update`` and save what
        that returns, holding an exclusive lock (``fcntl.flock`` on the folder products go to: no lock file is
        left behind) from the read to the write, so that two commands updating one product (two ``designate``
        runs on a workspace) see each other's changes instead of one losing the other's. Returns ``(path, the
        saved document)``. Without a folder to lock the update runs unlocked and the save says why."""
        import fcntl

        name = self._name(name)
        lock_fd = None
        try:
            folder, _ = self.places.write_target()
            folder.mkdir(parents=True, exist_ok=True)
            lock_fd = os.open(folder, os.O_RDONLY)
            fcntl.flock(lock_fd, fcntl.LOCK_EX)
        except (OSError, InputError):
            if lock_fd is not None:
                os.close(lock_fd)
            lock_fd = None
        try:
            doc = update(self.load_json(name, default=default))
            return self.save_json(name, doc), doc
        finally:
            if lock_fd is not None:
                fcntl.flock(lock_fd, fcntl.LOCK_UN)
                os.close(lock_fd)

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
        doc = json.loads(f.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as e:
        raise InputError(str(f), "json", f"unreadable workspace marker ({e})") from None
    if not isinstance(doc, dict):
        raise InputError(str(f), "json", f"unreadable workspace marker (a JSON {type(doc).__name__}, not an object)")
    return doc


def open_source(path, validate: bool = True, products_root=None) -> Source:
    """Open a workspace or a raw downlink (``.mcap`` or directory); reads and validates the downlink.

    ``products_root``: the operator's products directory (``--products-dir``), None for the usual places.
    """
    from .downlink import read_downlink

    p = Path(path)
    ws = p if is_workspace(p) else None
    if ws is not None:
        read_marker(ws)  # a damaged workspace is refused by every command, as `info` refuses it
    dl = read_downlink(p, validate=validate)
    source = Source(downlink=dl, path=p, workspace_dir=ws, products_root=None if products_root is None else Path(products_root))
    source.places  # noqa: B018  (checks --products-dir now: InputError if it is a file)
    return source
