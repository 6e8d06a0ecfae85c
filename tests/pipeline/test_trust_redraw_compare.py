"""docs/scripts/trust_redraw_compare.py: some draws' rows replaced in the trust tables, in place."""

import gzip
import json

import pytest

from scipctl.errors import InputError
from tests.doc_scripts import load

rc = load("trust_redraw_compare")


def _row(group, target, err):
    return json.dumps({"group": group, "target": target, "error_px": err})


def _write_gz(path, lines):
    path.write_bytes(gzip.compress(("\n".join(lines) + "\n").encode(), 9, mtime=0))


def test_a_redrawn_group_replaces_its_rows_in_place(tmp_path, monkeypatch):
    tables = tmp_path / "trust"
    tables.mkdir()
    _write_gz(tables / "a.jsonl.gz", [_row("a-1-s1.mcap", "t1", 1.0), _row("m-2-s2.mcap", "t1", 2.0),
                                      _row("m-2-s2.mcap", "t2", 3.0), _row("z-3-s3.mcap", "t1", 4.0)])
    _write_gz(tables / "b.jsonl.gz", [_row("b-4-s1.mcap", "t1", 5.0)])
    monkeypatch.setattr(rc, "TABLES", str(tables))
    redrawn = tmp_path / "redrawn"
    redrawn.mkdir()
    header = json.dumps({"provenance": {"tool": "scipctl"}})
    (redrawn / "m-2-s2.jsonl").write_text("\n".join([header, _row("m-2-s2.mcap", "t1", 9.0)]) + "\n")
    out = tmp_path / "out"
    out.mkdir()
    paths = rc.replaced_tables(str(redrawn), str(out))
    assert [p.split("/")[-1] for p in paths] == ["a.jsonl.gz", "b.jsonl.gz"]
    a = gzip.decompress((out / "a.jsonl.gz").read_bytes()).decode().splitlines()
    assert a == [_row("a-1-s1.mcap", "t1", 1.0), header, _row("m-2-s2.mcap", "t1", 9.0), _row("z-3-s3.mcap", "t1", 4.0)]
    assert (out / "b.jsonl.gz").read_bytes() == (tables / "b.jsonl.gz").read_bytes()  # untouched: the same bytes


def test_a_redrawn_table_of_no_group_is_refused(tmp_path, monkeypatch):
    tables = tmp_path / "trust"
    tables.mkdir()
    _write_gz(tables / "a.jsonl.gz", [_row("a-1-s1.mcap", "t1", 1.0)])
    monkeypatch.setattr(rc, "TABLES", str(tables))
    redrawn = tmp_path / "redrawn"
    redrawn.mkdir()
    (redrawn / "q-9-s1.jsonl").write_text(_row("q-9-s1.mcap", "t1", 1.0) + "\n")
    with pytest.raises(InputError, match="q-9-s1.jsonl.*none of the tables"):
        rc.replaced_tables(str(redrawn), str(tmp_path))
