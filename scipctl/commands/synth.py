"""``scipctl synth``: render synthetic downlinks with exact truth (see docs/simulator.md).

One downlink per run is written into OUT: ``OUT/<scenario>-<run>.mcap`` (or
the directory ``OUT/<scenario>-<run>/``), plus ``OUT/<scenario>-<run>.sim.json``,
the simulation record (error settings and every realised error, true and
estimated poses, target selection). Same arguments, same bytes: nothing in
the data depends on the clock or on the output path.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Optional

from ..model import InputError
from ..jsonutil import json_default


def regenerate_command(scenario: str, seed: int, container: str, run: str, no_errors: bool,
                       image_scale: float = 1.0, supersample: int = 2) -> str:
    env = ""
    if image_scale != 1.0:
        env += f"SCIPCTL_SYNTH_IMAGE_SCALE={image_scale:g} "
    if supersample != 2:
        env += f"SCIPCTL_SYNTH_SUPERSAMPLE={supersample} "
    cmd = f"{env}scipctl synth --scenario {scenario} --seed {seed} --container {container} --runs {run}"
    return cmd + (" --no-errors" if no_errors else "") + " -o OUT"


def record_json(record: dict) -> str:
    """The simulation record as deterministic JSON text."""
    return json.dumps(record, indent=1, sort_keys=True, allow_nan=False, default=_plain) + "\n"


_plain = json_default


def run(scenario: str, seed: int, out: Path, container: str, runs: Optional[str], no_errors: bool, json_out: bool) -> None:
    from ..sim.scenarios import SCENARIOS, list_runs

    if scenario not in SCENARIOS:
        raise InputError("synth", "--scenario", f"unknown scenario {scenario!r} (want one of: {', '.join(SCENARIOS)})")
    if container not in ("mcap", "dir"):
        raise InputError("synth", "--container", f"unknown container {container!r} (want mcap or dir)")
    known = list_runs(scenario)
    if runs is None or not runs.strip():
        selected = known
    else:
        selected = [r.strip() for r in runs.split(",") if r.strip()]
        bad = [r for r in selected if r not in known]
        if bad:
            raise InputError("synth", "--runs", f"unknown run(s) {', '.join(bad)} for scenario {scenario} (known: {', '.join(known)})")
        selected = list(dict.fromkeys(selected))
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise InputError(str(out), "-o/--out", "exists and is not a directory")
    image_scale, supersample = _env_quality()
    written = synthesize(scenario, seed, out, container, selected, no_errors, image_scale=image_scale, supersample=supersample)
    if json_out:
        from ..cli import emit_json

        emit_json({"scenario": scenario, "seed": seed, "container": container, "no_errors": no_errors, "runs": written})
    else:
        for w in written:
            sys.stdout.write(f"{w['path']}  ({w['images']} images, {len(w['targets'])} targets, {w['bytes']} bytes)\n")


def _env_quality() -> tuple[float, int]:
    """Preview/test hooks: ``SCIPCTL_SYNTH_IMAGE_SCALE`` (e.g. 0.125 -> 128 x 128 images) and
    ``SCIPCTL_SYNTH_SUPERSAMPLE`` (samples per pixel side, default 2). Both are recorded in the .sim.json."""
    import os

    raw_s = os.environ.get("SCIPCTL_SYNTH_IMAGE_SCALE", "1")
    raw_q = os.environ.get("SCIPCTL_SYNTH_SUPERSAMPLE", "2")
    try:
        scale = float(raw_s)
        if not (0 < scale <= 1) or abs(1024 * scale - round(1024 * scale)) > 1e-9:
            raise ValueError
    except ValueError:
        raise InputError("environment", "SCIPCTL_SYNTH_IMAGE_SCALE", f"{raw_s!r}: want a number in (0, 1] with 1024 x scale whole") from None
    try:
        ss = int(raw_q)
        if not 1 <= ss <= 8:
            raise ValueError
    except ValueError:
        raise InputError("environment", "SCIPCTL_SYNTH_SUPERSAMPLE", f"{raw_q!r}: want an integer 1 .. 8") from None
    return scale, ss


def synthesize(scenario: str, seed: int, out: Path, container: str, runs: list, no_errors: bool,
               image_scale: float = 1.0, supersample: int = 2, show_progress: bool = True) -> list[dict]:
    """Build and write each run; returns one summary per run (path, counts, sha256)."""
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

    from ..io.atomic import atomic_write_text
    from ..io.downlink import write_downlink
    from ..io.provenance import sha256_path
    from ..sim.errors import ErrorSettings
    from ..sim.scenarios import build_run, default_errors

    out.mkdir(parents=True, exist_ok=True)
    from ..cli import stderr_console

    console = stderr_console()
    written = []
    with Progress(TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn(),
                  console=console, disable=not show_progress, transient=False) as bar:
        for run_name in runs:
            name = f"{scenario}-{run_name}"
            task = bar.add_task(f"{name}: scene", total=None)

            def cb(done, total, pid, task=task, name=name):
                bar.update(task, total=total, completed=done, description=f"{name}: {pid}")

            errors = ErrorSettings.none() if no_errors else default_errors(scenario)
            sim = build_run(scenario, run_name, seed, errors=errors, image_scale=image_scale, supersample=supersample, progress=cb)
            path = out / (f"{name}.mcap" if container == "mcap" else name)
            bar.update(task, description=f"{name}: writing {path.name}")
            write_downlink(sim.downlink, path, container)
            rec = dict(sim.record)
            from .. import __version__

            rec["written_by"] = {"tool": "scipctl", "version": __version__,
                                 "regenerate": regenerate_command(scenario, seed, container, run_name, no_errors,
                                                                 image_scale, supersample)}
            rec["no_errors"] = bool(no_errors)
            rec_path = out / f"{name}.sim.json"
            atomic_write_text(rec_path, record_json(rec))
            bar.update(task, description=f"{name}: done")
            written.append({
                "run": run_name, "path": str(path), "record": str(rec_path), "container": container,
                "images": len(sim.downlink.images), "targets": [t.id for t in sim.downlink.targets],
                "bytes": _size(path), "sha256": sha256_path(path),
            })
    return written


def _size(path: Path) -> int:
    if path.is_file():
        return path.stat().st_size
    return sum(p.stat().st_size for p in path.rglob("*") if p.is_file())
