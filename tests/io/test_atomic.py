"""scipctl/io/atomic.py: temporaries carry their owner, and what a killed process left is removed by the next write.

A temporary is ``.<NAME>.<OWNER>.<PID>.<RAND>.tmp`` beside its target. The next write into that folder removes those
whose owner is this host and whose process is gone; it keeps those of a live process, of another host (or another
pid namespace of this host's name), and every other name. Each test places at least one stale temporary, so that a
writer that removes nothing fails it too.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from scipctl.io import atomic
from scipctl.io.atomic import atomic_directory, atomic_write_bytes, atomic_write_text, owner_tag

REPO = Path(__file__).resolve().parents[2]


def _dead_pid() -> int:
    """The pid of a process that has exited and been reaped (reused within the test only by bad luck)."""
    p = subprocess.Popen([sys.executable, "-c", "pass"])
    p.wait()
    with pytest.raises(ProcessLookupError):
        os.kill(p.pid, 0)
    return p.pid


@pytest.fixture
def sleeper():
    """A live child process: its pid is alive for the whole test."""
    p = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(600)"])
    yield p.pid
    p.kill()
    p.wait()


def _temp(folder: Path, target: str, pid: int, owner=None, kind="tmp", rand="abcd1234", folder_temp=False) -> Path:
    p = folder / f".{target}.{owner or owner_tag()[0]}.{pid}.{rand}.{kind}"
    if folder_temp:
        (p / "images").mkdir(parents=True)
        (p / "images" / "a.png").write_bytes(b"png" * 1000)
    else:
        p.write_bytes(b"half a file")
    return p


def _names(folder: Path) -> list:
    return sorted(p.name for p in folder.iterdir())


def test_temporary_names_carry_host_and_pid_and_stay_hidden_beside_the_target(tmp_path, monkeypatch):
    seen = []
    real = os.replace

    def spy(src, dst, *a, **kw):
        seen.append(Path(src))
        return real(src, dst, *a, **kw)

    monkeypatch.setattr(atomic.os, "replace", spy)
    atomic_write_text(tmp_path / "out.json", "{}\n")
    (src,) = seen
    m = atomic._OWNED_RE.match(src.name)
    assert src.parent == tmp_path and m and m["name"] == "out.json" and m["kind"] == "tmp"
    assert m["owner"] == owner_tag()[0] and int(m["pid"]) == os.getpid() and "." not in m["owner"]


def test_a_temporary_left_by_a_dead_process_of_this_host_is_removed_by_the_next_write(tmp_path):
    dead = _dead_pid()
    _temp(tmp_path, "out.json", dead)
    _temp(tmp_path, "other.json", dead, rand="zz99_x0a")  # another target's, in the same folder
    atomic_write_text(tmp_path / "out.json", "{}\n")
    assert _names(tmp_path) == ["out.json"]


def test_a_workspace_copy_left_by_a_dead_process_is_removed_by_the_next_folder_write(tmp_path):
    _temp(tmp_path, "ws", _dead_pid(), folder_temp=True)
    with atomic_directory(tmp_path / "ws") as d:
        (d / "f").write_text("x")
    assert _names(tmp_path) == ["ws"] and _names(tmp_path / "ws") == ["f"]


def test_live_processes_other_hosts_and_other_names_are_kept(tmp_path, sleeper):
    dead = _dead_pid()
    stale = _temp(tmp_path, "out.json", dead)
    kept = [
        _temp(tmp_path, "out.json", sleeper),  # a live process is still writing it
        _temp(tmp_path, "out.json", os.getpid(), rand="mine0000"),  # this process's own
        _temp(tmp_path, "out.json", dead, owner="otherhost"),  # another host: its pids mean nothing here
        _temp(tmp_path, "out.json", dead, owner=owner_tag()[0] + "+ns4026532000"),  # another pid namespace
        _temp(tmp_path, "out.json", dead, kind="old", folder_temp=True),  # never deleted, only put back
    ]
    others = [".out.json.abcd1234.tmp",  # an older scipctl's temporary: no owner, left alone
              f".out.json.{owner_tag()[0]}.{dead}.tmp", f".out.json.{owner_tag()[0]}.{dead}.abcd1234.bak",
              f"out.json.{owner_tag()[0]}.{dead}.abcd1234.tmp", ".hidden", ".out.json.swp", f".x.{owner_tag()[0]}.0.abcd1234.tmp"]
    for n in others:
        (tmp_path / n).write_text("not ours")
    atomic_write_text(tmp_path / "out.json", "{}\n")
    assert not stale.exists()
    assert _names(tmp_path) == sorted(["out.json"] + [p.name for p in kept] + others)


def test_a_host_name_with_dots_cannot_be_mistaken_for_another(tmp_path, monkeypatch):
    """Host ``node1.lab`` writing ``t.json`` and host ``lab`` writing ``t.json.node1`` name their temporaries apart:
    the owner field has no dot (``node1_lab``)."""
    dead = _dead_pid()
    monkeypatch.setattr(atomic.socket, "gethostname", lambda: "node1.lab")
    assert owner_tag()[0] == "node1_lab"
    theirs = _temp(tmp_path, "t.json", dead)  # .t.json.node1_lab.<pid>.abcd1234.tmp
    monkeypatch.setattr(atomic.socket, "gethostname", lambda: "lab")
    mine = _temp(tmp_path, "t.json.node1", dead)
    atomic_write_text(tmp_path / "t.json.node1", "{}\n")
    assert theirs.exists() and not mine.exists()
    monkeypatch.setattr(atomic.socket, "gethostname", lambda: "bad host/name")
    assert owner_tag()[0].startswith("%") and "." not in owner_tag()[0] and "/" not in owner_tag()[0]


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="pid namespaces are Linux's")
def test_another_pid_namespace_of_the_same_host_name_is_not_ours(tmp_path, monkeypatch):
    """A container sharing the host's name (``--network host``) has its own pids: its temporaries are not checked
    against ours, and ours not against its."""
    dead = _dead_pid()
    host_ns = _temp(tmp_path, "out.json", dead)  # written in the namespace this test runs in
    monkeypatch.setattr(atomic, "_INIT_PID_NS", -1)  # now this process looks like one in a container
    tag = owner_tag()[0]
    assert "+ns" in tag
    mine = _temp(tmp_path, "out.json", dead, owner=tag)
    atomic_write_text(tmp_path / "out.json", "{}\n")
    assert host_ns.exists() and not mine.exists()


def test_without_proc_nothing_is_removed(tmp_path, monkeypatch):
    """When the pid namespace cannot be read, a pid in a name cannot be checked: nothing is removed."""
    stale = _temp(tmp_path, "out.json", _dead_pid())
    real_stat = os.stat

    def stat(p, *a, **kw):
        if str(p).startswith("/proc/self/ns"):
            raise FileNotFoundError(2, "No such file or directory", str(p))
        return real_stat(p, *a, **kw)

    monkeypatch.setattr(atomic.os, "stat", stat)
    if sys.platform.startswith("linux"):
        tag, may_clean = owner_tag()
        assert tag.endswith("+ns") and not may_clean
        atomic_write_text(tmp_path / "out.json", "{}\n")
        assert stale.exists()
    monkeypatch.undo()
    atomic_write_text(tmp_path / "out.json", "{}\n")
    assert not stale.exists()


def test_a_replacement_killed_between_its_renames_is_put_back_not_deleted(tmp_path, sleeper):
    """Killed after ``ws`` became ``.ws.….old`` and before the new copy took its place: the next write of ``ws``
    starts from the previous copy (the operator's products), and the dead new copy is removed."""
    dead = _dead_pid()
    old = _temp(tmp_path, "ws", dead, kind="old", folder_temp=True)
    (old / "designations.json").write_text("operator's")
    _temp(tmp_path, "ws", dead, kind="tmp", folder_temp=True)  # the finished new copy that never went in
    live = _temp(tmp_path, "ws2", sleeper, kind="old", folder_temp=True)  # a live process between its renames
    with atomic_directory(tmp_path / "ws") as d:
        assert (tmp_path / "ws" / "designations.json").read_text() == "operator's"  # back before the new one is made
        (d / "f").write_text("new")
    assert _names(tmp_path) == sorted(["ws", live.name]) and _names(tmp_path / "ws") == ["f"]


def test_a_failed_swap_puts_the_previous_folder_back(tmp_path, monkeypatch):
    """The second rename of a swap fails (or a signal lands between the two): the previous copy goes back, and
    no temporary is left."""
    (tmp_path / "ws").mkdir()
    (tmp_path / "ws" / "keep").write_text("previous")
    real = os.replace
    calls = []

    def replace(src, dst, *a, **kw):
        calls.append(1)
        if len(calls) == 2:
            raise KeyboardInterrupt
        return real(src, dst, *a, **kw)

    monkeypatch.setattr(atomic.os, "replace", replace)
    with pytest.raises(KeyboardInterrupt):
        with atomic_directory(tmp_path / "ws") as d:
            (d / "new").write_text("new")
    assert _names(tmp_path) == ["ws"] and (tmp_path / "ws" / "keep").read_text() == "previous"


_WRITER = """
import sys, time
from pathlib import Path
from scipctl.io.atomic import atomic_directory, atomic_open

target = Path(sys.argv[2])
if sys.argv[1] == "file":
    with atomic_open(target) as f:
        f.write(b"x" * 8_000_000)
        f.flush()
        print("writing", flush=True)
        time.sleep(600)
else:
    with atomic_directory(target) as d:
        (d / "images").mkdir()
        (d / "images" / "a.png").write_bytes(b"x" * 8_000_000)
        print("writing", flush=True)
        time.sleep(600)
"""


def _killed_mid_write(kind: str, target: Path) -> None:
    """Run a writer of ``target`` in another process and SIGKILL it while its temporary is open."""
    env = dict(os.environ, PYTHONPATH=str(REPO))
    p = subprocess.Popen([sys.executable, "-c", _WRITER, kind, str(target)], stdout=subprocess.PIPE, text=True,
                         env=env)
    try:
        assert p.stdout.readline().strip() == "writing"
        assert [n for n in _names(target.parent) if n.startswith(f".{target.name}.")], "no temporary to leave"
    finally:
        p.kill()  # SIGKILL: no handler runs
        p.wait()
        p.stdout.close()


def test_sigkill_mid_write_leaves_a_temporary_that_the_next_write_removes(tmp_path):
    target = tmp_path / "big.bin"
    target.write_bytes(b"previous")
    _killed_mid_write("file", target)
    assert target.read_bytes() == b"previous" and len(_names(tmp_path)) == 2  # the kill left one temporary
    atomic_write_bytes(target, b"new")
    assert _names(tmp_path) == ["big.bin"] and target.read_bytes() == b"new"


def test_sigkill_mid_workspace_write_leaves_a_copy_that_the_next_write_removes(tmp_path):
    ws = tmp_path / "ws"
    _killed_mid_write("dir", ws)
    assert not ws.exists() and len(_names(tmp_path)) == 1
    with atomic_directory(ws) as d:
        (d / "f").write_text("x")
    assert _names(tmp_path) == ["ws"]


def test_writes_reach_the_disk_before_and_after_the_rename(tmp_path, monkeypatch):
    """A file written by atomic_write_bytes is fsynced before it replaces the target and the folder after; a
    folder written by atomic_directory has each of its files and folders fsynced before the swap, and the parent
    after it (after a power cut: the old version or the whole new one)."""
    events = []
    real_fsync, real_replace = os.fsync, os.replace

    def fsync(fd):
        events.append(("fsync", os.readlink(f"/proc/self/fd/{fd}")))
        real_fsync(fd)

    def replace(a, b):
        events.append(("replace", str(b)))
        real_replace(a, b)

    monkeypatch.setattr(atomic.os, "fsync", fsync)
    monkeypatch.setattr(atomic.os, "replace", replace)
    target = tmp_path / "out.json"
    atomic_write_bytes(target, b"{}")
    assert target.read_bytes() == b"{}"
    kinds = [(k, Path(p).name if k == "fsync" else p) for k, p in events]
    i = kinds.index(("replace", str(target)))
    assert any(k == "fsync" and n.startswith(".out.json.") for k, n in kinds[:i])  # the temporary's bytes
    assert ("fsync", tmp_path.name) in kinds[i + 1:]  # then the folder that holds the new name
    events.clear()
    folder = tmp_path / "ws"
    with atomic_directory(folder) as tmp:
        (tmp / "sub").mkdir()
        (tmp / "sub" / "a.txt").write_text("a")
        (tmp / "b.txt").write_text("b")
    assert (folder / "sub" / "a.txt").read_text() == "a"
    i = [k for k, _ in events].index("replace")
    synced = {Path(p).name for k, p in events[:i] if k == "fsync"}
    assert {"a.txt", "b.txt", "sub"} <= synced
    assert ("fsync", str(tmp_path)) in events[i + 1:]


# ----------------------------------------------------------------------------- a command's several files: all or none
def test_an_output_group_puts_every_file_in_place_and_leaves_no_temporary(tmp_path):
    (tmp_path / "a.txt").write_text("old")
    stale = _temp(tmp_path, "b.bin", _dead_pid())
    with atomic.output_group() as g:
        g.add_text(tmp_path / "a.txt", "new")
        g.add_bytes(tmp_path / "sub" / "b.bin", b"\x00\x01")
        assert (tmp_path / "a.txt").read_text() == "old" and not (tmp_path / "sub" / "b.bin").exists()  # staged only
    assert (tmp_path / "a.txt").read_text() == "new" and (tmp_path / "sub" / "b.bin").read_bytes() == b"\x00\x01"
    assert not stale.exists() and _names(tmp_path) == ["a.txt", "sub"] and _names(tmp_path / "sub") == ["b.bin"]
    mode = (tmp_path / "sub" / "b.bin").stat().st_mode & 0o777
    assert mode == 0o666 & ~atomic._umask()  # what open() would give, not mkstemp's 0600


def test_an_output_group_changes_no_target_when_a_later_write_fails(tmp_path, monkeypatch):
    """The second file cannot be written (its folder is a file): the first, already staged, does not replace its
    target either, the error names the second file and its option, and no temporary is left."""
    from scipctl.errors import InputError

    (tmp_path / "a.txt").write_text("old")
    (tmp_path / "notafolder").write_text("x")
    with pytest.raises(InputError, match=r"notafolder/b\.txt: --report: cannot write"):
        with atomic.output_group() as g:
            g.add_text(tmp_path / "a.txt", "new")
            g.add_text(tmp_path / "notafolder" / "b.txt", "report", "--report")
    assert (tmp_path / "a.txt").read_text() == "old" and _names(tmp_path) == ["a.txt", "notafolder"]

    calls = []

    def full_disk(fd):  # the second file's bytes do not reach the disk
        calls.append(fd)
        if len(calls) == 2:
            raise OSError(28, "No space left on device")

    monkeypatch.setattr(atomic.os, "fsync", full_disk)
    with pytest.raises(InputError, match=r"c\.txt: -o: cannot write: No space left on device"):
        with atomic.output_group() as g:
            g.add_text(tmp_path / "a.txt", "new")
            g.add_text(tmp_path / "c.txt", "new")
    assert (tmp_path / "a.txt").read_text() == "old" and _names(tmp_path) == ["a.txt", "notafolder"]


def test_an_output_group_changes_no_target_when_the_command_fails_after_staging(tmp_path):
    with pytest.raises(RuntimeError, match="the command's own error"):
        with atomic.output_group() as g:
            g.add_text(tmp_path / "a.txt", "new")
            raise RuntimeError("the command's own error")
    assert _names(tmp_path) == []
