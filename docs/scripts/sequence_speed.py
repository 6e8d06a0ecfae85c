#!/usr/bin/env python3
"""Speed of ``scipctl sequence`` as an operator runs it, and a check that a speed-up changed no answer
(docs/sequence.md, "Speed"; issue #15 item 5).

Cases (the bundled ``sample_sols/mcap/paper-s1-straight.mcap``):

``r1``        the README's walkthrough: ``scipctl ingest`` to a workspace, ``scipctl designate --camera pancam
              --pixel 512.25,380.5 --id r1`` (done once, not timed), then ``scipctl sequence WS --target r1``;
``t1..t3``    ``scipctl sequence paper-s1-straight.mcap --target tN``: the marked targets, designated on the fly.

Each timed run is a child process (``python -c 'from scipctl.cli import app; app()' sequence ...``): its wall
time and its CPU time (user + system from ``getrusage(RUSAGE_CHILDREN)``, threads included). On a shared
2-core machine wall time is noise; the load average (``os.getloadavg``) is printed beside it.

``--stages``: ``--stage-runs N`` (default 1) more children per case run the command in-process with timers
(``time.process_time``, this process's CPU, threads included; and wall) around the stages: imports, reading the source, the designation
of a marked target, terrain (dense stereo + mesh), the approach plan, the nominal views, the Monte Carlo, the
chain simulation (and, inside it, rendering, NCC tracking, draped templates, occlusion casts, mast pointing),
the rules and the document; per stage the median over the N runs.

``--snapshot DIR``: the child also writes, per case, everything the command answers at full precision (the
prediction's ``to_dict()`` without its timings, a hash of every reduced-size expected view the report shows
(rendered by the child when the command did not render them), the rule checks, the sequence
document as written, the ``--json`` summary without its timings, the exit code): ``DIR/<case>.json``.
``--compare A B``: those snapshots must be equal, value for value (exit 1 otherwise, naming the first
difference).

``--code DIR`` times and snapshots another checkout's ``scipctl`` (e.g. the main branch: the "before").
``--versus DIR`` also times the checkout DIR, its runs alternating with ``--code``'s (A B B A ...), so that a
load that changes during the measurement weighs on both alike.

    PYTHONPATH=. .venv/bin/python docs/scripts/sequence_speed.py [--cases r1,t1,t2,t3] [--repeat 3] [--stages]
        [--snapshot DIR] [--code DIR] [--versus DIR] [--workdir DIR] [--json]
    PYTHONPATH=. .venv/bin/python docs/scripts/sequence_speed.py --compare before/ after/
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import resource
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
SOL = ROOT / "sample_sols/mcap/paper-s1-straight.mcap"
CASES = ("r1", "t1", "t2", "t3")
README_PIXEL = "512.25,380.5"


def _env(code: Path) -> dict:
    return dict(os.environ, PYTHONPATH=str(code))


def _run(argv: list, code: Path, cwd: Path) -> dict:
    """Run ``argv`` (a python child); wall and CPU seconds (user + system, RUSAGE_CHILDREN), exit code, output."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    p = subprocess.run(argv, cwd=cwd, env=_env(code), stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return {"wall_s": wall, "cpu_s": cpu, "rc": p.returncode, "stdout": p.stdout.decode(), "stderr": p.stderr.decode()}


def _scipctl(args: list, code: Path, cwd: Path) -> dict:
    return _run([sys.executable, "-c", "from scipctl.cli import app; app()", *args], code, cwd)


def _workspace(tmp: Path, code: Path) -> Path:
    """The README's walkthrough up to ``sequence``: ingest the sample, designate r1 (not timed; reused when
    ``tmp/ws`` has it: the designation record carries its time, and the sequence the record's hash)."""
    ws = tmp / "ws"
    if (ws / "scipctl" / "targets.json").exists():
        return Path("ws")
    for args in (["ingest", str(SOL), "-o", "ws"],
                 ["designate", str(ws), "--camera", "pancam", "--pixel", README_PIXEL, "--id", "r1", "--json"]):
        r = _scipctl(args, code, tmp)
        if r["rc"] != 0:
            raise SystemExit(f"scipctl {' '.join(args)} exited {r['rc']}:\n{r['stderr'][-2000:]}")
    return Path("ws")


def _sequence_args(case: str, ws: Path, out: Path) -> list:
    src = ws if case == "r1" else SOL
    return ["sequence", str(src), "--target", case, "--format", "json", "--json", "-o", str(out)]


# ---------------------------------------------------------------------------------------------- in the child
class _Timers:
    """Cumulative CPU (process_time) and wall seconds per stage name; nested stages count in both."""

    def __init__(self):
        self.cpu, self.wall, self.calls = {}, {}, {}

    def wrap(self, name, fn):
        def timed(*a, **k):
            c0, w0 = time.process_time(), time.perf_counter()
            try:
                return fn(*a, **k)
            finally:
                self.cpu[name] = self.cpu.get(name, 0.0) + time.process_time() - c0
                self.wall[name] = self.wall.get(name, 0.0) + time.perf_counter() - w0
                self.calls[name] = self.calls.get(name, 0) + 1

        return timed

    def patch(self, name, module, attr):
        setattr(module, attr, self.wrap(name, getattr(module, attr)))


def _child(case: str, args: list, stages_out: Path, snapshot_out) -> int:
    """In-process ``scipctl ARGS`` with stage timers (and the snapshot of its answers)."""
    c_start, w_start = time.process_time(), time.perf_counter()
    tm = _Timers()
    import scipctl.cli as cli

    import scipctl.core.tracking as tracking
    import scipctl.io.workspace as workspace
    import scipctl.pipeline.predict as predict
    import scipctl.pipeline.predict.chain_sim as chain_sim
    import scipctl.pipeline.predict.prediction as prediction
    import scipctl.pipeline.target_sequence as target_sequence
    from scipctl.core.kinematics import RoverConfig
    from scipctl.pipeline.predict.terrain import Terrain

    c_imported, w_imported = time.process_time(), time.perf_counter()
    tm.patch("read source", workspace, "open_source")
    tm.patch("designate marked target", predict, "resolve_target")
    tm.patch("terrain: dense stereo", prediction, "terrain_sources")
    tm.patch("terrain: mesh", prediction, "Terrain")
    tm.patch("plan", prediction, "plan_approach")
    tm.patch("views", prediction, "check_views")
    tm.patch("monte carlo", prediction, "monte_carlo")
    tm.patch("chain", prediction, "simulate_chain")
    tm.patch("rules + document", target_sequence, "document_for")
    tm.patch("chain: track step", chain_sim, "_track_step")
    tm.patch("chain: hazcam handoff", chain_sim, "_hazcam_handoff")
    tm.patch("chain: draped template", chain_sim, "_draped_template")
    tm.patch("chain: NCC track", tracking, "track")
    for meth in ("render", "occluded", "cast"):
        setattr(Terrain, meth, tm.wrap(f"terrain.{meth} (all stages)", getattr(Terrain, meth)))
    RoverConfig.point_at = tm.wrap("mast point_at (all stages)", RoverConfig.point_at)
    captured = {}
    make_sequence = target_sequence.make_sequence

    def capture(*a, **k):
        res = make_sequence(*a, **k)
        captured["res"] = res
        captured["rover_config"] = a[0].downlink.rover_config
        captured["params"] = k.get("params")
        return res

    target_sequence.make_sequence = capture
    sys.argv = ["scipctl", *args]
    rc = 0
    out_buf = _Capture()
    real_stdout = sys.stdout
    sys.stdout = out_buf
    try:
        cli.app()
    except SystemExit as e:
        rc = e.code if isinstance(e.code, int) else (0 if e.code is None else 1)
    finally:
        sys.stdout = real_stdout
    c_end, w_end = time.process_time(), time.perf_counter()
    stages = {"imports": {"cpu_s": c_imported - c_start, "wall_s": w_imported - w_start, "calls": 1}}
    for k in tm.cpu:
        stages[k] = {"cpu_s": tm.cpu[k], "wall_s": tm.wall[k], "calls": tm.calls[k]}
    stages["total (in process)"] = {"cpu_s": c_end - c_start, "wall_s": w_end - w_start, "calls": 1}
    stages_out.write_text(json.dumps(stages, indent=1))
    if snapshot_out:
        Path(snapshot_out).write_text(json.dumps(_snapshot(case, args, rc, out_buf.text(), captured), indent=1,
                                                 sort_keys=True, default=_jsonable))
    return 0


class _Capture:
    def __init__(self):
        self.parts = []

    def write(self, s):
        self.parts.append(s)
        return len(s)

    def flush(self):
        pass

    def text(self):
        return "".join(self.parts)


def _jsonable(x):
    import numpy as np

    if isinstance(x, np.ndarray):
        return x.tolist()
    if isinstance(x, np.generic):
        return x.item()
    raise TypeError(f"not JSON: {type(x)}")


def _snapshot(case, args, rc, stdout, captured) -> dict:
    """Everything the command answered, at full precision (JSON floats are repr: exact)."""
    import numpy as np

    snap = {"case": case, "rc": rc}
    summary = json.loads(stdout) if stdout.strip() else None
    if isinstance(summary, dict):
        summary.pop("seconds", None)
    snap["summary"] = summary
    out = Path(args[args.index("-o") + 1])
    snap["document"] = out.read_text() if out.exists() else None
    if "res" in captured:
        doc, checks, pred, record = captured["res"]
        d = pred.to_dict()
        d.pop("seconds", None)
        snap["prediction"] = d
        snap["checks"] = [c.to_dict() for c in checks]
        snap["record"] = record.to_dict()
        views = pred.views
        if not views:  # the command did not render them (only the report shows them): render them here
            import copy

            from scipctl.pipeline.predict import PredictParams, check_views

            views = check_views(copy.deepcopy(pred.plan), pred.terrain, captured["rover_config"],
                                pred.surface_point_site, captured["params"] or PredictParams(), render=True)
        snap["views_sha256"] = hashes = {}
        for key, v in sorted(views.items(), key=lambda kv: str(kv[0])):
            h = hashlib.sha256()
            for a in (v.image, v.depth_m):
                h.update(np.ascontiguousarray(a).tobytes())
            hashes[str(key)] = h.hexdigest()
    return snap


# ---------------------------------------------------------------------------------------------- the parent
def _compare(a, b, path="") -> str | None:
    if type(a) is not type(b):
        return f"{path}: {type(a).__name__} {a!r:.80} != {type(b).__name__} {b!r:.80}"
    if isinstance(a, dict):
        if set(a) != set(b):
            return f"{path}: keys differ: {sorted(set(a) ^ set(b))}"
        for k in sorted(a):
            r = _compare(a[k], b[k], f"{path}.{k}")
            if r:
                return r
        return None
    if isinstance(a, list):
        if len(a) != len(b):
            return f"{path}: length {len(a)} != {len(b)}"
        for i, (x, y) in enumerate(zip(a, b)):
            r = _compare(x, y, f"{path}[{i}]")
            if r:
                return r
        return None
    if a != a and b != b:  # NaN == NaN here
        return None
    return None if a == b else f"{path}: {a!r:.120} != {b!r:.120}"


def compare(dir_a: Path, dir_b: Path) -> int:
    names = sorted(p.name for p in dir_a.glob("*.json"))
    if not names or names != sorted(p.name for p in dir_b.glob("*.json")):
        print(f"snapshots differ in their cases: {names} vs {sorted(p.name for p in dir_b.glob('*.json'))}")
        return 1
    bad = 0
    for n in names:
        diff = _compare(json.loads((dir_a / n).read_text()), json.loads((dir_b / n).read_text()))
        print(f"{n}: {'identical' if diff is None else 'DIFFERENT ' + diff}")
        bad += diff is not None
    return 1 if bad else 0


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if argv[:1] == ["--child"]:  # the in-process run: --child CASE STAGES_OUT SNAPSHOT_OUT|- SCIPCTL_ARGS...
        case, stages_out, snap = argv[1], Path(argv[2]), argv[3]
        return _child(case, argv[4:], stages_out, None if snap == "-" else snap)
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--cases", default=",".join(CASES))
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--stages", action="store_true", help="per-stage CPU and wall (more in-process runs per case)")
    ap.add_argument("--stage-runs", type=int, default=1, help="in-process runs per case for --stages (median per stage)")
    ap.add_argument("--snapshot", type=Path, help="write each case's full-precision answers to DIR/<case>.json")
    ap.add_argument("--code", type=Path, default=ROOT, help="the scipctl checkout to run (default: this one)")
    ap.add_argument("--workdir", type=Path, help="where the workspace and outputs go (default: a temporary directory);"
                    " give the same one to runs whose snapshots are compared: the command lines and r1's designation"
                    " record (it carries its time) are then the same")
    ap.add_argument("--versus", type=Path, help="also time this checkout, runs alternating with --code's")
    ap.add_argument("--compare", nargs=2, type=Path, metavar=("A", "B"))
    ap.add_argument("--json", action="store_true")
    a = ap.parse_args(argv)
    if a.compare:
        return compare(*a.compare)
    code = a.code.resolve()
    cases = [c for c in a.cases.split(",") if c]
    if a.snapshot:
        a.snapshot.mkdir(parents=True, exist_ok=True)
    results = {"code": str(code), "cpus": os.cpu_count(), "load_before": os.getloadavg(), "cases": {}}
    with tempfile.TemporaryDirectory(prefix="seq-speed-") as t:
        tmp = Path(t) if a.workdir is None else a.workdir.resolve()
        tmp.mkdir(parents=True, exist_ok=True)
        ws = _workspace(tmp, code) if "r1" in cases else None
        for case in cases:
            runs, vs_runs = [], []
            for i in range(a.repeat):
                order = [(code, runs)] + ([(a.versus.resolve(), vs_runs)] if a.versus else [])
                for c, into in (order if i % 2 == 0 else order[::-1]):
                    out = Path(f"{case}-{i}.json")
                    r = _scipctl(_sequence_args(case, ws, out), c, tmp)
                    if r["rc"] not in (0, 1):
                        raise SystemExit(f"sequence --target {case} exited {r['rc']} ({c}):\n{r['stderr'][-2000:]}")
                    into.append({"wall_s": r["wall_s"], "cpu_s": r["cpu_s"], "rc": r["rc"], "load1": os.getloadavg()[0]})
            res = _summary(runs)
            if a.versus:
                res["versus"] = _summary(vs_runs)
                res["versus"]["code"] = str(a.versus.resolve())
            if a.stages or a.snapshot:
                runs_st = []
                for j in range(max(1, a.stage_runs)):
                    out = Path(f"{case}-stages-out.json")
                    if (tmp / out).exists():
                        (tmp / out).unlink()
                    st = tmp / f"{case}-stages.json"
                    snap = str((a.snapshot / f"{case}.json").resolve()) if a.snapshot and j == 0 else "-"
                    r = _run([sys.executable, str(Path(__file__).resolve()), "--child", case, str(st), snap,
                              *_sequence_args(case, ws, out)], code, tmp)
                    if r["rc"] != 0:
                        raise SystemExit(f"stage run of {case} failed:\n{r['stderr'][-3000:]}")
                    runs_st.append(json.loads(st.read_text()))
                # per stage, the median over the runs
                res["stages"] = {k: {f: statistics.median(x[k][f] for x in runs_st) for f in ("cpu_s", "wall_s", "calls")}
                                 for k in runs_st[0]}
                res["stage_runs"] = len(runs_st)
            results["cases"][case] = res
            _print_case(case, res) if not a.json else None
    results["load_after"] = os.getloadavg()
    if a.json:
        print(json.dumps(results, indent=1))
    else:
        print(f"load average before {tuple(round(x, 2) for x in results['load_before'])}, "
              f"after {tuple(round(x, 2) for x in results['load_after'])}; {results['cpus']} CPUs; code {code}")
    return 0


def _summary(runs: list) -> dict:
    return {"runs": runs, "rc": runs[0]["rc"] if runs else None,
            "wall_s_median": statistics.median(x["wall_s"] for x in runs) if runs else None,
            "cpu_s_median": statistics.median(x["cpu_s"] for x in runs) if runs else None,
            "wall_s_min": min((x["wall_s"] for x in runs), default=None),
            "cpu_s_min": min((x["cpu_s"] for x in runs), default=None)}


def _print_runs(label, res):
    runs = res["runs"]
    line = ", ".join(f"{x['wall_s']:.2f}/{x['cpu_s']:.2f} (load {x['load1']:.1f})" for x in runs)
    print(f"{label}: exit {res['rc']}; wall/CPU s per run: {line}; median wall {res['wall_s_median']:.2f} s, "
          f"CPU {res['cpu_s_median']:.2f} s" if runs else f"{label}: no timed run")


def _print_case(case, res):
    _print_runs(case, res)
    if "versus" in res:
        _print_runs(f"{case} versus {res['versus']['code']}", res["versus"])
    if "stages" in res:
        for k, v in res["stages"].items():
            print(f"    {k:34s} CPU {v['cpu_s']:6.2f} s  wall {v['wall_s']:6.2f} s  ({v['calls']:g} calls)")
    sys.stdout.flush()


if __name__ == "__main__":
    sys.exit(main())
