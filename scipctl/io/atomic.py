"""Write outputs all-or-nothing: to a temporary path beside the target, then rename.

Temporaries are hidden names in the target's folder (a rename across folders would not be atomic) that say who
wrote them (docs/workspace.md, "Temporary files")::

    .<NAME>.<OWNER>.<PID>.<RAND>.tmp   a file or folder being written; after a folder swap, the replaced copy
                                       being removed
    .<NAME>.<OWNER>.<PID>.<RAND>.old   a replaced folder between the two renames of a folder swap

``NAME`` is the target's name (its first 100 characters), ``OWNER`` the writer's host (and pid namespace, see
:func:`owner_tag`) with no dot in it, ``PID`` its process id. A process killed with SIGKILL leaves these behind
(SIGTERM and SIGINT unwind and remove them). The next write into the same folder removes the ``.tmp`` ones whose
owner is this host and whose process is gone (:func:`remove_stale_temporaries`); those of another host or of a
live process (or of a reused pid) are kept, and so is every name that does not match. An ``.old`` is never deleted:
the next write of its target puts it back if the target is missing (:func:`recover_interrupted`).
"""

from __future__ import annotations

import contextlib
import hashlib
import os
import re
import shutil
import socket
import sys
import tempfile
from pathlib import Path
from typing import Optional

_NAME_CHARS = 100  # of the target's name kept in its temporaries' names (a name has at most 255 bytes)
# the last four dot-separated fields carry no dot, so they are read unambiguously from the right
_OWNED_RE = re.compile(r"^\.(?P<name>.+)\.(?P<owner>[^.]+)\.(?P<pid>[1-9][0-9]{0,9})\.(?P<rand>[a-z0-9_]+)\."
                       r"(?P<kind>tmp|old)$")
_HOST_RE = re.compile(r"^[A-Za-z0-9-]+(\.[A-Za-z0-9-]+)*$")
_INIT_PID_NS = 0xEFFFFFFC  # the inode of Linux's initial pid namespace (PROC_PID_INIT_INO)


def owner_tag() -> tuple:
    """``(tag, may_clean)``: this process's owner field in temporaries' names, and whether pids in names with that
    tag can be checked from here.

    The tag is the host name with its dots written as ``_`` (a host name never holds ``_``; one that is not a plain
    host name is ``%`` and a hash of it). On Linux, a process outside the initial pid namespace (a container that
    shares its host's name, as with ``--network host``) adds ``+ns<inode of its pid namespace>``: a pid means
    something only inside its namespace. When the namespace cannot be read (no ``/proc``) the tag ends in ``+ns``
    and ``may_clean`` is False: such a process never removes anything.
    """
    host = socket.gethostname()
    if _HOST_RE.match(host) and len(host) <= 64:
        tag = host.replace(".", "_")
    else:
        tag = "%" + hashlib.sha256(host.encode("utf-8", "surrogateescape")).hexdigest()[:16]
    if sys.platform.startswith("linux"):
        try:
            ns = os.stat("/proc/self/ns/pid").st_ino
        except OSError:
            return tag + "+ns", False
        if ns != _INIT_PID_NS:
            tag += f"+ns{ns}"
    return tag, True


def _temp_prefix(path: Path) -> str:
    return f".{path.name[:_NAME_CHARS]}.{owner_tag()[0]}.{os.getpid()}."


def _process_gone(pid: int) -> bool:
    """True only when no process ``pid`` exists here (a live one, or one of another user, is not gone)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return True
    except (OSError, OverflowError):
        return False
    return False


def _left_by_dead_process(folder: Path, kind: str) -> list:
    """``(entry name, match)`` of the temporaries of ``kind`` in ``folder`` that this host's dead processes left."""
    tag, may_clean = owner_tag()
    if not may_clean:
        return []
    try:
        names = os.listdir(folder)
    except OSError:
        return []
    found = []
    for n in sorted(names):
        m = _OWNED_RE.match(n)
        if m and m["kind"] == kind and m["owner"] == tag and _process_gone(int(m["pid"])):
            found.append((n, m))
    return found


def remove_stale_temporaries(folder) -> list:
    """Remove the ``.tmp`` temporaries (files or folders) in ``folder`` that a process of this host left when it was
    killed (its pid no longer exists); returns their names. Best effort: what cannot be removed stays."""
    folder = Path(folder)
    removed = []
    for n, _ in _left_by_dead_process(folder, "tmp"):
        p = folder / n
        try:
            if p.is_dir() and not p.is_symlink():
                shutil.rmtree(p)
            else:
                os.unlink(p)
        except FileNotFoundError:  # another process removed it first
            pass
        except OSError:
            continue
        removed.append(n)
    return removed


def recover_interrupted(path) -> Optional[Path]:
    """Put back the folder ``path`` when a process of this host was killed between the two renames of replacing
    it (``path`` is missing, ``.<NAME>.<OWNER>.<PID>.<RAND>.old`` beside it holds the previous copy, its process
    is gone). Returns ``path`` when it did, else None. Only names shorter than 100 characters (whole in the
    temporary's name) are recovered; several candidates: the most recently renamed one."""
    path = Path(path)
    if len(path.name) >= _NAME_CHARS or os.path.lexists(path):
        return None
    candidates = []
    for n, m in _left_by_dead_process(path.parent, "old"):
        with contextlib.suppress(OSError):
            if m["name"] == path.name and (path.parent / n).is_dir():
                candidates.append(((path.parent / n).lstat().st_ctime_ns, n))
    for _, n in sorted(candidates, reverse=True):
        if os.path.lexists(path):
            break
        try:
            os.replace(path.parent / n, path)
        except OSError:
            continue
        return path
    return None


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


def _sync_folder(folder: Path) -> None:
    """Make a rename in ``folder`` durable (fsync of the folder); a system or file system that cannot sync a
    folder (Windows, some network file systems) is left as it is: the rename itself stays atomic."""
    try:
        fd = os.open(folder, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def _sync_tree(root: Path) -> None:
    """fsync every regular file and folder under ``root`` (a folder about to be renamed into place), deepest first,
    so that the rename publishes what was written, not what the page cache still holds."""
    for folder, _dirs, files in os.walk(root, topdown=False):
        for name in files:
            p = os.path.join(folder, name)
            if os.path.isfile(p) and not os.path.islink(p):
                fd = os.open(p, os.O_RDONLY)
                try:
                    os.fsync(fd)
                finally:
                    os.close(fd)
        _sync_folder(Path(folder))


@contextlib.contextmanager
def _staged_file(path: Path):
    """Yield ``(file, temporary)``: a binary file open for writing under a temporary name beside ``path`` (stale
    temporaries in that folder removed first, :func:`remove_stale_temporaries`). When the block ends without an
    error the bytes are on the disk (fsync) and the file has the permissions ``open()`` would give; on an error the
    temporary is removed. Nothing replaces ``path`` here."""
    path.parent.mkdir(parents=True, exist_ok=True)
    remove_stale_temporaries(path.parent)
    fd, tmp = tempfile.mkstemp(prefix=_temp_prefix(path), suffix=".tmp", dir=path.parent)  # a valid name
    try:
        with os.fdopen(fd, "wb") as f:
            yield f, Path(tmp)
            f.flush()
            os.fsync(f.fileno())
        os.chmod(tmp, 0o666 & ~_umask())  # mkstemp makes 0600; give the file the permissions open() would
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        raise


@contextlib.contextmanager
def atomic_open(path):
    """Yield a binary file open for writing; on success it replaces ``path``, on error it is removed. Stale
    temporaries in ``path``'s folder are removed first (:func:`remove_stale_temporaries`). The file's bytes reach
    the disk (fsync) before the rename, and the rename before this returns (the folder's fsync): after a power cut
    ``path`` is the old file or the whole new one, never an empty one."""
    path = Path(path)
    with _staged_file(path) as (f, tmp):
        yield f
    try:
        os.replace(tmp, path)
        _sync_folder(path.parent)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        raise


def atomic_write_bytes(path, data: bytes) -> None:
    with atomic_open(path) as f:
        f.write(data)


class OutputGroup:
    """The files one command writes, staged (each whole and on the disk, under its temporary name beside its target)
    before any of them replaces its target: :func:`output_group`."""

    def __init__(self):
        self.staged = []  # (temporary, target)

    def add_bytes(self, path, data: bytes, option: str = "-o") -> None:
        """Stage ``data`` for ``path``; a failed write is :class:`InputError` naming ``path`` and ``option``."""
        from ..errors import InputError

        path = Path(path)
        try:
            with _staged_file(path) as (f, tmp):
                f.write(data)
        except OSError as e:
            raise InputError(str(path), option, f"cannot write: {e.strerror or e}") from None
        self.staged.append((tmp, path))

    def add_text(self, path, text: str, option: str = "-o") -> None:
        self.add_bytes(path, text.encode("utf-8"), option)


@contextlib.contextmanager
def output_group():
    """All of a command's output files or none: yield an :class:`OutputGroup`; when the block ends without an error,
    every staged file replaces its target (renames in the order staged, then each folder synced); on an error
    (a write that failed, an exception of the command's, a signal) every temporary is removed and no target
    changes. The renames are one step each, not one together: a process killed between two of them leaves the
    first target new and the next old (each whole).

    Usage::

        with output_group() as g:
            g.add_text(out, html)
            g.add_bytes(out.with_suffix(".annotations.mcap"), data, "-o (its annotations MCAP)")
    """
    group = OutputGroup()
    try:
        yield group
        for tmp, path in group.staged:
            os.replace(tmp, path)
        for folder in dict.fromkeys(path.parent for _, path in group.staged):
            _sync_folder(folder)
    finally:
        for tmp, _ in group.staged:
            with contextlib.suppress(FileNotFoundError):
                os.unlink(tmp)


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

    Before that, a copy of ``path`` left by a replacement that was killed between its two renames is put back
    (:func:`recover_interrupted`) and stale temporaries beside it are removed (:func:`remove_stale_temporaries`).
    The replaced copy is renamed to the temporary's ``.tmp`` name before it is deleted, so that a kill while it is
    being deleted leaves a ``.tmp`` (removed by the next write), never a partial ``.old``.

    What was written under the temporary is synced to the disk before the rename, and the rename before this returns.

    Usage::

        with atomic_directory(out) as tmp:
            (tmp / "file").write_text(...)
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    recover_interrupted(path)
    remove_stale_temporaries(path.parent)
    tmp = Path(tempfile.mkdtemp(prefix=_temp_prefix(path), suffix=".tmp", dir=path.parent))
    os.chmod(tmp, 0o777 & ~_umask())
    try:
        yield tmp
        _sync_tree(tmp)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    if path.exists():
        if not overwrite:
            shutil.rmtree(tmp, ignore_errors=True)
            raise FileExistsError(str(path))
        old = tmp.with_name(tmp.name[:-len(".tmp")] + ".old")
        try:
            os.replace(path, old)
            os.replace(tmp, path)
        finally:
            if os.path.lexists(old):
                if not os.path.lexists(path):  # the new copy did not go in (an error, a signal): the previous goes back
                    os.replace(old, path)
                elif not os.path.lexists(tmp):  # swapped: the previous copy is now a temporary to delete
                    os.replace(old, tmp)
            shutil.rmtree(tmp, ignore_errors=True)
    else:
        os.replace(tmp, path)
    _sync_folder(path.parent)
