import hashlib
import json
import os

import pytest

from scipctl.io.downlink import downlink_differences, read_downlink, write_downlink
from scipctl.io.workspace import create_workspace, is_workspace, open_source, sidecar_dir, write_workspace
from scipctl.model import InputError
from tests.io.builders import make_small_downlink
from tests.io.readonly_fs import make_read_only, tree


@pytest.fixture
def mcap_src(tmp_path):
    p = tmp_path / "sol42.mcap"
    write_downlink(make_small_downlink(), p)
    return p


def test_workspace_is_a_valid_downlink_with_provenance(tmp_path, mcap_src):
    dl = read_downlink(mcap_src)
    ws = create_workspace(dl, tmp_path / "ws", summary={"images": len(dl.images)}, source_path=mcap_src)
    assert is_workspace(ws)
    back = read_downlink(ws)
    assert downlink_differences(dl, back) == []
    info = json.loads((ws / "scipctl" / "workspace.json").read_text())
    assert info["source"] == {"path": str(mcap_src), "sha256": hashlib.sha256(mcap_src.read_bytes()).hexdigest()}
    assert info["provenance"]["inputs"]["downlink"]["sha256"] == info["source"]["sha256"]
    assert info["provenance"]["tool"] == "scipctl" and "time_utc" in info["provenance"]
    assert info["provenance"]["cwd"] == os.getcwd()  # the command line's relative paths are relative to it
    assert info["summary"] == {"images": len(dl.images)}


def test_workspace_products_do_not_change_its_identity(tmp_path, mcap_src):
    ws = create_workspace(read_downlink(mcap_src), tmp_path / "ws")
    src = open_source(ws)
    h0 = src.downlink.source_sha256
    src.save_json("targets.json", {"targets": [{"id": "t1"}]})
    again = open_source(ws)
    assert again.downlink.source_sha256 == h0
    assert again.load_json("targets.json") == {"targets": [{"id": "t1"}]}
    assert again.workspace_dir == ws and again.is_workspace
    assert again.products_dir == ws / "scipctl"
    assert again.workspace_info()["scipctl_workspace"] == 1


def test_raw_downlink_products_go_to_a_sidecar(tmp_path, mcap_src):
    src = open_source(mcap_src)
    assert src.workspace_dir is None and not src.is_workspace and src.workspace_info() is None
    assert src.load_json("targets.json") is None
    assert src.load_json("targets.json", default={"targets": []}) == {"targets": []}
    before = mcap_src.read_bytes()
    path = src.save_json("targets.json", {"a": 1})
    assert path == tmp_path / "sol42.mcap.scipctl" / "targets.json" == sidecar_dir(mcap_src) / "targets.json"
    assert mcap_src.read_bytes() == before  # the input is never modified
    assert open_source(mcap_src).load_json("targets.json") == {"a": 1}


def test_raw_directory_downlink_sidecar(tmp_path):
    write_downlink(make_small_downlink(), tmp_path / "dl", container="dir")
    src = open_source(tmp_path / "dl")
    assert not src.is_workspace
    src.save_json("handoff.json", [1, 2])
    assert (tmp_path / "dl.scipctl" / "handoff.json").exists() and not (tmp_path / "dl" / "scipctl").exists()


@pytest.mark.parametrize("name", ["../evil.json", "a/b.json", "workspace.json", ""])
def test_product_names_are_plain_file_names(mcap_src, name):
    with pytest.raises(InputError):
        open_source(mcap_src).save_json(name, {})


def test_malformed_product_json(tmp_path, mcap_src):
    ws = create_workspace(read_downlink(mcap_src), tmp_path / "ws")
    (ws / "scipctl" / "targets.json").write_text("{oops")
    with pytest.raises(InputError) as ei:
        open_source(ws).load_json("targets.json")
    assert ei.value.field == "json" and ei.value.product.endswith("targets.json")


@pytest.mark.parametrize("marker", ['{"provenance": {"tool": "scip', "[1, 2]"])
def test_a_damaged_workspace_marker_is_refused_on_open(tmp_path, mcap_src, marker):
    # a truncated workspace.json (a copy cut short): designate, sequence ... refuse it as `info` does
    ws = create_workspace(read_downlink(mcap_src), tmp_path / "ws")
    (ws / "scipctl" / "workspace.json").write_text(marker)
    with pytest.raises(InputError) as ei:
        open_source(ws)
    assert ei.value.field == "json" and ei.value.product.endswith("workspace.json")


def test_reingest_keeps_products_but_replaces_nothing_else(tmp_path, mcap_src):
    dl = read_downlink(mcap_src)
    ws = create_workspace(dl, tmp_path / "ws", source_path=mcap_src)
    (ws / "scipctl" / "targets.json").write_text('{"targets": [{"id": "r1"}]}')
    (ws / "scipctl" / "notes").mkdir()
    (ws / "scipctl" / "notes" / "a.txt").write_text("operator note")
    os.utime(ws / "scipctl" / "targets.json", ns=(1_000_000_000, 1_000_000_000))
    done = write_workspace(dl, ws, source_path=mcap_src)  # the same source again
    assert done.replaced and done.kept_products == ["notes", "targets.json"] and done.superseded_dir is None
    assert is_workspace(ws) and (ws / "scipctl" / "targets.json").read_text() == '{"targets": [{"id": "r1"}]}'
    assert (ws / "scipctl" / "targets.json").stat().st_mtime_ns == 1_000_000_000  # copied with its times
    assert (ws / "scipctl" / "notes" / "a.txt").read_text() == "operator note"
    info = json.loads((ws / "scipctl" / "workspace.json").read_text())
    assert info["kept_products"] == ["notes", "targets.json"] and "superseded" not in info
    assert sorted(p.name for p in tmp_path.iterdir()) == ["sol42.mcap", "ws"]  # no temporary or .old left
    other = tmp_path / "photos"
    other.mkdir()
    (other / "cat.jpg").write_bytes(b"meow")
    with pytest.raises(InputError) as ei:
        create_workspace(dl, other)
    assert ei.value.field == "output" and (other / "cat.jpg").read_bytes() == b"meow"
    plain = tmp_path / "plain_dl"
    write_downlink(dl, plain, container="dir")  # a downlink directory is not a workspace either
    with pytest.raises(InputError):
        create_workspace(dl, plain)


def test_reingest_in_place_and_from_another_container_keeps_products(tmp_path, mcap_src):
    dl = read_downlink(mcap_src)
    ws = create_workspace(dl, tmp_path / "ws", source_path=mcap_src)
    (ws / "scipctl" / "handoff.json").write_text("[1]")
    as_dir = write_downlink(dl, tmp_path / "as_dir", container="dir")  # same downlink, other container and hash
    dl_dir = read_downlink(as_dir)
    assert dl_dir.source_sha256 != dl.source_sha256
    done = write_workspace(dl_dir, ws, source_path=as_dir)  # recognised by its identical downlink files
    assert done.kept_products == ["handoff.json"]
    done = write_workspace(read_downlink(ws), ws, source_path=ws)  # in place
    assert done.kept_products == ["handoff.json"] and (ws / "scipctl" / "handoff.json").read_text() == "[1]"


def test_reingest_of_a_different_downlink_is_refused_without_force(tmp_path, mcap_src):
    dl = read_downlink(mcap_src)
    ws = create_workspace(dl, tmp_path / "ws", source_path=mcap_src)
    (ws / "scipctl" / "targets.json").write_text('{"targets": []}')
    before = tree(ws)
    other = tmp_path / "sol43.mcap"
    write_downlink(make_small_downlink(sol=43), other)
    with pytest.raises(InputError) as ei:
        create_workspace(read_downlink(other), ws, source_path=other)
    e = ei.value
    assert e.product == str(ws) and e.field == "source" and "--force" in e.message and "targets.json" in e.message
    assert "\n" not in str(e)
    assert tree(ws) == before  # nothing changed
    assert sorted(p.name for p in tmp_path.iterdir()) == ["sol42.mcap", "sol43.mcap", "ws"]


def test_force_sets_the_old_products_aside(tmp_path, mcap_src):
    dl = read_downlink(mcap_src)
    ws = create_workspace(dl, tmp_path / "ws", source_path=mcap_src)
    (ws / "scipctl" / "targets.json").write_text('{"targets": []}')
    (ws / "scipctl" / "handoff.json").write_text("[]")
    old_marker = (ws / "scipctl" / "workspace.json").read_text()
    other = tmp_path / "sol43.mcap"
    write_downlink(make_small_downlink(sol=43), other)
    dl43 = read_downlink(other)
    done = write_workspace(dl43, ws, source_path=other, force=True)
    assert done.kept_products == [] and done.superseded_products == ["handoff.json", "targets.json"]
    sup = done.superseded_dir
    assert sup.parent == ws / "scipctl" and sup.name.startswith("superseded-")
    assert (sup / "targets.json").read_text() == '{"targets": []}' and (sup / "handoff.json").read_text() == "[]"
    assert (sup / "workspace.json").read_text() == old_marker  # which downlink they were made from
    assert not (ws / "scipctl" / "targets.json").exists() and open_source(ws).load_json("targets.json") is None
    assert downlink_differences(dl43, read_downlink(ws)) == []
    info = json.loads((ws / "scipctl" / "workspace.json").read_text())
    assert info["superseded"]["dir"] == sup.name and info["superseded"]["products"] == ["handoff.json", "targets.json"]
    assert info["superseded"]["previous_source"]["path"] == str(mcap_src)
    # forcing again (back to sol 42) keeps the earlier set-aside folder and sets the new products aside
    (ws / "scipctl" / "targets.json").write_text('{"targets": [{"id": "b"}]}')
    again = write_workspace(dl, ws, source_path=mcap_src, force=True)
    assert again.kept_products == [sup.name] and again.superseded_products == ["targets.json"]
    assert (sup / "targets.json").exists() and (again.superseded_dir / "targets.json").exists()
    assert again.superseded_dir != sup
    # only set-aside folders left: nothing in use to protect, so no --force is needed, and they are kept
    third = write_workspace(dl43, ws, source_path=other)
    assert third.kept_products == sorted([sup.name, again.superseded_dir.name]) and third.superseded_dir is None


def test_a_different_downlink_replaces_a_workspace_without_products(tmp_path, mcap_src):
    ws = create_workspace(read_downlink(mcap_src), tmp_path / "ws", source_path=mcap_src)
    other = tmp_path / "sol43.mcap"
    write_downlink(make_small_downlink(sol=43), other)
    done = write_workspace(read_downlink(other), ws, source_path=other)
    assert done.replaced and done.kept_products == [] and done.superseded_dir is None
    assert read_downlink(ws).sol == 43


def test_unwritable_output_folder_is_an_input_error(tmp_path, mcap_src, monkeypatch):
    (tmp_path / "ro").mkdir()
    make_read_only(monkeypatch, tmp_path / "ro")
    with pytest.raises(InputError) as ei:
        create_workspace(read_downlink(mcap_src), tmp_path / "ro" / "ws")
    assert ei.value.field == "output" and str(tmp_path / "ro") in ei.value.product
    assert list((tmp_path / "ro").iterdir()) == []


def test_a_file_in_the_output_path_is_named(tmp_path, mcap_src):
    # `-o FILE/ws` said "cannot write the workspace: File exists"
    (tmp_path / "afile").write_text("x")
    with pytest.raises(InputError) as ei:
        create_workspace(read_downlink(mcap_src), tmp_path / "afile" / "sub" / "ws")
    assert ei.value.field == "output" and f"{tmp_path / 'afile'} is not a folder" in ei.value.message
    assert (tmp_path / "afile").read_text() == "x"


def test_update_json_holds_the_products_lock_from_read_to_write(tmp_path, mcap_src):
    """Two commands updating one product (two designate runs on a workspace) each see the other's change: the
    second waits for the first's write (it used to read, work for seconds, and overwrite the first's target)."""
    import threading
    import time

    ws = tmp_path / "ws"
    create_workspace(read_downlink(mcap_src), ws, source_path=mcap_src)
    b_read = threading.Event()

    def add(tag, wait=None):
        def f(doc):
            doc = doc or {"ids": []}
            if wait is not None:
                b = threading.Thread(target=lambda: open_source(ws).update_json("c.json", add("b", None)))
                b.start()
                time.sleep(0.3)  # B runs meanwhile, up to its lock
                assert not b_read.is_set()  # it has not read the document yet
                wait.append(b)
            else:
                b_read.set()
            return {"ids": doc["ids"] + [tag]}
        return f

    threads = []
    path, doc = open_source(ws).update_json("c.json", add("a", threads))
    threads[0].join(10)
    assert b_read.is_set() and json.loads(path.read_text()) == {"ids": ["a", "b"]}
    assert sorted(p.name for p in path.parent.iterdir()) == ["c.json", "workspace.json"]  # no lock file left



def test_reingest_after_a_kill_between_the_swap_renames_keeps_the_operators_products(tmp_path, mcap_src):
    """A re-ingest killed (SIGKILL) after ``ws`` was renamed to ``.ws.<host>.<pid>.<rand>.old`` and before the new
    copy took its place leaves no ``ws``: the next ingest to ``ws`` puts the previous workspace back first, so its
    products are carried (not lost to a fresh workspace), and removes the dead process's new copy."""
    import subprocess
    import sys

    from scipctl.io.atomic import owner_tag

    dl = read_downlink(mcap_src)
    ws = create_workspace(dl, tmp_path / "ws", source_path=mcap_src)
    (ws / "scipctl" / "targets.json").write_text('{"targets": [{"id": "r1"}]}')
    p = subprocess.Popen([sys.executable, "-c", "pass"])
    p.wait()  # a process of this host that is gone
    left = f".ws.{owner_tag()[0]}.{p.pid}.k2j4h6g8"
    create_workspace(dl, tmp_path / "new", source_path=mcap_src).rename(tmp_path / f"{left}.tmp")
    ws.rename(tmp_path / f"{left}.old")
    done = write_workspace(dl, tmp_path / "ws", source_path=mcap_src)
    assert done.replaced and done.kept_products == ["targets.json"]
    assert (ws / "scipctl" / "targets.json").read_text() == '{"targets": [{"id": "r1"}]}'
    assert sorted(p.name for p in tmp_path.iterdir()) == ["sol42.mcap", "ws"]
