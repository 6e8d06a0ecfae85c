#!/usr/bin/env python3
"""Throughput of validation campaigns: downlinks per core-hour, measured in CPU time (docs/campaign.md).

Each case runs scipctl as a child process and measures its CPU time with ``getrusage(RUSAGE_CHILDREN)`` (the
child and every process it waited for: a local Dask cluster's worker processes are the campaign's children and
are joined when it closes), and its wall time. On a shared machine wall time is noise; CPU time is the figure
(``downlinks per core-hour = 3600 x downlinks / CPU s``). For campaigns the workers' own CPU time per task, from
the records (``cpu_s``, and per stage: ``load`` is reading or rendering), is reported beside it.

Cases:

``handoff-chain``  ``scipctl campaign`` on the bundled sols (``--copies K``: K copies of each, distinct names, so
                   K x 2 downlinks), every handoff method and the chain, no prediction.
``baseline``       today's way for the same work: one ``scipctl simulate-handoff --chain --json`` process per
                   bundled sol.
``synth``          ``scipctl synth`` of one default paper run (12 images), today's way; and
``synth-campaign`` ``scipctl campaign --synth paper --seeds 1 --runs s1-straight --no-predict``: the same run
                   rendered on a worker, then its handoff and chain.

    PYTHONPATH=. .venv/bin/python docs/scripts/bench_campaign.py [--cases handoff-chain,baseline,synth,synth-campaign]
        [--copies 1] [--workers 2] [--json]
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
SOLS = sorted((ROOT / "sample_sols/mcap").glob("*.mcap"))
CASES = ("handoff-chain", "baseline", "synth", "synth-campaign")


def _scipctl(args: list, cwd: Path) -> dict:
    """Run ``scipctl ARGS``; its wall time, CPU time (user + system, with everything it waited for), stdout."""
    env = dict(os.environ, PYTHONPATH=str(ROOT) + (os.pathsep + os.environ["PYTHONPATH"] if os.environ.get("PYTHONPATH") else ""))
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    p = subprocess.run([sys.executable, "-c", "from scipctl.cli import app; app()", *args], cwd=cwd, env=env,
                       stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if p.returncode not in (0, 1):  # 1 is an answer ("no"/NO-GO: a chain ended NO-GO), with its JSON written
        raise SystemExit(f"scipctl {' '.join(args)} exited {p.returncode}:\n{p.stderr.decode()[-2000:]}")
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return {"wall_s": wall, "cpu_s": cpu, "stdout": p.stdout.decode()}


def _rate(n: int, cpu_s: float) -> float:
    return 3600.0 * n / cpu_s if cpu_s > 0 else float("nan")


def _campaign_case(name: str, args: list, tmp: Path, workers: int) -> dict:
    out = tmp / f"out-{name}"
    r = _scipctl(["campaign", *args, "-o", str(out), "--workers", str(workers), "--json"], tmp)
    doc = json.loads(r["stdout"])
    n = doc["run"]["ran"]
    return {"case": name, "downlinks": n, "wall_s": r["wall_s"], "cpu_s": r["cpu_s"],
            "downlinks_per_core_hour": _rate(n, r["cpu_s"]), "workers": workers,
            "task_cpu_s": doc["cpu"]["worker_cpu_s"], "task_cpu_s_by_stage": doc["cpu"]["by_stage"],
            "downlinks_per_core_hour_tasks_only": doc["cpu"]["downlinks_per_core_hour"]}


class _Results(list):
    """The results, each also printed to stderr as soon as it is measured (a long run keeps what it measured)."""

    def append(self, r: dict) -> None:
        super().append(r)
        sys.stderr.write(_line(r) + "\n")
        sys.stderr.flush()


def _line(r: dict) -> str:
    extra = ""
    if "task_cpu_s" in r:
        stages = ", ".join(f"{k} {v:.1f}" for k, v in r["task_cpu_s_by_stage"].items())
        extra = f"; tasks {r['task_cpu_s']:.1f} CPU s ({stages})"
    return (f"{r['case']:15s} {r['downlinks']:3d} downlinks  CPU {r['cpu_s']:7.1f} s  wall {r['wall_s']:7.1f} s  "
            f"{r['downlinks_per_core_hour']:7.1f} downlinks/core-hour{extra}")


def run(cases: list, copies: int, workers: int) -> list:
    results = _Results()
    with tempfile.TemporaryDirectory(prefix="bench-campaign-") as td:
        tmp = Path(td)
        sols = tmp / "sols"
        sols.mkdir()
        for k in range(copies):
            for s in SOLS:
                shutil.copy(s, sols / (f"c{k}-" + s.name))
        if "handoff-chain" in cases:
            results.append(_campaign_case("handoff-chain", [str(sols), "--no-predict"], tmp, workers))
        if "baseline" in cases:
            cpu = wall = 0.0
            for s in SOLS:
                d = tmp / f"base-{s.stem}"
                d.mkdir()
                r = _scipctl(["simulate-handoff", str(shutil.copy(s, d / s.name)), "--chain", "--json"], tmp)
                cpu, wall = cpu + r["cpu_s"], wall + r["wall_s"]
            results.append({"case": "baseline", "downlinks": len(SOLS), "wall_s": wall, "cpu_s": cpu,
                            "downlinks_per_core_hour": _rate(len(SOLS), cpu),
                            "command": "scipctl simulate-handoff SOL --chain --json, one process per sol"})
        if "synth" in cases:
            r = _scipctl(["synth", "--scenario", "paper", "--seed", "1", "--runs", "s1-straight", "-o",
                          str(tmp / "synth")], tmp)
            results.append({"case": "synth", "downlinks": 1, "wall_s": r["wall_s"], "cpu_s": r["cpu_s"],
                            "downlinks_per_core_hour": _rate(1, r["cpu_s"]),
                            "command": "scipctl synth --scenario paper --seed 1 --runs s1-straight -o OUT"})
        if "synth-campaign" in cases:
            results.append(_campaign_case("synth-campaign", ["--synth", "paper", "--seeds", "1", "--runs", "s1-straight",
                                                             "--no-predict"], tmp, workers))
    return results


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", default=",".join(CASES), help=f"comma-separated, from {', '.join(CASES)}")
    ap.add_argument("--copies", type=int, default=1, help="copies of each bundled sol in the handoff-chain campaign")
    ap.add_argument("--workers", type=int, default=os.cpu_count() or 1, help="local cluster workers")
    ap.add_argument("--json", action="store_true", help="results as JSON on stdout")
    a = ap.parse_args()
    cases = [c.strip() for c in a.cases.split(",") if c.strip()]
    bad = [c for c in cases if c not in CASES]
    if bad or a.copies < 1 or a.workers < 1:
        ap.error(f"unknown case(s) {bad}" if bad else "--copies and --workers must be >= 1")
    results = run(cases, a.copies, a.workers)
    if a.json:
        print(json.dumps(results, indent=1))
        return
    for r in results:
        print(_line(r))


if __name__ == "__main__":
    main()
