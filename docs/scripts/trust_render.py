"""Render simulated downlinks for the trust model of ``scip`` (docs/handoff.md, "Trust: scip").

    python docs/scripts/trust_render.py FAMILY SEED RUN OUT_DIR [--extra N] [--occluded M] [--shallow K]
                                        [--stale CAMERA:BASELINE_SCALE[:FOCAL_SCALE]]

One run of the ``paper`` scenario, of one scene family, written as ``OUT_DIR/<family>-<seed>-<run>.mcap``
with ``N`` extra targets (random true surface points near the rock, seen by the near hazcam pair and the near
navcam pair, exact marks: ``scipctl.sim.extra_targets``) besides the run's three, and up to ``M`` occluded
targets (true surface points the near navcam pair sees and something hides from the near left hazcam, >= 5 cm
in front, over the whole 4 px disk around the point's pixel; ids ``o01``...: ``choose_occluded_targets``). An occluded target has navcam marks and
no mark in the left hazcam; the ``.sim.json`` lists it under ``occluded_targets``, and ``scipctl trust-evidence``
labels every hazcam answer for it wrong. ``--shallow K`` first stands up to ``K`` pebbles in the scene, each
a few centimetres in front of a surface point on the near left hazcam's line of sight, hiding it over the same disk
while the navcams still see it (ids ``p01``...: ``scipctl.sim.occluders``); they are listed under
``shallow_occluders`` and their points under ``occluded_targets`` too. ``--stale navcam:1.01`` renders with a stale
calibration of that camera pair (``ErrorSettings.stale_camera``: the true right eye 1 % farther along the baseline
than the downlinked model says, and the focal length of both eyes times FOCAL_SCALE, default 1), on top of the
family's errors. Only the images the handoff
uses (the ``near`` and ``far`` stops) are rendered, as ``scipctl synth`` renders them (same exposure, noise
and seeds); the pancam and mid-stop images are left black, to halve the rendering time.

FAMILY is one of the six trust families below (scene draw = seed; error settings; rover; texture), or any
other name of the simulator's scene families (``scipctl.sim.families.FAMILIES``: ``bedrock-slabs``,
``sand-sheet``, ``pebble-field``, ``angular-rocks``, ``low-sun``, ...; its terrain, rocks, sun, error scale,
rover and texture as ``scipctl synth --family`` builds them; ``mixed`` realised per scene from the seed). The six
keep their own settings and output (``m2020`` is the trust family below, not the simulator's family of that name):

* ``paper``: the scenario's default errors;
* ``noerr``: ``ErrorSettings.none()``;
* ``err05`` / ``err2``: every geometric error (mast calibration, odometry, tilt sensor, vibration, pointing)
  scaled by 0.5 / 2, radiometry as the default;
* ``m2020``: default errors, the Mars 2020 rover (``$SCIPCTL_SHARED_REAL/12_*``);
* ``mars-tex``: default errors, the terrain textured from real Mars navcam pictures
  (``$SCIPCTL_SHARED_REAL/05_dora_msl_navcam_left``).

A ``.sim.json`` record beside it says the family (``family``: the name given), settings and the extra targets;
for a simulator family also ``scene_family``, the realised :class:`~scipctl.sim.families.SceneFamily`.
"""

from __future__ import annotations

import argparse
import json
import os
from dataclasses import replace
from pathlib import Path

import numpy as np

SCALED_FIELDS = ("mast_tilt_offset_rad", "mast_pan_offset_rad", "mast_tilt_axis_error_rad", "odometry_scale_sigma",
                 "odometry_scale_leg_sigma", "heading_drift_sigma_rad_per_m", "heading_noise_sigma_rad",
                 "turn_scale_sigma", "tilt_sensor_sigma_rad", "vibration_max_rad", "pointing_noise_frac")
TRUST_FAMILIES = ("paper", "noerr", "err05", "err2", "m2020", "mars-tex")
SCENARIO = "paper"


def family_names() -> list:
    """Every FAMILY this script takes: the six trust families, then the simulator's other families."""
    from scipctl.sim.families import FAMILIES as SIM_FAMILIES

    return list(TRUST_FAMILIES) + [f for f in SIM_FAMILIES if f not in TRUST_FAMILIES]


def scaled_errors(base, s: float):
    kw = {f: getattr(base, f) * s for f in SCALED_FIELDS}
    kw["mast_head_offset_m"] = tuple(x * s for x in base.mast_head_offset_m)
    return replace(base, **kw)


def family_settings(family: str):
    """(errors, rover, texture) of one of the six trust families (``TRUST_FAMILIES``)."""
    from scipctl.sim.errors import ErrorSettings
    from scipctl.sim.scenarios import default_errors

    real = Path(os.environ.get("SCIPCTL_SHARED_REAL", "/work/shared/real"))
    errors, rover, texture = default_errors(SCENARIO), None, None
    if family == "noerr":
        errors = ErrorSettings.none()
    elif family == "err05":
        errors = scaled_errors(errors, 0.5)
    elif family == "err2":
        errors = scaled_errors(errors, 2.0)
    elif family == "m2020":
        from scipctl.commands.synth import m2020_sim_rover

        rover = m2020_sim_rover(sorted(real.glob("12_*"))[0])
    elif family == "mars-tex":
        from scipctl.commands.synth import read_texture_sources

        texture = read_texture_sources(real / "05_dora_msl_navcam_left")
    elif family != "paper":
        raise SystemExit(f"not a trust family: {family!r} (known: {', '.join(TRUST_FAMILIES)})")
    return errors, rover, texture


def stale_settings(spec: str) -> dict:
    """``--stale CAMERA:BASELINE_SCALE[:FOCAL_SCALE]`` -> the ErrorSettings fields it sets; ValueError naming the
    option when the spec is malformed or a scale lies outside (0.5, 2)."""
    parts = spec.split(":")
    if len(parts) not in (2, 3) or parts[0] not in ("navcam", "hazcam", "pancam"):
        raise ValueError(f"--stale: expected CAMERA:BASELINE_SCALE[:FOCAL_SCALE] with CAMERA navcam, hazcam or pancam, "
                         f"got {spec!r}")
    try:
        scales = [float(x) for x in parts[1:]] + [1.0] * (3 - len(parts))
    except ValueError:
        raise ValueError(f"--stale: the scales must be numbers, got {spec!r}") from None
    if not all(0.5 < x < 2.0 for x in scales):
        raise ValueError(f"--stale: the scales must lie in (0.5, 2), got {spec!r}")
    return {"stale_camera": parts[0], "stale_baseline_scale": scales[0], "stale_focal_scale": scales[1]}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("family", choices=family_names())
    ap.add_argument("seed", type=int)
    ap.add_argument("run")
    ap.add_argument("out", type=Path)
    ap.add_argument("--extra", type=int, default=12)
    ap.add_argument("--occluded", type=int, default=0)
    ap.add_argument("--shallow", type=int, default=0)
    ap.add_argument("--stale", default=None, metavar="CAMERA:BASELINE_SCALE[:FOCAL_SCALE]")
    a = ap.parse_args(argv)
    try:
        stale = stale_settings(a.stale) if a.stale else None
    except ValueError as e:
        ap.error(str(e))

    from scipctl import __version__
    from scipctl.io.atomic import atomic_write_text
    from scipctl.io.downlink import write_downlink
    from scipctl.model import TargetTruth
    from scipctl.sim.build import build_run, render_stops
    from scipctl.sim.extra_targets import choose_extra_targets, choose_occluded_targets, extra_marks
    from scipctl.sim.occluders import add_shallow_occluders
    from scipctl.sim.scenarios import _rng

    scene_family = None
    if a.family in TRUST_FAMILIES:
        errors, rover, texture = family_settings(a.family)
        errors = replace(errors, **stale) if stale else errors
        sim = build_run(SCENARIO, a.run, a.seed, errors=errors, render=False, rover=rover, texture=texture)
    else:
        from scipctl.sim.families import family_of_run
        from scipctl.sim.scenarios import default_errors

        scene_family = family_of_run(a.family, SCENARIO, a.run, a.seed)
        errors = default_errors(SCENARIO).scaled(scene_family.error_scale)  # what build_run uses for the family
        errors = replace(errors, **stale) if stale else errors
        sim = build_run(SCENARIO, a.run, a.seed, errors=errors, render=False, family=scene_family)
    pid = {(p.stop, p.camera, p.eye): p.product_id for p in sim.products}
    haz = pid[("near", "hazcam", "left")]
    req = [pid[("near", "hazcam", "right")], pid[("near", "navcam", "left")], pid[("near", "navcam", "right")]]
    # pebbles first: the targets drawn below are drawn in the scene that is rendered
    protect = np.array([t.xyz_site_m for t in sim.downlink.truth_targets], float).reshape(-1, 3)
    shallow = []
    if a.shallow > 0:
        scene, shallow = add_shallow_occluders(sim.scene, sim.products, haz, req[1:], protect, a.shallow,
                                               _rng(a.seed, SCENARIO, a.run, "shallow-occluders"))
        sim = replace(sim, scene=scene)
    extra = choose_extra_targets(sim.scene, sim.products, haz, req, a.extra, _rng(a.seed, SCENARIO, a.run, "extra-targets"))
    hidden = (choose_occluded_targets(sim.scene, sim.products, haz, req[1:], a.occluded,
                                      _rng(a.seed, SCENARIO, a.run, "occluded-targets")) if a.occluded > 0 else [])
    hidden = [(s.target, s.depth_m, s.hazcam_uv) for s in shallow] + hidden
    extra_all = extra + [t for t, _, _ in hidden]
    sim.downlink.targets.extend(extra_marks(sim.scene, sim.products, extra_all))
    sim.downlink.truth_targets.extend(TargetTruth(t.id, np.asarray(t.xyz_site_m, float)) for t in extra_all)
    pngs = render_stops(sim, errors, {"near", "far"})  # the handoff's stops only, rendered as build_run renders them
    for im in sim.downlink.images:
        im.png = pngs.get(im.product_id, im.png)
    a.out.mkdir(parents=True, exist_ok=True)
    name = f"{a.family}-{a.seed}-{a.run}"
    path = write_downlink(sim.downlink, a.out / f"{name}.mcap", "mcap")
    rec = dict(sim.record, family=a.family, extra_targets=[{"id": t.id, "xyz_site_m": t.xyz_site_m.tolist()} for t in extra],
               occluded_targets=[{"id": t.id, "xyz_site_m": t.xyz_site_m.tolist(), "hidden_in": haz,
                                  "occluder_depth_m": dep, "hidden_uv": uv.tolist()} for t, dep, uv in hidden],
               rendered_stops=["near", "far"],
               written_by={"tool": "scipctl", "version": __version__,
                           "regenerate": f"python docs/scripts/trust_render.py {a.family} {a.seed} {a.run} OUT --extra {a.extra}"
                                         + (f" --occluded {a.occluded}" if a.occluded else "")
                                         + (f" --shallow {a.shallow}" if a.shallow else "")
                                         + (f" --stale {a.stale}" if a.stale else "")})
    if a.shallow > 0:  # only then: the records of the other commands keep their bytes
        rec["shallow_occluders"] = [{"name": s.rock.name, "hides": s.target.id, "centre_xy_m": s.rock.centre_xy_m.tolist(),
                                     "size_m": s.rock.size_m.tolist()} for s in shallow]
    if scene_family is not None:
        rec["scene_family"] = scene_family.to_dict()
    atomic_write_text(a.out / f"{name}.sim.json", json.dumps(rec, indent=1, sort_keys=True, default=str) + "\n")
    print(path)


if __name__ == "__main__":
    main()
