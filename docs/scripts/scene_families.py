"""Measurements of the scene families for docs/simulator.md ("Scene families").

    .venv/bin/python docs/scripts/scene_families.py targets [--seeds 0-4] [--families a,b]
        choose_targets for every paper and traverse run of each seed (render=False, image scale 0.125):
        runs with 3 targets, target kinds, fewest marks per target, failures.
    .venv/bin/python docs/scripts/scene_families.py cpu [--scale 0.5] [--seed 0] [--families a,b] [--out DIR]
        CPU seconds (time.process_time: every thread of the process) to build one paper s1-straight downlink per
        family: scene + 12 images (2 x 2 samples) + targets, after a warm-up build (imports); then the 12 images
        of some families again without shadow rays (the shadows' share). --out DIR keeps the left images as PNG.
    .venv/bin/python docs/scripts/scene_families.py sheet DIR OUT.png [--view near-navcam] [--tile 128] [--levels 16]
        a contact sheet of one left image per family from a --out DIR (grey levels quantised to keep it small).

Families that read shared/real need it beside the checkout or SCIPCTL_SHARED_REAL.
"""

import argparse
import collections
import json
import time
from pathlib import Path

import numpy as np


def _families(arg):
    from scipctl.sim.families import FAMILIES

    return arg.split(",") if arg else list(FAMILIES)


def _seeds(arg):
    a, _, b = arg.partition("-")
    return range(int(a), int(b or a) + 1)


def targets(a):
    from scipctl.sim.build import _SCENES, build_run
    from scipctl.sim.scenarios import list_runs

    out = {}
    for name in _families(a.families):
        t0 = time.process_time()
        n = n_ok = 0
        kinds, fails, min_marks = collections.Counter(), [], None
        for seed in _seeds(a.seeds):
            for scenario in ("paper", "traverse"):
                for run in list_runs(scenario):
                    n += 1
                    try:
                        sim = build_run(scenario, run, seed, image_scale=0.125, supersample=1, render=False, family=name)
                    except Exception as e:  # report, keep going
                        fails.append(f"{scenario} {run} seed {seed}: {type(e).__name__}: {e}")
                        continue
                    ts = sim.record["targets"]
                    kinds.update(t["kind"] for t in ts)
                    n_ok += len(ts) == 3
                    if len(ts) != 3:
                        fails.append(f"{scenario} {run} seed {seed}: {len(ts)} targets")
                    m = min(t["n_marks"] for t in ts) if ts else 0
                    min_marks = m if min_marks is None else min(min_marks, m)
            _SCENES.clear()
        out[name] = {"runs": n, "with_3_targets": n_ok, "kinds": dict(kinds), "min_marks_per_target": min_marks,
                     "fails": fails, "cpu_s": round(time.process_time() - t0, 1)}
        print(name, json.dumps(out[name]), flush=True)


def cpu(a):
    from scipctl.sim.build import _SCENES, build_run
    from scipctl.sim.render import render_radiance

    build_run("paper", "s1-straight", a.seed, image_scale=0.125, supersample=1, render=True)  # warm-up: imports
    out_dir = Path(a.out) if a.out else None
    if out_dir:
        out_dir.mkdir(parents=True, exist_ok=True)
    for name in _families(a.families):
        _SCENES.clear()
        t0 = time.process_time()
        sim = build_run("paper", "s1-straight", a.seed, image_scale=a.scale, supersample=2, render=True, family=name)
        total = time.process_time() - t0
        el = float(np.degrees(np.arcsin(-sim.scene.sun_dir_site[2])))
        line = f"{name:18s} downlink {total:6.1f} CPU-s  sun {el:4.1f} deg  targets {[t['kind'] for t in sim.record['targets']]}"
        if name in a.shadow_families.split(","):
            t = {}
            for shadows in (True, False):
                t0 = time.process_time()
                for p in sim.products:
                    render_radiance(sim.scene, p.model_true_site, p.width, p.height, 2, shadows=shadows)
                t[shadows] = time.process_time() - t0
            line += f"  12 images: {t[True]:.1f} CPU-s with shadows, {t[False]:.1f} without"
        print(line, flush=True)
        if out_dir:
            import cv2

            for im in sim.downlink.images:
                if im.eye == "left":
                    px = im.pixels if im.pixels.dtype == np.uint8 else (im.pixels >> 8).astype(np.uint8)
                    cv2.imwrite(str(out_dir / f"{name}__{im.product_id}.png"), px)


def sheet(a):
    import cv2

    from scipctl.sim.families import FAMILIES

    d, tile = Path(a.dir), a.tile
    cells = []
    for name in FAMILIES:
        im = cv2.imread(str(next(d.glob(f"{name}__*-{a.view}-L.png"))), cv2.IMREAD_GRAYSCALE)
        h, w = im.shape
        im = cv2.resize(im, (tile, int(round(h * tile / w))), interpolation=cv2.INTER_AREA)
        canvas = np.full((tile, tile), 255, np.uint8)
        top = (tile - im.shape[0]) // 2
        canvas[top:top + im.shape[0]] = im
        label = np.full((16, tile), 255, np.uint8)
        cv2.putText(label, name, (3, 12), cv2.FONT_HERSHEY_SIMPLEX, 0.4, 0, 1, cv2.LINE_AA)
        cells.append(np.pad(np.vstack([label, canvas]), ((0, 0), (0, 4)), constant_values=255))
    rows = [np.hstack(cells[i:i + 4] + [np.full_like(cells[0], 255)] * (4 - len(cells[i:i + 4]))) for i in range(0, len(cells), 4)]
    s = np.vstack(rows).astype(float)
    q = np.round(s / 255 * (a.levels - 1)) * (255 / (a.levels - 1))
    cv2.imwrite(a.out, q.astype(np.uint8), [cv2.IMWRITE_PNG_COMPRESSION, 9])


def main():
    ap = argparse.ArgumentParser()
    sub = ap.add_subparsers(dest="what", required=True)
    t = sub.add_parser("targets")
    t.add_argument("--seeds", default="0-4")
    t.add_argument("--families", default="")
    c = sub.add_parser("cpu")
    c.add_argument("--scale", type=float, default=0.5)
    c.add_argument("--seed", type=int, default=0)
    c.add_argument("--families", default="")
    c.add_argument("--shadow-families", default="default,low-sun,high-sun")
    c.add_argument("--out", default="")
    s = sub.add_parser("sheet")
    s.add_argument("dir")
    s.add_argument("out")
    s.add_argument("--view", default="near-navcam")
    s.add_argument("--tile", type=int, default=128)
    s.add_argument("--levels", type=int, default=16)
    a = ap.parse_args()
    {"targets": targets, "cpu": cpu, "sheet": sheet}[a.what](a)


if __name__ == "__main__":
    main()
