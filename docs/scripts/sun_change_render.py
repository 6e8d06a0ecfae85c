"""Render a downlink whose designation images were taken under another sun (docs/stereo-and-tracking.md,
"The designation under another sun").

    python docs/scripts/sun_change_render.py FAMILY SEED RUN OUT_DIR --shift AZ_DEG:EL_DEG [--shift ...]
                                             [--image-scale S]

SCIP designates today and drives tomorrow: the 10 m pancam images the operator designates in come from the
sol before the approach, at another time of day, while the simulator renders every stop of a run under one sun.
This writes ``OUT_DIR/control/paper-RUN.mcap``, exactly what ``scipctl synth --scenario paper --seed SEED --family
FAMILY --runs RUN`` writes (same images, same bytes), and for each ``--shift`` a copy
``OUT_DIR/sun<AZ>_<EL>/paper-RUN.mcap`` in which only the designation stop's images (``pan10``, both pancams) are
rendered again with the sun moved by AZ_DEG in azimuth (clockwise seen from above: north -> east) and EL_DEG in
elevation; every other image, pose, model, mark and truth is the control's. Each copy has its ``.sim.json``
(the control's record with ``designation_sun``: the shift, the sun direction the pan10 images were rendered
with, and the command). Paired: the same scenes, the same sensor noise, one change.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np

SCENARIO = "paper"
DESIGNATION_STOP = "pan10"
MIN_ELEVATION_DEG = 2.0


def parse_shift(spec: str) -> tuple:
    """``AZ_DEG:EL_DEG`` -> (az_deg, el_deg); ValueError naming the option when malformed or out of range."""
    parts = spec.split(":")
    if len(parts) != 2:
        raise ValueError(f"--shift: expected AZ_DEG:EL_DEG, got {spec!r}")
    try:
        az, el = float(parts[0]), float(parts[1])
    except ValueError:
        raise ValueError(f"--shift: AZ_DEG and EL_DEG must be numbers, got {spec!r}") from None
    if not (math.isfinite(az) and math.isfinite(el) and -180.0 <= az <= 180.0 and -60.0 <= el <= 60.0):
        raise ValueError(f"--shift: want AZ_DEG in [-180, 180] and EL_DEG in [-60, 60], got {spec!r}")
    return az, el


def shifted_sun(sun_dir_site: np.ndarray, az_deg: float, el_deg: float) -> np.ndarray:
    """The unit vector towards the sun ``sun_dir_site`` ``(3,)`` (site frame: x north, y east, z down) moved by
    ``az_deg`` of azimuth (north -> east positive) and ``el_deg`` of elevation, the elevation kept in
    [MIN_ELEVATION_DEG, 89] degrees. Returns ``(3,)``, unit length."""
    s = np.asarray(sun_dir_site, float)
    if s.shape != (3,) or not np.all(np.isfinite(s)) or np.linalg.norm(s) == 0.0:
        raise ValueError(f"sun_dir_site: expected a finite non-zero (3,) vector, got {s!r}")
    s = s / np.linalg.norm(s)
    az = math.atan2(s[1], s[0]) + math.radians(az_deg)
    el = math.asin(max(-1.0, min(1.0, -s[2]))) + math.radians(el_deg)
    el = min(max(el, math.radians(MIN_ELEVATION_DEG)), math.radians(89.0))
    return np.array([math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), -math.sin(el)])


def shift_name(az_deg: float, el_deg: float) -> str:
    return f"sun{az_deg:+g}_{el_deg:+g}".replace("+", "p").replace("-", "m")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("family")
    ap.add_argument("seed", type=int)
    ap.add_argument("run")
    ap.add_argument("out", type=Path)
    ap.add_argument("--shift", action="append", default=[], metavar="AZ_DEG:EL_DEG")
    ap.add_argument("--image-scale", type=float, default=1.0)
    a = ap.parse_args(argv)
    try:
        shifts = [parse_shift(s) for s in a.shift]
    except ValueError as e:
        ap.error(str(e))
    from scipctl.sim.families import FAMILIES

    if a.family not in FAMILIES:
        ap.error(f"FAMILY: unknown {a.family!r} (want one of {', '.join(FAMILIES)})")

    from scipctl import __version__
    from scipctl.commands.synth import record_json, regenerate_command
    from scipctl.io.atomic import atomic_write_text
    from scipctl.io.downlink import write_downlink
    from scipctl.sim.build import build_run, render_stops
    from scipctl.sim.families import family_of_run
    from scipctl.sim.scenarios import default_errors

    fam = family_of_run(a.family, SCENARIO, a.run, a.seed)
    errors = default_errors(SCENARIO).scaled(fam.error_scale)  # what build_run uses for the family
    supersample = 2
    sim = build_run(SCENARIO, a.run, a.seed, image_scale=a.image_scale, supersample=supersample, family=a.family)
    name = f"{SCENARIO}-{a.run}"
    rec = dict(sim.record)
    rec["written_by"] = {"tool": "scipctl", "version": __version__,
                         "regenerate": regenerate_command(SCENARIO, a.seed, "mcap", a.run, False, a.image_scale,
                                                          supersample, f"--family {a.family}")}
    rec["no_errors"] = False
    ctrl = a.out / "control"
    ctrl.mkdir(parents=True, exist_ok=True)
    write_downlink(sim.downlink, ctrl / f"{name}.mcap", "mcap")
    atomic_write_text(ctrl / f"{name}.sim.json", record_json(rec))
    print(ctrl / f"{name}.mcap")
    pngs = {im.product_id: im.png for im in sim.downlink.images}
    for az, el in shifts:
        sun = shifted_sun(sim.scene.sun_dir_site, az, el)
        new = render_stops(sim, errors, {DESIGNATION_STOP}, supersample, scene=replace(sim.scene, sun_dir_site=sun))
        for im in sim.downlink.images:
            im.png = new.get(im.product_id, pngs[im.product_id])
        folder = a.out / shift_name(az, el)
        folder.mkdir(parents=True, exist_ok=True)
        write_downlink(sim.downlink, folder / f"{name}.mcap", "mcap")
        cmd = " ".join(["python docs/scripts/sun_change_render.py", a.family, str(a.seed), a.run, "OUT",
                        f"--shift {az:g}:{el:g}"] + ([f"--image-scale {a.image_scale:g}"] if a.image_scale != 1.0 else []))
        vrec = dict(rec, designation_sun={"stop": DESIGNATION_STOP, "shift_az_deg": az, "shift_el_deg": el,
                                          "sun_dir_site": sun.tolist(), "products": sorted(new), "command": cmd})
        atomic_write_text(folder / f"{name}.sim.json", record_json(vrec))
        print(folder / f"{name}.mcap")
    for im in sim.downlink.images:
        im.png = pngs[im.product_id]
    return 0


if __name__ == "__main__":
    sys.exit(main())
