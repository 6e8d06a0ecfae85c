"""Where products go when the home next to a source is not writable (read-only archives), and --products-dir.

Read-only folders are simulated with tests.io.readonly_fs (works as root, where chmod does not stop writes);
one extra test uses a real chmod and runs only as a non-root user."""

import hashlib
import json
import os

import pytest

from scipctl.io.downlink import write_downlink
from scipctl.io.product_store import source_key
from scipctl.io.workspace import create_workspace, open_source
from scipctl.io.downlink import read_downlink
from scipctl.model import InputError
from tests.io.builders import make_small_downlink
from tests.io.readonly_fs import make_read_only, tree


@pytest.fixture
def archive(tmp_path, monkeypatch):
    """A raw downlink in its own folder ``archive/``; XDG_DATA_HOME pointed into tmp_path."""
    monkeypatch.setenv("XDG_DATA_HOME", str(tmp_path / "cache"))
    (tmp_path / "archive").mkdir()
    p = tmp_path / "archive" / "sol42.mcap"
    write_downlink(make_small_downlink(), p)
    return p


def _key(p):
    return f"{p.name}-{hashlib.sha256(str(p.resolve()).encode()).hexdigest()[:12]}"


def test_read_only_folder_products_go_to_the_per_user_folder_and_are_read_back(tmp_path, archive, monkeypatch):
    before = tree(archive.parent)
    make_read_only(monkeypatch, archive.parent)
    src = open_source(archive)
    expected_dir = tmp_path / "cache" / "scipctl" / "sidecars" / _key(archive)
    assert src.products_dir == src.check_writable() == expected_dir
    path = src.save_json("targets.json", {"targets": [{"id": "r1"}]})
    assert path == expected_dir / "targets.json"
    assert json.loads(path.read_text()) == {"targets": [{"id": "r1"}]}
    note = src.location_note()
    assert str(expected_dir) in note and str(archive.parent) in note and "not writable" in note
    assert tree(archive.parent) == before  # nothing written beside the source
    again = open_source(archive)  # the next command
    assert again.load_json("targets.json") == {"targets": [{"id": "r1"}]}
    assert again.read_from == {"targets.json": path} and again.product_names() == ["targets.json"]


def test_a_write_refused_despite_the_access_check_falls_back_too(tmp_path, archive, monkeypatch):
    """os.access says writable (NFS, ACLs) but the write fails with EROFS: the per-user folder is used."""
    before = tree(archive.parent)
    make_read_only(monkeypatch, archive.parent, access_lies=True)
    src = open_source(archive)
    assert src.products_dir == archive.parent / "sol42.mcap.scipctl"  # the check believed it writable
    path = src.save_json("handoff.json", {"results": []})
    assert path == tmp_path / "cache" / "scipctl" / "sidecars" / _key(archive) / "handoff.json"
    assert os.strerror(30) in src.location_note()  # "Read-only file system"
    assert tree(archive.parent) == before
    assert open_source(archive).load_json("handoff.json") == {"results": []}


def test_a_sidecar_made_before_the_folder_went_read_only_is_still_read_and_the_newest_copy_wins(
        tmp_path, archive, monkeypatch):
    side = archive.parent / "sol42.mcap.scipctl"
    side.mkdir()
    (side / "targets.json").write_text(json.dumps({"targets": [{"id": "old"}]}))
    os.utime(side / "targets.json", ns=(1_000_000_000, 1_000_000_000))  # written long ago
    before = tree(archive.parent)
    make_read_only(monkeypatch, archive.parent)
    src = open_source(archive)
    doc = src.load_json("targets.json")
    assert doc == {"targets": [{"id": "old"}]} and src.read_from["targets.json"] == side / "targets.json"
    doc["targets"].append({"id": "new"})
    src.save_json("targets.json", doc)
    assert tree(archive.parent) == before
    again = open_source(archive)
    assert [t["id"] for t in again.load_json("targets.json")["targets"]] == ["old", "new"]
    assert again.product_path("targets.json").parent == tmp_path / "cache" / "scipctl" / "sidecars" / _key(archive)


def test_nowhere_writable_is_a_one_line_input_error(tmp_path, archive, monkeypatch):
    (tmp_path / "cache").mkdir()  # e.g. a home directory on a read-only mount
    make_read_only(monkeypatch, archive.parent)
    make_read_only(monkeypatch, tmp_path / "cache")
    src = open_source(archive)
    with pytest.raises(InputError) as ei:
        src.save_json("targets.json", {})
    assert ei.value.field == "products" and "--products-dir" in ei.value.message
    assert str(tmp_path / "cache") in ei.value.product and "\n" not in str(ei.value)
    assert list((tmp_path / "cache").iterdir()) == []


def test_products_dir_holds_products_of_raw_downlinks_and_workspaces(tmp_path, archive):
    root = tmp_path / "prod"
    src = open_source(archive, products_root=root)
    path = src.save_json("targets.json", {"targets": []})
    assert path == root / _key(archive) / "targets.json" and "--products-dir" in src.location_note()
    assert not (archive.parent / "sol42.mcap.scipctl").exists()
    assert open_source(archive, products_root=root).load_json("targets.json") == {"targets": []}
    assert open_source(archive).load_json("targets.json") is None  # DIR is only looked at when given
    ws = create_workspace(read_downlink(archive), tmp_path / "ws")
    wsrc = open_source(ws, products_root=root)
    assert wsrc.save_json("handoff.json", [1]) == root / _key(ws) / "handoff.json"
    assert not (ws / "scipctl" / "handoff.json").exists()


def test_products_dir_that_is_a_file_is_refused(tmp_path, archive):
    (tmp_path / "f").write_text("x")
    with pytest.raises(InputError) as ei:
        open_source(archive, products_root=tmp_path / "f")
    assert ei.value.product == str(tmp_path / "f") and ei.value.field == "products-dir"


@pytest.mark.parametrize("access_lies", [False, True])
def test_a_read_only_workspace_does_not_fall_back(tmp_path, archive, monkeypatch, access_lies):
    ws = create_workspace(read_downlink(archive), tmp_path / "ws")
    (ws / "scipctl" / "targets.json").write_text('{"targets": []}')
    before = tree(ws)
    make_read_only(monkeypatch, ws / "scipctl", access_lies=access_lies)
    src = open_source(ws)
    assert src.load_json("targets.json") == {"targets": []}  # reading works
    with pytest.raises(InputError) as ei:
        if not access_lies:
            src.check_writable()
        src.save_json("targets.json", {"targets": [{"id": "x"}]})
    assert ei.value.product == str(ws / "scipctl") and ei.value.field == "products"
    assert "--products-dir" in ei.value.message and "make it writable" in ei.value.message
    assert tree(ws) == before and not (tmp_path / "cache").exists()


def test_source_key_names_the_source_and_hashes_its_resolved_path(tmp_path):
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    ka, kb = source_key(tmp_path / "a" / "sol.mcap"), source_key(tmp_path / "b" / "sol.mcap")
    assert ka.startswith("sol.mcap-") and kb.startswith("sol.mcap-") and ka != kb
    os.symlink(tmp_path / "a", tmp_path / "link")
    assert source_key(tmp_path / "link" / "sol.mcap") == ka


@pytest.mark.skipif(os.geteuid() == 0, reason="chmod does not stop root; covered by the simulated tests above")
def test_real_chmod_read_only_folder(tmp_path, archive):
    os.chmod(archive.parent, 0o555)
    try:
        path = open_source(archive).save_json("targets.json", {"a": 1})
        assert path.parent == tmp_path / "cache" / "scipctl" / "sidecars" / _key(archive)
        assert sorted(p.name for p in archive.parent.iterdir()) == ["sol42.mcap"]
    finally:
        os.chmod(archive.parent, 0o755)


def test_a_name_too_long_for_a_sidecar_goes_to_the_per_user_folder(tmp_path, monkeypatch):
    """A 250-byte downlink file name: its sidecar, NAME.scipctl, cannot exist (ENAMETOOLONG), which was exit 3 in
    designate and simulate-handoff; now its products go to the per-user folder under a key cut to a valid name,
    with a note saying why."""
    from scipctl.io.downlink import write_downlink
    from scipctl.io.product_store import KEY_NAME_MAX_BYTES, source_key
    from scipctl.io.workspace import open_source
    from tests.io.builders import make_small_downlink

    monkeypatch.setenv("XDG_DATA_HOME", str(tmp_path / "data"))
    src = write_downlink(make_small_downlink(), tmp_path / ("L" * 245 + ".mcap"))
    assert len(src.name) == 250
    key = source_key(src)
    assert len(key.encode()) == KEY_NAME_MAX_BYTES + 13 and key.startswith("L" * 50)
    source = open_source(src)
    path = source.save_json("targets.json", {"targets": []})
    assert path == tmp_path / "data" / "scipctl" / "sidecars" / key / "targets.json"
    assert "longer than a file name may be" in source.location_note()
    assert open_source(src).load_json("targets.json") == {"targets": []}  # read back from there
