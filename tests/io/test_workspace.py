import hashlib
import json

import pytest

from scipctl.io.downlink import downlink_differences, read_downlink, write_downlink
from scipctl.io.workspace import create_workspace, is_workspace, open_source, sidecar_dir
from scipctl.model import InputError
from tests.io.builders import make_small_downlink


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


def test_reingest_replaces_a_workspace_but_not_other_directories(tmp_path, mcap_src):
    dl = read_downlink(mcap_src)
    ws = create_workspace(dl, tmp_path / "ws")
    (ws / "scipctl" / "targets.json").write_text("{}")
    create_workspace(dl, ws)  # replacing a workspace is allowed (its products go with it)
    assert not (ws / "scipctl" / "targets.json").exists() and is_workspace(ws)
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
