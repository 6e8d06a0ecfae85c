"""Bad input on the command line: exit code 2, one line on stderr naming a product or file and a field, no
traceback, nothing written (no half-made workspace, no temporary directory beside it, no sidecar).

* ``scipctl ingest BAD -o OUT`` and ``scipctl info BAD`` on seeded mutants of a small valid downlink
  (tests/io/mutate.py, tests/io/builders.py), both containers: whatever ``ingest`` does, ``info`` does
  the same, and the exit code agrees with ``read_downlink`` (0 only for harmless damage);
* bad arguments (non-finite or out-of-image ``--pixel``, bad ``--band-px``/``--success-px``/sigmas/format,
  unknown products, cameras, targets and methods) to designate, simulate-handoff, sequence and report;
* one real process per container, where libpng or a traceback would show on the real stderr.

In-process runs (CliRunner) record Python warnings and the process's file-descriptor output (capfd), each of
which would be another line on a real terminal.
"""

from __future__ import annotations

import copy
import shutil
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest
import yaml
from typer.testing import CliRunner

from scipctl.cli import app
from scipctl.io.downlink import read_downlink, write_downlink
from scipctl.io.workspace import is_workspace
from scipctl.model import InputError
from tests.io.builders import META, make_small_downlink, plain_records, write_raw_mcap
from tests.io.mutate import dump_yaml, mutate_bytes, mutate_tree, odd_png

SEED = 20250613
REPO = Path(__file__).resolve().parents[2]
NAV = "navcam_left_1_0"
runner = CliRunner()


@pytest.fixture(scope="module")
def base(tmp_path_factory):
    """A small valid downlink as scipctl's MCAP, as a plain MCAP without CRCs, and as a directory."""
    d = tmp_path_factory.mktemp("base")
    dl = make_small_downlink(n_positions=1)
    write_downlink(dl, d / "dl.mcap")
    write_raw_mcap(d / "plain.mcap", META, plain_records(dl), writer_options={"use_chunking": False, "enable_crcs": False})
    write_downlink(dl, d / "dir", container="dir")
    return {"mcap": d / "dl.mcap", "plain": d / "plain.mcap", "dir": d / "dir", "downlink": dl}


def invoke(args, capfd):
    """CliRunner run of ``scipctl ARGS`` -> (result, [problems with the process's output])."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        r = runner.invoke(app, [str(a) for a in args])
    problems = [f"warning {w.category.__name__}: {w.message}" for w in caught]
    out, err = capfd.readouterr()
    if out or err:
        problems.append(f"printed outside the CLI's streams: {(out + err)[:200]!r}")
    return r, problems


def bad_input_problems(r, fragment: str = "") -> list:
    """What is wrong with ``r`` as the CLI's answer to bad input ([] if nothing)."""
    lines = r.stderr.split("\n")
    problems = []
    if r.exit_code != 2:
        problems.append(f"exit code {r.exit_code}, not 2")
    if len(lines) != 2 or lines[1] != "" or not lines[0].startswith("scipctl: error: ") or not lines[0].isprintable():
        problems.append(f"stderr is not one error line: {r.stderr[:300]!r}")
    if "Traceback" in r.stderr or r.exception is not None and not isinstance(r.exception, SystemExit):
        problems.append(f"traceback / exception {r.exception!r}")
    if r.stdout:
        problems.append(f"stdout not empty: {r.stdout[:100]!r}")
    if fragment not in r.stderr:
        problems.append(f"{fragment!r} not in {r.stderr!r}")
    return problems


# --------------------------------------------------------------------------- ingest / info on mutants
def _mcap_mutant(which):
    def make(base, rng, work):
        data, desc = mutate_bytes(base[which].read_bytes(), rng)
        (work / "bad.mcap").write_bytes(data)
        return work / "bad.mcap", desc
    return make


def _dir_mutant(base, rng, work):
    bad = work / "bad"
    shutil.copytree(base["dir"], bad)
    op = ["yaml-bytes", "yaml-records", "png-bytes", "png-odd", "png-missing"][int(rng.integers(5))]
    pngs = sorted((bad / "images").iterdir())
    png = pngs[int(rng.integers(len(pngs)))]
    if op == "yaml-bytes":
        data, desc = mutate_bytes((bad / "downlink.yaml").read_bytes(), rng)
        (bad / "downlink.yaml").write_bytes(data)
    elif op == "yaml-records":
        doc = copy.deepcopy(yaml.safe_load((bad / "downlink.yaml").read_text()))
        desc = mutate_tree(doc, rng)
        (bad / "downlink.yaml").write_text(dump_yaml(doc), encoding="utf-8")
    elif op == "png-bytes":
        data, desc = mutate_bytes(png.read_bytes(), rng)
        png.write_bytes(data)
    elif op == "png-odd":
        data, desc = odd_png(rng, 64, 48)
        png.write_bytes(data)
    else:
        png.unlink()
        desc = "missing"
    return bad, f"{op} {png.name if op.startswith('png') else ''} {desc}"


@pytest.mark.parametrize("kind, make, n", [
    ("scipctl-mcap", _mcap_mutant("mcap"), 30),
    ("plain-mcap-no-crc", _mcap_mutant("plain"), 40),
    ("directory", _dir_mutant, 50),
])
def test_ingest_and_info_on_damaged_downlinks(base, tmp_path, capfd, kind, make, n):
    rng = np.random.default_rng([SEED, len(kind)])
    failures, rejected = [], 0
    for i in range(n):
        work = tmp_path / f"case{i}"
        work.mkdir()
        bad, desc = make(base, rng, work)
        out = work / "ws"
        try:
            read_downlink(bad)
            expected = 0
        except InputError:
            expected = 2
        capfd.readouterr()
        r, problems = invoke(["ingest", bad, "-o", out], capfd)
        ri, problems_i = invoke(["info", bad], capfd)
        problems += problems_i
        if expected == 2:
            rejected += 1
            problems += [f"ingest: {p}" for p in bad_input_problems(r)]
            problems += [f"info: {p}" for p in bad_input_problems(ri)]
            if ri.stderr != r.stderr:
                problems.append(f"info and ingest disagree: {ri.stderr!r} vs {r.stderr!r}")
            if sorted(p.name for p in work.iterdir()) != [bad.name]:
                problems.append(f"left behind: {sorted(p.name for p in work.iterdir())}")
        elif (r.exit_code, ri.exit_code) != (0, 0) or not is_workspace(out):
            problems.append(f"harmless damage, but exit codes {r.exit_code}/{ri.exit_code}: {r.stderr[-200:]!r}")
        failures += [f"{kind} case {i} ({desc}): {p}" for p in problems]
        shutil.rmtree(work)
    assert not failures, f"{len(failures)} failure(s):\n" + "\n".join(failures[:20])
    assert rejected >= n // 2


def test_one_real_process_per_container(base, tmp_path):
    """A real process: libpng or a traceback would be on its stderr. The PNG damage here used to print
    'libpng error: IDAT: incorrect data check' before the error line."""
    exe = REPO / ".venv" / "bin" / "scipctl"
    if not exe.exists():
        exe = Path(sys.executable).with_name("scipctl")
    d = tmp_path / "dir"
    shutil.copytree(base["dir"], d / "bad")
    png = d / "bad" / "images" / f"{NAV}.png"
    data = bytearray(png.read_bytes())
    data[data.index(b"IDAT") + 40] ^= 0x10
    png.write_bytes(bytes(data))
    m = tmp_path / "mcap"
    m.mkdir()
    plain = base["plain"].read_bytes()
    k = plain.index(b'"camera": "navcam"')
    (m / "bad.mcap").write_bytes(plain[:k] + b"\xff" + plain[k + 1:])  # not UTF-8: no CRC to catch it first
    for work, bad, named in ((d, d / "bad", f"{NAV}: image: corrupt PNG"), (m, m / "bad.mcap", "not valid JSON")):
        for args in (["ingest", str(bad), "-o", str(work / "ws")], ["info", str(bad)]):
            r = subprocess.run([str(exe), *args], capture_output=True, text=True, timeout=120,
                               env={"PATH": "/usr/bin:/bin", "PYTHONPATH": str(REPO)})
            assert r.returncode == 2, r.stderr
            assert r.stdout == ""
            assert len(r.stderr.splitlines()) == 1 and r.stderr.startswith("scipctl: error: ") and named in r.stderr, r.stderr
            assert sorted(p.name for p in work.iterdir()) == [bad.name]


# --------------------------------------------------------------------------- bad arguments
S = "SRC"  # stands for the downlink in the argument lists below
BAD_ARGS = [
    # designate
    (["designate", S, "--product", NAV, "--pixel", "nan,10"], "--pixel: pixel: expected two finite numbers"),
    (["designate", S, "--product", NAV, "--pixel", "10,inf"], "--pixel: pixel: expected two finite numbers"),
    (["designate", S, "--product", NAV, "--pixel", "1e400,10"], "--pixel: pixel: expected two finite numbers"),
    (["designate", S, "--product", NAV, "--pixel", "10"], "--pixel: pixel: expected two finite numbers"),
    (["designate", S, "--product", NAV, "--pixel", "1,2,3"], "--pixel: pixel: expected two finite numbers"),
    (["designate", S, "--product", NAV, "--pixel", "u,v"], "--pixel: pixel: expected U,V numbers"),
    (["designate", S, "--product", NAV, "--pixel", "63.6,10"], f"{NAV}: pixel: (63.6, 10) is outside the 64x48 image"),
    (["designate", S, "--product", NAV, "--pixel", "10,-0.6"], f"{NAV}: pixel: (10, -0.6) is outside"),
    (["designate", S, "--product", NAV, "--pixel", "1e308,1e308"], f"{NAV}: pixel: (1e+308, 1e+308) is outside"),
    (["designate", S, "--product", "ghost", "--pixel", "30,20"], "ghost: product_id: no such image product"),
    (["designate", S, "--product", "navcam_right_1_0", "--pixel", "30,20"], "navcam_right_1_0: eye: designate from a left"),
    (["designate", S, "--camera", "periscope", "--pixel", "30,20"], "camera: no left periscope image"),
    (["designate", S, "--pixel", "30,20"], "designate: --product: give --product"),
    (["designate", S, "--product", NAV, "--pixel", "30,20", "--band-px", "0"], "--band-px: band_px: must be a positive"),
    (["designate", S, "--product", NAV, "--pixel", "30,20", "--band-px", "-2"], "--band-px: band_px: must be a positive"),
    (["designate", S, "--product", NAV, "--pixel", "30,20", "--band-px", "nan"], "--band-px: band_px: must be a positive"),
    (["designate", S, "--product", NAV, "--pixel", "30,20", "--band-px", "inf"], "--band-px: band_px: must be a positive"),
    (["designate", "no/such.mcap", "--product", NAV, "--pixel", "30,20"], "no/such.mcap: path: no such file"),
    # simulate-handoff
    (["simulate-handoff", S, "--success-px", "0"], "--success-px: success_px: must be a positive finite number"),
    (["simulate-handoff", S, "--success-px", "-4"], "--success-px: success_px: must be a positive finite number"),
    (["simulate-handoff", S, "--success-px", "nan"], "--success-px: success_px: must be a positive finite number"),
    (["simulate-handoff", S, "--success-px", "inf"], "--success-px: success_px: must be a positive finite number"),
    (["simulate-handoff", S, "--methods", "telepathy"], "--methods: methods: unknown method 'telepathy'"),
    (["simulate-handoff", S, "--methods", " , "], "--methods: methods: no method named"),
    (["simulate-handoff", S, "--from", NAV], "--from/--pixel: pixel: give both"),
    (["simulate-handoff", S, "--from", NAV, "--pixel", "nan,3"], "--pixel: pixel: expected two finite numbers"),
    (["simulate-handoff", S, "--from", NAV, "--pixel", "30,48"], f"{NAV}: pixel: (30, 48) is outside the image"),
    (["simulate-handoff", S, "--from", "hazcam_left_1_0", "--pixel", "3,3"], "--from must be a left navcam product"),
    (["simulate-handoff", S, "--hazcam", "ghost"], "ghost: product_id: no such image product"),
    (["simulate-handoff", S, "--target", "ghost", "--methods", "pure-kinematic"], "ghost: target: no such marked target"),
    (["simulate-handoff", S, "--chain", "--chain-answer", "navcam"], "--chain-answer: must be one of handoff, closure"),
    (["simulate-handoff", S, "--chain-answer", "closure"], "--chain-answer: is the chain's answer: give --chain too"),
    # sequence
    (["sequence", S, "--target", "ghost"], "ghost: --target: not designated"),
    (["sequence", S, "--target", "t_flat", "--format", "pdf"], "--format: format: unknown format 'pdf'"),
    (["sequence", S, "--target", "t_flat", "--sigma-position-m", "0"], "--sigma-position-m: sigma_position_m: must be"),
    (["sequence", S, "--target", "t_flat", "--sigma-position-m", "nan"], "--sigma-position-m: sigma_position_m: must be"),
    (["sequence", S, "--target", "t_flat", "--sigma-yaw-deg", "inf"], "--sigma-yaw-deg: sigma_yaw_deg: must be"),
    # report
    (["report", S, "-o", "SRCDIR"], ": -o: is a directory"),
    (["report", S, "--sigma-yaw-deg", "-1", "-o", "r.html"], "--sigma-yaw-deg: sigma_yaw_deg: must be"),
    # the annotations MCAP beside the page cannot be written (a folder of that name): said before the work (the
    # page was written and the annotations only noted, exit 0)
    (["report", S, "-o", "ANNDIR/r.html"], "r.annotations.mcap: -o (its annotations MCAP beside it): is a directory"),
    # an empty list named nothing: synth exited 0 having made nothing, campaign --synth rendered every run
    (["synth", "--scenario", "paper", "--runs", ",", "-o", "out"], "synth: --runs: ',' names no run"),
    (["campaign", "--synth", "paper", "--seeds", "1", "--runs", ",", "-o", "out"], "campaign: --runs: ',' names nothing"),
    (["campaign", "--synth", "paper", "--seeds", "1", "--families", " , ", "-o", "out"],
     "campaign: --families: ' , ' names nothing"),
]


@pytest.fixture(scope="module")
def args_src(tmp_path_factory, base):
    d = tmp_path_factory.mktemp("args")
    shutil.copy(base["mcap"], d / "sol.mcap")
    return d


@pytest.mark.parametrize("args, fragment", BAD_ARGS, ids=[" ".join(a[0:1] + a[2:]).replace(NAV, "NAV") for a, _ in BAD_ARGS])
def test_bad_arguments(args_src, capfd, monkeypatch, args, fragment):
    monkeypatch.chdir(args_src)  # relative outputs (r.html) land here, where the listing below would show them
    before = sorted(p.name for p in args_src.iterdir())
    if "ANNDIR/r.html" in args:  # a folder where the report's annotations MCAP would go, made for this case
        (args_src / "ann" / "r.annotations.mcap").mkdir(parents=True, exist_ok=True)
        before = sorted(p.name for p in args_src.iterdir())
    args = [str(args_src / "sol.mcap") if a == S else str(args_src) if a == "SRCDIR"
            else str(args_src / "ann" / "r.html") if a == "ANNDIR/r.html" else a for a in args]
    r, problems = invoke(args, capfd)
    assert problems + bad_input_problems(r, fragment) == []
    assert sorted(p.name for p in args_src.iterdir()) == before  # no sidecar products, no report, no temp files
