"""Scenarios: rover approaches to a target rock, as downlinks with exact truth (pure numerics; no files).

``paper`` -- the experiment of the SCIP handoff paper: 3 scenes x {straight,
arc} approaches = 6 runs (``s1-straight``, ``s1-arc``, ... ``s3-arc``). Stops
(distances are ground distances from the named cameras to the centre of the
big rock):

=========  ========================  =====================================
stop       cameras                   place
=========  ========================  =====================================
``pan10``  pancam                    mast 10 m from the rock
``mid``    pancam + navcam           mast 4.5 m
``far``    navcam                    navcams 3 m
``near``   navcam + hazcam           hazcams 1 m, rover facing the rock
=========  ========================  =====================================

``pan10``/``mid``/``far`` lie on the approach bearing; in the ``arc`` run that
bearing is rotated by 30 deg about the rock, so the far navcams see the rock
from 30 deg away from the near stop's line of sight. The near stop is the same
in both runs of a scene (up to 2 cm / 1.5 deg). Mast cameras are pointed at the
rock with ``RoverConfig.point_at`` of the calibrated config (the rover's belief),
for the rock's place relative to the rover as SCIP's tracking measures it.

``traverse`` -- one approach from 10 m with stops every 10-20 % of the
remaining distance (pancam down to ~4.5 m, navcam from ~5 m, hazcams from 2 m
hazcam distance to 1 m), runs ``s1-straight`` and ``s1-curved``.

Each run has 3 marked targets of different kinds (``flat``, ``point``,
``edge``, ``sand``, ``contrast``); the 6 paper runs make the paper's 18 handoff
cases. Marks are the exact projection of the target's true 3-D point through
the true model of every image that sees it (in the image, and not occluded:
checked by a ray cast from the model's ray origin -- the CAHVORE entrance
pupil -- to the point).

This module defines the scenarios (names, stop plans, default errors). Building a run from a plan is
:mod:`.build` (``build_run``), with :mod:`.placement` (true rover poses on the terrain),
:mod:`.products` (the images), :mod:`.targets` (choosing targets) and :mod:`.marks` (exact marks).
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass, field
from typing import Optional

import numpy as np

from . import rover as rover_mod
from .errors import DEG, ErrorSettings

SCENARIOS = ("paper", "traverse")
KINDS = ("flat", "point", "edge", "sand", "contrast")
# the default rover's placement constants (a SimRover carries each rover's own: scipctl/sim/rover.py)
MAST_REF_X_M = rover_mod.DEFAULT_MAST_REF_X_M  # between the pancam and navcam centres
NAVCAM_REF_X_M = rover_mod.DEFAULT_NAVCAM_REF_X_M
HAZCAM_REF_X_M = rover_mod.DEFAULT_HAZCAM_REF_X_M


def _rng(*keys) -> np.random.Generator:
    """A generator seeded from ints and strings (stable across runs and platforms)."""
    ints = []
    for k in keys:
        if isinstance(k, str):
            ints.append(int.from_bytes(hashlib.sha256(k.encode()).digest()[:4], "little"))
        else:
            ints.append(int(k) & 0xFFFFFFFF)
    return np.random.default_rng(np.random.SeedSequence(ints))


def _wrap(a: float) -> float:
    return float((a + np.pi) % (2 * np.pi) - np.pi)


# ----------------------------------------------------------------------------- plans
@dataclass
class StopPlan:
    label: str
    xy_m: np.ndarray  # (2,) true rover origin, site frame
    yaw_rad: float  # true heading
    cameras: tuple  # camera pairs imaged at this stop, in order
    ref_camera: str = "navcam"  # the pair whose ground distance to the rock is ``ref_dist_m``
    ref_dist_m: float = 0.0
    bearing_rad: float = 0.0  # from the rock towards the reference cameras
    path_length_m: float = 0.0  # drive from the previous stop
    turn_rad: float = 0.0
    arc_leg: bool = False  # the drive from the previous stop is an arc (5 % longer than the chord)


@dataclass
class RunPlan:
    scenario: str
    run: str
    seed: int
    scene_index: int
    scene_seed: int
    bearing_rad: float  # from the rock towards the final approach
    sun_azimuth_rad: float
    keep_clear: list
    stops: list  # list[StopPlan]
    kinds: tuple  # target kinds wanted, in order of preference
    key_images: list  # [(stop label, camera)] whose pairs must see every target
    sol: int = 1
    rover: Optional[rover_mod.SimRover] = field(default=None, repr=False)  # None: the default rover

    @property
    def name(self) -> str:
        return f"{self.scenario}-{self.run}"


def _place(ref_x_m: float, dist_m: float, bearing_rad: float, jitter=(0.0, 0.0, 0.0)):
    """Rover origin ``(2,)`` and heading for a camera reference point at ``ref_x_m`` (rover x) that stands
    ``dist_m`` from the rock (at the origin) along ``bearing_rad``, the rover facing the rock."""
    c = dist_m * np.array([np.cos(bearing_rad), np.sin(bearing_rad)])
    yaw = bearing_rad + np.pi + jitter[2]
    xy = c - ref_x_m * np.array([np.cos(yaw), np.sin(yaw)]) + np.array(jitter[:2])
    return xy, _wrap(yaw)


def _finish_legs(stops: list, arc_legs: set = frozenset()) -> list:
    for i in range(1, len(stops)):
        d = float(np.linalg.norm(stops[i].xy_m - stops[i - 1].xy_m))
        stops[i].arc_leg = i in arc_legs
        stops[i].path_length_m = d * (1.05 if stops[i].arc_leg else 1.0)
        stops[i].turn_rad = _wrap(stops[i].yaw_rad - stops[i - 1].yaw_rad)
    return stops


def _corridors(bearings, r0=0.75, r1=13.0, half_width=1.0):
    out = []
    for b in bearings:
        u = np.array([np.cos(b), np.sin(b)])
        out.append((r0 * u, r1 * u, half_width))
    return out


def list_runs(scenario: str) -> list[str]:
    if scenario == "paper":
        return [f"s{i}-{a}" for i in (1, 2, 3) for a in ("straight", "arc")]
    if scenario == "traverse":
        return ["s1-straight", "s1-curved"]
    raise ValueError(f"scenario: unknown {scenario!r} (want one of {', '.join(SCENARIOS)})")


def _scene_params(scenario: str, seed: int, scene_index: int):
    r = _rng(seed, scenario, "scene", scene_index)
    bearing = r.uniform(0, 2 * np.pi)
    turn_sign = float(r.choice([-1.0, 1.0]))
    sun_off = float(r.choice([-1.0, 1.0])) * r.uniform(35, 100) * DEG
    scene_seed = int(r.integers(0, 2 ** 31 - 1))
    return bearing, turn_sign, bearing + sun_off, scene_seed


def plan_run(scenario: str, run: str, seed: int, rover: Optional[rover_mod.SimRover] = None) -> RunPlan:
    """The geometry of one run (no rendering). ``rover``: whose placement constants and corridor width to use
    (None: the default rover)."""
    rv = rover_mod.default_sim_rover() if rover is None else rover
    MAST_REF_X_M, NAVCAM_REF_X_M, HAZCAM_REF_X_M = rv.mast_ref_x_m, rv.navcam_ref_x_m, rv.hazcam_ref_x_m
    extra = rv.corridor_extra_m
    runs = list_runs(scenario)
    if run not in runs:
        raise ValueError(f"run: unknown {run!r} for scenario {scenario} (want one of {', '.join(runs)})")
    scene_index = int(run.split("-")[0][1:])
    approach = run.split("-", 1)[1]
    beta, sgn, sun_az, scene_seed = _scene_params(scenario, seed, scene_index)
    rr = _rng(seed, scenario, run)
    run_index = runs.index(run)
    if scenario == "paper":
        alpha = 0.0 if approach == "straight" else sgn * 30.0 * DEG
        b_far = beta + alpha
        # the near stop of the two runs of a scene: the same place up to ~1 cm and ~1 deg
        near_d, near_b, near_yaw = 1.0 + rr.normal(0, 0.01), beta + rr.normal(0, 0.5 * DEG), rr.normal(0, 0.75 * DEG)
        stops = []
        xy, yaw = _place(MAST_REF_X_M, 10.0, b_far)
        stops.append(StopPlan("pan10", xy, yaw, ("pancam",), "pancam", 10.0, b_far))
        xy, yaw = _place(MAST_REF_X_M, 4.5, b_far)
        stops.append(StopPlan("mid", xy, yaw, ("pancam", "navcam"), "navcam", 4.5, b_far))
        xy, yaw = _place(NAVCAM_REF_X_M, 3.0, b_far)
        stops.append(StopPlan("far", xy, yaw, ("navcam",), "navcam", 3.0, b_far))
        xy, yaw = _place(HAZCAM_REF_X_M, near_d, near_b, (0.0, 0.0, near_yaw))
        stops.append(StopPlan("near", xy, yaw, ("navcam", "hazcam"), "hazcam", near_d, near_b))
        _finish_legs(stops, arc_legs={3} if alpha else set())
        keep = _corridors([beta, beta + sgn * 30.0 * DEG], half_width=1.0 + extra)
        # the arc between the far arc stop and the near stop
        arc = [_place(NAVCAM_REF_X_M, r, beta + sgn * f * 30.0 * DEG)[0] for r, f in ((3.2, 1.0), (2.4, 0.6), (1.8, 0.3), (1.6, 0.0))]
        keep += [(arc[i], arc[i + 1], 1.0 + extra) for i in range(len(arc) - 1)]
        kinds = tuple(KINDS[(3 * run_index + j) % len(KINDS)] for j in range(3))
        key = [("near", "hazcam"), ("near", "navcam"), ("far", "navcam")]
        return RunPlan(scenario, run, seed, scene_index, scene_seed, beta, sun_az, keep, stops, kinds, key, sol=run_index + 1,
                       rover=rover)
    # traverse
    curve = 0.0 if approach == "straight" else sgn * 35.0 * DEG
    haz_off = HAZCAM_REF_X_M - MAST_REF_X_M
    d_end = 1.0 + haz_off  # mast distance when the hazcams are 1 m from the rock
    ds = [10.0]
    while ds[-1] > d_end + 1e-9:
        d = ds[-1] * (1.0 - rr.uniform(0.10, 0.20))
        for must in (4.6, 2.0 + haz_off):  # a stop at the pancam->navcam handoff and at 2 m hazcam distance
            if ds[-1] > must + 1e-9 and d < must:
                d = must
        ds.append(max(d, d_end))
    stops = []
    for k, d in enumerate(ds):
        b = beta + curve * (10.0 - d) / (10.0 - d_end)
        cams = []
        if d > 4.3:
            cams.append("pancam")
        if d < 5.3:
            cams.append("navcam")
        if d - haz_off <= 2.0 + 1e-9:
            cams.append("hazcam")
        xy, yaw = _place(MAST_REF_X_M, d, b)
        ref = "hazcam" if "hazcam" in cams else ("navcam" if "navcam" in cams else "pancam")
        ref_d = d - haz_off if ref == "hazcam" else d
        stops.append(StopPlan(f"d{k:02d}", xy, yaw, tuple(cams), ref, ref_d, b))
    _finish_legs(stops, arc_legs=set(range(1, len(stops))) if curve else set())
    bs = np.linspace(0, 1, 8)
    keep = []
    pts = [_place(MAST_REF_X_M, d_end + (10.5 - d_end) * f, beta + curve * (1 - f))[0] for f in bs]
    keep += [(pts[i], pts[i + 1], 1.1 + extra) for i in range(len(pts) - 1)]
    kinds = tuple(KINDS[(3 * run_index + j) % len(KINDS)] for j in range(3))
    first_nav = next(s.label for s in stops if "navcam" in s.cameras)
    key = [(stops[-1].label, "hazcam"), (stops[-1].label, "navcam"), (first_nav, "navcam"), (stops[0].label, "pancam")]
    return RunPlan(scenario, run, seed, scene_index, scene_seed, beta, sun_az, keep, stops, kinds, key, sol=run_index + 1,
                   rover=rover)


def default_errors(scenario: str) -> ErrorSettings:
    """The errors a scenario injects by default: :class:`ErrorSettings` defaults, and for ``paper`` a washed-out
    far navcam pair in run ``s2-arc`` (the paper's run 4)."""
    if scenario == "paper":
        return ErrorSettings(washed_out=(("s2-arc", "far", "navcam"),))
    return ErrorSettings()
