#!/usr/bin/env python3
"""An operator's commands on one downlink, timed, with the stereo self-calibration's saved fits kept between them
(the default) or removed before each command (every command fits its pairs anew): docs/stereo-and-tracking.md,
"The fits kept for the next command".

The flow, on a fresh copy of the bundled ``sample_sols/mcap/paper-s1-straight.mcap`` per round and mode:
``designate --camera pancam --pixel 512.25,380.5 --id r1`` (the README's pixel), ``simulate-handoff --chain``,
``sequence --target r1``, ``report``. Each command is a child process; its wall time and CPU time (user + system,
``getrusage(RUSAGE_CHILDREN)``: threads included) are printed, and the modes alternate (kept, fresh, fresh, kept,
...) so that a load that changes during the measurement weighs on both alike. Each round also checks that the two
modes' designations are equal to the last digit (the saved fit is the fit).

    PYTHONPATH=. .venv/bin/python docs/scripts/bench_operator_flow.py [--rounds 2] [--json]
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
SOL = ROOT / "sample_sols/mcap/paper-s1-straight.mcap"
FLOW = (("designate", ["--camera", "pancam", "--pixel", "512.25,380.5", "--id", "r1", "--json"]),
        ("simulate-handoff", ["--chain"]),
        ("sequence", ["--target", "r1"]),
        ("report", ["-o", "{dir}/report.html"]))


def _run(cmd: str, src: Path, args: list, cwd: Path) -> dict:
    env = dict(os.environ, PYTHONPATH=str(ROOT) + (os.pathsep + os.environ["PYTHONPATH"] if os.environ.get("PYTHONPATH") else ""))
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    p = subprocess.run([sys.executable, "-c", "from scipctl.cli import app; app()", cmd, str(src),
                        *[a.format(dir=cwd) for a in args]], cwd=cwd, env=env, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if p.returncode not in (0, 1):  # 1: an answer (NO-GO), its products written
        raise SystemExit(f"{cmd} exited {p.returncode}: {p.stderr.strip()[-500:]}")
    return {"wall_s": wall, "cpu_s": (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime),
            "rc": p.returncode, "stdout": p.stdout}


def flow(mode: str) -> dict:
    with tempfile.TemporaryDirectory(prefix="scipctl-flow-") as d:
        d = Path(d)
        src = d / SOL.name
        shutil.copy(SOL, src)
        saved = d / (src.name + ".scipctl") / "stereo_selfcal.json"
        out = {}
        for cmd, args in FLOW:
            if mode == "fresh":
                saved.unlink(missing_ok=True)
            out[cmd] = _run(cmd, src, args, d)
        designation = json.loads(out["designate"]["stdout"])
        return {"mode": mode, "designation": {k: designation[k] for k in ("xyz_rover_m", "range_m", "uv_right")},
                **{cmd: {k: round(v, 2) for k, v in r.items() if k.endswith("_s")} | {"rc": r["rc"]}
                   for cmd, r in out.items()}}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rounds", type=int, default=2)
    ap.add_argument("--json", action="store_true")
    a = ap.parse_args(argv)
    rows = []
    for i in range(a.rounds):
        order = ("kept", "fresh") if i % 2 == 0 else ("fresh", "kept")
        got = {m: flow(m) for m in order}
        if got["kept"]["designation"] != got["fresh"]["designation"]:
            raise SystemExit(f"round {i + 1}: the designations differ: {got['kept']['designation']} "
                             f"against {got['fresh']['designation']}")
        for m in order:
            row = dict(got[m], round=i + 1, load_avg=round(os.getloadavg()[0], 2))
            rows.append(row)
            total_wall = sum(row[c]["wall_s"] for c, _ in FLOW)
            total_cpu = sum(row[c]["cpu_s"] for c, _ in FLOW)
            print(f"round {i + 1} {m:5s} " + "  ".join(f"{c} {row[c]['wall_s']:.1f}/{row[c]['cpu_s']:.1f}"
                                                        for c, _ in FLOW)
                  + f"  total {total_wall:.1f} s wall / {total_cpu:.1f} CPU s (load {row['load_avg']})",
                  file=sys.stderr)
    if a.json:
        print(json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
