"""Write outputs all-or-nothing: to a temporary path beside the target, then rename."""

from __future__ import annotations

import contextlib
import os
import shutil
import tempfile
from pathlib import Path


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def _refuse_stdout(path, option: str) -> None:
    """``-``, the usual name for standard output, is not taken for a file of that name in the current folder."""
    from ..errors import InputError

    if str(path) == "-":
        raise InputError("-", option, "standard output is not an output file here; give a file path "
                         "(--json prints the machine-readable answer on stdout)")


def check_output_file(path, option: str = "-o") -> Path:
    """``path`` as a :class:`Path` if a file can be written there (not a directory; its folder, or the nearest
    existing ancestor that would hold it, writable), else :class:`InputError` naming ``path`` and ``option``.
    Commands call it before their work, so a bad output path costs nothing; the write itself can still fail
    (a full disk), and callers map that to the same error."""
    from ..errors import InputError
    from .product_store import is_writable_dir, nearest_existing

    _refuse_stdout(path, option)
    path = Path(path)
    if path.is_dir():
        raise InputError(str(path), option, "is a directory; give the file to write")
    if not is_writable_dir(path.parent):
        raise InputError(str(path), option, f"cannot write here: {nearest_existing(path.parent)} is not a "
                         "writable folder")
    return path


def check_not_input(out, src, option: str = "-o", products_root=None) -> None:
    """:class:`InputError` when the output file ``out`` is the input ``src`` itself, a file of a directory input
    (its ``downlink.yaml``, anything under its ``images/`` or ``scipctl/``), or a file in any other place that holds
    the source's products (a raw downlink's sidecar ``<SRC>.scipctl/``, ``DIR/<key>/`` of ``--products-dir DIR``
    given as ``products_root``, the per-user fallback ``.../sidecars/<key>/``): writing there would replace the
    downlink (or its products) with the command's output. Other files in a workspace (e.g. ``WS/report.html``,
    written again by the next run) are allowed."""
    from ..errors import InputError
    from .product_store import source_key, user_fallback_root

    o, s = Path(out).resolve(), Path(src).resolve()
    rel = o.relative_to(s).parts if s.is_dir() and o.is_relative_to(s) and o != s else None
    key = source_key(s)
    product_places = [Path(str(s) + ".scipctl")] + [Path(root).resolve() / key for root in
                                                     (products_root, user_fallback_root()) if root is not None]
    if (o == s or any(o.is_relative_to(d) for d in product_places)
            or (rel and (rel[0] in ("images", "scipctl") or rel == ("downlink.yaml",)))):
        raise InputError(str(out), option, f"would overwrite the input {src} (or one of its files or products); "
                         "give a file outside the downlink")


def check_output_dir(path, option: str = "-o") -> Path:
    """``path`` as a :class:`Path` if it is (or can be made) a writable folder, else :class:`InputError`."""
    from ..errors import InputError
    from .product_store import is_writable_dir, nearest_existing

    _refuse_stdout(path, option)
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise InputError(str(path), option, "exists and is not a folder")
    if not is_writable_dir(path):
        raise InputError(str(path), option, f"cannot write here: {nearest_existing(path)} is not a writable folder")
    return path


def atomic_write_bytes(path, data: bytes) -> None:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name[:100]}.", suffix=".tmp", dir=path.parent)  # a valid name
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
        os.chmod(tmp, 0o666 & ~_umask())  # mkstemp makes 0600; give the file the permissions open() would
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        raise


def atomic_write_text(path, text: str) -> None:
    atomic_write_bytes(path, text.encode("utf-8"))


def write_output_text(path, text: str, option: str = "-o") -> None:
    """:func:`atomic_write_text` of a file the user named with ``option``: a failed write (read-only place, full
    disk) is :class:`InputError` naming ``path`` and ``option`` (exit 2), and nothing is left behind."""
    from ..errors import InputError

    try:
        atomic_write_text(path, text)
    except OSError as e:
        raise InputError(str(path), option, f"cannot write: {e.strerror or e}") from None


@contextlib.contextmanager
def atomic_directory(path, overwrite: bool = True):
    """Yield a temporary directory; on success it replaces ``path``; on error it is removed.

    Usage::

        with atomic_directory(out) as tmp:
            (tmp / "file").write_text(...)
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{path.name[:100]}.", suffix=".tmp", dir=path.parent))
    os.chmod(tmp, 0o777 & ~_umask())
    try:
        yield tmp
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    if path.exists():
        if not overwrite:
            shutil.rmtree(tmp, ignore_errors=True)
            raise FileExistsError(str(path))
        old = path.with_name(f".{path.name[:200]}.old")
        shutil.rmtree(old, ignore_errors=True)
        os.replace(path, old)
        os.replace(tmp, path)
        shutil.rmtree(old, ignore_errors=True)
    else:
        os.replace(tmp, path)
