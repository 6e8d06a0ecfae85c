"""Simulate a read-only folder in-process, in a way that holds when the tests run as root (CI).

``chmod`` does not stop root, and read-only bind mounts need privileges the tests do not have. Instead the
file-system calls Python makes are patched for paths inside the folder, as on a read-only mount (EROFS):

- ``os.access(path, W_OK)`` is False (what the kernel answers for a read-only mount, even to root);
- creating, opening for writing, renaming into/out of, or removing anything in it raises ``OSError(EROFS)``:
  ``os.open`` with a write flag (``tempfile.mkstemp``), ``builtins.open``/``io.open`` in a write mode,
  ``os.mkdir`` (``Path.mkdir``), ``os.replace``/``os.rename``, ``os.unlink``/``os.rmdir``.

``access_lies=True`` keeps ``os.access`` truthful-looking (says writable) while writes still fail: a folder
whose permissions are only checked by the server (NFS, ACLs), so the code's fallback after a failed write is
exercised too. Callers check the real folder listing afterwards: nothing may have appeared in it.
"""

from __future__ import annotations

import builtins
import errno
import io
import os
from pathlib import Path

_WRITE_FLAGS = os.O_WRONLY | os.O_RDWR | os.O_CREAT | os.O_TRUNC | os.O_APPEND


def _inside(path, root: Path) -> bool:
    if isinstance(path, int):  # a file descriptor
        return False
    try:
        p = Path(os.fsdecode(path)).absolute()
    except TypeError:
        return False
    p = Path(os.path.normpath(p))
    return p == root or root in p.parents


def make_read_only(monkeypatch, folder, access_lies: bool = False) -> None:
    root = Path(os.path.normpath(Path(folder).resolve()))

    def refuse(path):
        raise OSError(errno.EROFS, os.strerror(errno.EROFS), os.fsdecode(path))

    real_access, real_open, real_mkdir = os.access, os.open, os.mkdir
    real_replace, real_rename, real_unlink, real_rmdir = os.replace, os.rename, os.unlink, os.rmdir
    real_bopen = builtins.open

    def access(path, mode, *a, **kw):
        if not access_lies and mode & os.W_OK and _inside(path, root):
            return False
        return real_access(path, mode, *a, **kw)

    def os_open(path, flags, *a, **kw):
        if flags & _WRITE_FLAGS and _inside(path, root):
            refuse(path)
        return real_open(path, flags, *a, **kw)

    def b_open(file, mode="r", *a, **kw):
        if any(c in mode for c in "wax+") and _inside(file, root):
            refuse(file)
        return real_bopen(file, mode, *a, **kw)

    def mkdir(path, *a, **kw):
        if _inside(path, root):
            refuse(path)
        return real_mkdir(path, *a, **kw)

    def two(real):
        def f(src, dst, *a, **kw):
            if _inside(src, root) or _inside(dst, root):
                refuse(dst)
            return real(src, dst, *a, **kw)
        return f

    def one(real):
        def f(path, *a, **kw):
            if _inside(path, root):
                refuse(path)
            return real(path, *a, **kw)
        return f

    monkeypatch.setattr(os, "access", access)
    monkeypatch.setattr(os, "open", os_open)
    monkeypatch.setattr(os, "mkdir", mkdir)
    monkeypatch.setattr(os, "replace", two(real_replace))
    monkeypatch.setattr(os, "rename", two(real_rename))
    monkeypatch.setattr(os, "unlink", one(real_unlink))
    monkeypatch.setattr(os, "rmdir", one(real_rmdir))
    monkeypatch.setattr(builtins, "open", b_open)
    monkeypatch.setattr(io, "open", b_open)


def tree(folder) -> dict:
    """{relative path: (size, mtime_ns)} of everything under ``folder`` (the real file system)."""
    root = Path(folder)
    return {p.relative_to(root).as_posix(): (p.stat().st_size if p.is_file() else -1, p.stat().st_mtime_ns)
            for p in sorted(root.rglob("*"))}
