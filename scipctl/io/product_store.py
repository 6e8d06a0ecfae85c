"""Where the products of one source (workspace or raw downlink) are read from and written to (docs/workspace.md).

A source's products (``targets.json``, ``handoff.json``, ...) have a **home**:
``WS/scipctl/`` for a workspace, the sidecar ``<SRC>.scipctl/`` next to a raw
downlink. Two other places may hold them:

- an **explicit root** given by the operator (``--products-dir DIR`` or
  ``SCIPCTL_PRODUCTS_DIR``): products then go to ``DIR/<key>/``;
- the **per-user fallback** for a raw downlink whose folder is not writable
  (read-only archives): ``$XDG_DATA_HOME/scipctl/sidecars/<key>/``
  (``~/.local/share/...`` when ``XDG_DATA_HOME`` is unset or not absolute).

``<key>`` is ``<source name>-<first 12 hex digits of the SHA-256 of the
resolved source path>``, so two downlinks with the same name in different
folders never share products.

Writing: the explicit root if given; else the home if it is writable; else,
for a raw downlink, the per-user fallback (also when a write to the home
fails with EACCES/EPERM/EROFS although the access check allowed it). A
workspace whose ``scipctl/`` is not writable is an error (exit 2) that says to
make it writable or to give ``--products-dir``: a workspace is the operator's
working copy, and its products are not scattered silently into a cache.

Reading: every place that may hold the product is looked at; when several
hold a copy, the most recently written one (modification time) is used, so a
product is found wherever it was last written.
"""

from __future__ import annotations

import errno
import hashlib
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Optional

from ..model import InputError

# errno values that mean "this place is not writable" (the write may go to the per-user fallback instead)
UNWRITABLE_ERRNOS = frozenset({errno.EACCES, errno.EPERM, errno.EROFS})
ENV_PRODUCTS_DIR = "SCIPCTL_PRODUCTS_DIR"
HOW_TO_REDIRECT = f"give --products-dir DIR (or set {ENV_PRODUCTS_DIR}) to write products elsewhere"


#: the longest file name most file systems take (bytes)
NAME_MAX_BYTES = 255
#: a key keeps at most this much of the source's name (bytes), so that the key itself is a valid file name (the
#: 13 bytes of "-<digest>" after it); every key that was a valid name before the cut is unchanged
KEY_NAME_MAX_BYTES = NAME_MAX_BYTES - 13


def source_key(src) -> str:
    """``<name>-<12 hex digits of sha256(resolved path)>``: the folder name of a source's products outside its home
    (a name longer than :data:`KEY_NAME_MAX_BYTES` bytes is cut there; the digest keeps keys apart)."""
    resolved = Path(src).resolve()
    digest = hashlib.sha256(str(resolved).encode("utf-8", "surrogateescape")).hexdigest()[:12]
    name = (resolved.name or "root").encode("utf-8", "surrogateescape")[:KEY_NAME_MAX_BYTES]
    return f"{name.decode('utf-8', 'ignore')}-{digest}"


def name_too_long(path: Path) -> bool:
    """Whether ``path``'s last component is longer than a file name may be (:data:`NAME_MAX_BYTES`)."""
    return len(Path(path).name.encode("utf-8", "surrogateescape")) > NAME_MAX_BYTES


def user_fallback_root() -> Optional[Path]:
    """``$XDG_DATA_HOME/scipctl/sidecars`` (``~/.local/share/scipctl/sidecars`` when unset or relative);
    a data folder, not a cache: designations are operator work, and caches get cleaned;
    None when there is no home directory to put it in."""
    base = os.environ.get("XDG_DATA_HOME", "")
    if base and os.path.isabs(base):
        return Path(base) / "scipctl" / "sidecars"
    try:
        return Path.home() / ".local" / "share" / "scipctl" / "sidecars"
    except (RuntimeError, KeyError):
        return None


def is_writable_dir(path: Path) -> bool:
    """Whether files can be created in directory ``path``: if it does not exist yet, whether its nearest
    existing ancestor is a directory that lets us create it. Checked with ``os.access`` (no trial write)."""
    try:
        p = nearest_existing(path)
        return p.exists() and p.is_dir() and os.access(p, os.W_OK | os.X_OK)
    except OSError:  # e.g. ENAMETOOLONG: a name the file system cannot hold is no place to write
        return False


def nearest_existing(path) -> Path:
    """``path`` itself if it exists, else its nearest existing ancestor (the root when none exists)."""
    p = Path(path)
    while not p.exists() and p.parent != p:
        p = p.parent
    return p


def is_unwritable_error(e: OSError) -> bool:
    return e.errno in UNWRITABLE_ERRNOS


@dataclass(frozen=True)
class ProductPlaces:
    """The places one source's products may live in.

    ``home``: ``WS/scipctl`` or ``<SRC>.scipctl``. ``explicit``: ``DIR/<key>`` when the operator gave a
    products directory, else None. ``fallback``: the per-user directory for a raw downlink, None for a
    workspace (which never falls back).
    """

    source: Path
    home: Path
    explicit: Optional[Path]
    fallback: Optional[Path]
    is_workspace: bool = False

    @classmethod
    def for_source(cls, source, home, is_workspace: bool, products_root=None) -> "ProductPlaces":
        source = Path(source)
        key = source_key(source)
        explicit = None
        if products_root is not None:
            root = Path(products_root)
            if root.exists() and not root.is_dir():
                raise InputError(str(root), "products-dir", "exists and is not a directory")
            explicit = root / key
        fallback_root = None if is_workspace else user_fallback_root()
        fallback = None if fallback_root is None else fallback_root / key
        return cls(source=source, home=Path(home), explicit=explicit, fallback=fallback, is_workspace=is_workspace)

    def readable(self) -> list[Path]:
        """Every place that may hold products, in order of preference when two copies are equally new."""
        return [d for d in (self.explicit, self.home, self.fallback) if d is not None]

    def find(self, name: str) -> Optional[Path]:
        """The most recently written copy of product ``name`` (a plain file name), or None if there is none."""
        best, best_mtime = None, None
        for d in self.readable():
            f = d / name
            try:
                st = f.stat()
            except OSError:
                continue
            if not f.is_file():
                continue
            if best is None or st.st_mtime_ns > best_mtime:
                best, best_mtime = f, st.st_mtime_ns
        return best

    def names(self) -> list[str]:
        """Names of the plain files in every place (sorted, each once), dot-files excluded."""
        out = set()
        for d in self.readable():
            try:
                out.update(p.name for p in d.iterdir() if p.is_file() and not p.name.startswith("."))
            except OSError:
                continue
        return sorted(out)

    def write_target(self) -> tuple[Path, Optional[str]]:
        """(directory new products go to, why it is not the home, or None). InputError if nowhere is writable."""
        if self.explicit is not None:
            if not is_writable_dir(self.explicit):
                raise InputError(str(self.explicit), "products-dir", "not writable; choose another --products-dir "
                                 f"(or {ENV_PRODUCTS_DIR})")
            return self.explicit, "--products-dir / " + ENV_PRODUCTS_DIR
        if is_writable_dir(self.home):
            return self.home, None
        if name_too_long(self.home):
            return self.fallback_target(why=f"{self.home.name[:40]}... is longer than a file name may be")
        return self.fallback_target()

    def fallback_target(self, detail: str = "", why: Optional[str] = None) -> tuple[Path, str]:
        """The per-user fallback (raw downlinks), or InputError naming the home when there is none. ``why``: the
        reason the home cannot be used, when it is not that its folder is unwritable."""
        if why is not None:
            detail = f" ({why})"
        if self.is_workspace:
            raise InputError(str(self.home), "products", f"workspace products folder is not writable{detail}; "
                             f"make it writable, or {HOW_TO_REDIRECT}")
        if self.fallback is None:  # no home directory for the per-user fallback
            raise InputError(str(self.home), "products", f"not writable{detail} and no per-user fallback "
                             f"(no home directory); {HOW_TO_REDIRECT}")
        if not is_writable_dir(self.fallback):
            raise InputError(str(self.fallback), "products",
                             f"neither {self.home} nor the per-user fallback is writable; {HOW_TO_REDIRECT}")
        return self.fallback, why or f"{self.home.parent} is not writable{detail}"
