"""An output path that cannot be written is bad input: exit 2, one line naming the path and the option, said
before the work (the commands below take from seconds to minutes), and nothing written. The read-only place is
tests/io/readonly_fs.py's (os.access says no, and every write raises EROFS, as a read-only mount does for root)."""

import gzip
import shutil

import pytest
from typer.testing import CliRunner

from scipctl.cli import app
from scipctl.io.atomic import check_output_dir, check_output_file
from scipctl.errors import InputError
from tests.commands.conftest import SAMPLE
from tests.io.readonly_fs import make_read_only

runner = CliRunner()
TABLE = SAMPLE.parents[2] / "tests/data/trust/evidence-20dl-11fam.jsonl.gz"


def _one_line_exit_2(r, path, option):
    assert r.exit_code == 2, r.output
    assert r.stderr.count("\n") == 1 and "Traceback" not in r.stderr
    assert r.stderr.startswith(f"scipctl: error: {path}: {option}: "), r.stderr


@pytest.fixture
def ro(tmp_path, monkeypatch):
    d = tmp_path / "ro"
    d.mkdir()
    make_read_only(monkeypatch, d)
    return d


@pytest.mark.parametrize("args,option", [
    (["synth", "--scenario", "paper", "--seed", "0", "--runs", "s1-straight", "-o", "{ro}/synth"], "-o/--out"),
    (["trust-evidence", str(SAMPLE), "-o", "{ro}/t.jsonl"], "-o"),
    (["report", str(SAMPLE), "-o", "{ro}/r.html"], "-o"),
    (["sequence", str(SAMPLE), "--target", "t2", "-o", "{ro}/s.seqn"], "-o"),
    (["fit-trust", str(TABLE), "-o", "{ro}/m.json"], "-o"),
])
def test_unwritable_output_exits_2_before_the_work(ro, args, option):
    args = [a.format(ro=ro) for a in args]
    out = args[args.index("-o") + 1]
    r = runner.invoke(app, args)
    _one_line_exit_2(r, out, option)
    assert "cannot write here" in r.stderr and list(ro.iterdir()) == []


def _lying_folder_and_small_table(tmp_path, monkeypatch):
    """A folder os.access calls writable whose writes fail (tests/io/readonly_fs.py, access_lies), and the first 400
    rows of the evidence table (fit-trust in a second)."""
    d = tmp_path / "lies"
    d.mkdir()
    make_read_only(monkeypatch, d, access_lies=True)
    small = tmp_path / "small.jsonl.gz"
    lines = gzip.decompress(TABLE.read_bytes()).splitlines()[:400]
    small.write_bytes(gzip.compress(b"\n".join(lines) + b"\n"))
    return d, small


def test_a_write_that_fails_late_is_exit_2_too(tmp_path, monkeypatch):
    """os.access allowed it (it can: NFS, ACLs), the write itself failed: the same one line, nothing left."""
    d, small = _lying_folder_and_small_table(tmp_path, monkeypatch)
    r = runner.invoke(app, ["fit-trust", str(small), "-o", str(d / "m.json")])
    _one_line_exit_2(r, d / "m.json", "-o")
    assert list(d.iterdir()) == []


@pytest.mark.parametrize("args", [["report", str(SAMPLE), "-o", "-"],
                                  ["sequence", str(SAMPLE), "--target", "t2", "-o", "-"]])
def test_dash_is_not_a_file_named_dash(tmp_path, monkeypatch, args):
    # a script's `-o -` expecting stdout wrote a file literally named "-" in the current folder
    monkeypatch.chdir(tmp_path)
    r = runner.invoke(app, args)
    _one_line_exit_2(r, "-", "-o")
    assert "standard output" in r.stderr and list(tmp_path.iterdir()) == []


def test_check_output_paths(tmp_path, monkeypatch):
    assert check_output_file(tmp_path / "new/deeper/f.txt") == tmp_path / "new/deeper/f.txt"  # folders to be made
    assert check_output_dir(tmp_path / "a/b") == tmp_path / "a/b"
    for check in (check_output_file, check_output_dir):
        with pytest.raises(InputError, match="standard output"):
            check("-")
    with pytest.raises(InputError, match="is a directory"):
        check_output_file(tmp_path)
    (tmp_path / "file").write_text("x")
    with pytest.raises(InputError, match="not a folder"):
        check_output_dir(tmp_path / "file")
    ro = tmp_path / "ro"
    ro.mkdir()
    make_read_only(monkeypatch, ro)
    with pytest.raises(InputError, match="-o: cannot write here"):
        check_output_file(ro / "x/f.txt")
    with pytest.raises(InputError, match="--report: cannot write here"):
        check_output_file(ro / "f.txt", "--report")
    shutil.rmtree(tmp_path / "a", ignore_errors=True)


def test_fit_trust_writes_its_model_and_report_together(tmp_path, monkeypatch):
    """--report's folder refuses the write only when it is made (os.access said yes): the model, whose folder is
    fine, is not written either (before, it was, and the command exited 2 with half its output in place)."""
    d, small = _lying_folder_and_small_table(tmp_path, monkeypatch)
    r = runner.invoke(app, ["fit-trust", str(small), "-o", str(tmp_path / "m.json"), "--report", str(d / "r.json")])
    _one_line_exit_2(r, d / "r.json", "--report")
    assert list(d.iterdir()) == [] and sorted(p.name for p in tmp_path.iterdir()) == ["lies", "small.jsonl.gz"]


def test_synth_refuses_a_folder_in_the_way_of_a_runs_record_before_the_work(tmp_path):
    (tmp_path / "out" / "paper-s1-straight.sim.json").mkdir(parents=True)
    r = runner.invoke(app, ["synth", "--scenario", "paper", "--seed", "0", "--runs", "s1-straight", "-o",
                            str(tmp_path / "out")])
    _one_line_exit_2(r, tmp_path / "out" / "paper-s1-straight.sim.json", "-o/--out")
    assert "is a directory" in r.stderr and [p.name for p in (tmp_path / "out").iterdir()] == ["paper-s1-straight.sim.json"]


def test_synth_writes_a_downlink_and_its_record_together(tmp_path, monkeypatch):
    """The truth record's bytes do not reach the disk (a full disk at its fsync): the downlink, rendered and
    written first before, is not left without its record; exit 2 naming the record, nothing in the folder."""
    import os

    from scipctl.io import atomic

    real_fsync = os.fsync

    def full_disk_for_records(fd):
        if ".sim.json." in os.readlink(f"/proc/self/fd/{fd}"):
            raise OSError(28, "No space left on device")
        real_fsync(fd)

    monkeypatch.setenv("SCIPCTL_SYNTH_IMAGE_SCALE", "0.125")  # 128 x 128 images: seconds
    monkeypatch.setattr(atomic.os, "fsync", full_disk_for_records)
    out = tmp_path / "out"
    r = runner.invoke(app, ["synth", "--scenario", "paper", "--seed", "0", "--runs", "s1-straight", "-o", str(out)])
    assert r.exit_code == 2 and "Traceback" not in r.stderr, r.output
    errors = [line for line in r.stderr.splitlines() if line.startswith("scipctl: error: ")]  # (after the progress bar)
    assert errors == [f"scipctl: error: {out / 'paper-s1-straight.sim.json'}: -o/--out: cannot write: No space left "
                      "on device"] and r.stderr.rstrip("\n").endswith(errors[0])
    assert list(out.iterdir()) == []
