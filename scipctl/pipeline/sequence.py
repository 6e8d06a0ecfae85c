"""Uplink command sequence for the single-cycle approach, with flight-rule checks (docs/sequence.md).

The command stems are NOTIONAL (no flight command dictionary is implied):
they name what the rover is asked to do, with the arguments a real
dictionary would need. Two forms:

* SeqN-style text (NASA AMMOS Aerie's sequence notation: ``@ID``,
  ``@METADATA "key" <json>``, one command per line ``R<hh:mm:ss> STEM args``
  with a relative time tag = the estimated duration of the previous command,
  ``#`` comments);
* SeqJSON (Aerie/PlanDev's import format: ``id``, ``metadata``, ``steps`` with typed ``args`` and ``time``);
* JSON (same content, named arguments).

Both are deterministic: the same inputs give byte-identical output (fixed
float formatting, sorted keys, a seeded Monte Carlo, no wall-clock time; the
provenance carries the tool version, the command line and input hashes).

Flight rules (:func:`check_rules`) are checked before anything is written;
a violation means no sequence.
"""

from __future__ import annotations

import hashlib
import json
import math
from dataclasses import dataclass
from typing import Optional

import numpy as np

from ..errors import one_line
from .designate import Designation
from .predict import Prediction

FORMAT = "scipctl-sequence/1"
NOTIONAL = "NOTIONAL command stems (scipctl planning vocabulary, not a flight command dictionary)"

# paper's Table 1 (near navcams): refined kinematic has the best success rate of the refined methods,
# pure geometric the smallest error of the methods that always answer (the `best-single` choice without results)
DEFAULT_HANDOFF = ("refined-kinematic", "pure-geometric")
FALLBACK_RULE = {"min_ncc": 0.7, "max_disagreement_px": 8.0}
# how the navcam->hazcam handoff is chosen: `scip` (the default: the recommended handoff, issue #14, the one the
# prediction's chain runs) or `best-single` (one paper method by the saved near-navcam results, as before scip)
HANDOFF_CHOICES = ("scip", "best-single")


@dataclass(frozen=True)
class FlightRules:
    max_drive_m: float = 15.0
    min_standoff_m: float = 0.6  # horizontal rover origin -> target at the final pose
    target_keep_out_m: float = 0.25  # footprint -> target, whole path
    rock_keep_out_m: float = 0.15  # footprint -> rock cells, whole path
    max_tilt_rad: float = math.radians(15.0)  # terrain tilt at the final pose
    min_confidence: float = 0.5  # calibrated predicted P(success): uplink when success is more likely than not
    min_p_simulated: float = 0.7  # the prediction's simulated P (geometry Monte Carlo x tracking on expected views)
    hazcam_fov_margin_px: float = 20.0
    min_terrain_known_fraction: float = 0.5  # advisory: share of the path under today's stereo

    def check(self) -> "FlightRules":
        """Raise ValueError naming the first bad field; return self (the rules file: ``pipeline/rules.py``)."""
        from .predict.params import _check_number

        c = "FlightRules"
        _check_number(c, "max_drive_m", self.max_drive_m, 0.0, lo_open=True)
        _check_number(c, "min_standoff_m", self.min_standoff_m, 0.0)
        _check_number(c, "target_keep_out_m", self.target_keep_out_m, 0.0)
        _check_number(c, "rock_keep_out_m", self.rock_keep_out_m, 0.0)
        _check_number(c, "max_tilt_rad", self.max_tilt_rad, 0.0, math.pi / 2)
        _check_number(c, "min_confidence", self.min_confidence, 0.0, 1.0)
        _check_number(c, "min_p_simulated", self.min_p_simulated, 0.0, 1.0)
        _check_number(c, "hazcam_fov_margin_px", self.hazcam_fov_margin_px, 0.0)
        _check_number(c, "min_terrain_known_fraction", self.min_terrain_known_fraction, 0.0, 1.0)
        return self


@dataclass(frozen=True)
class Timing:
    """Notional durations (s) for the relative time tags."""

    drive_speed_m_s: float = 0.05
    drive_overhead_s: float = 30.0
    turn_rate_rad_s: float = 0.05
    turn_overhead_s: float = 10.0
    mast_s: float = 10.0
    image_s: float = 20.0
    track_s: float = 15.0
    stereo_s: float = 10.0
    handoff_scaled_s: float = 20.0
    handoff_hazcam_s: float = 60.0
    arm_s: float = 600.0
    misc_s: float = 1.0


@dataclass
class RuleCheck:
    rule: str
    ok: bool
    value: Optional[float]
    limit: Optional[float]
    unit: str
    message: str
    blocking: bool = True

    def to_dict(self) -> dict:
        return dict(self.__dict__)


@dataclass
class Command:
    stem: str
    args: list  # [(name, value)] in order; value: float | int | str | ("enum", NAME)
    duration_s: float
    comment: str = ""
    stop: Optional[int] = None


# ============================================================================ rules
def check_rules(pred: Prediction, rover_config, rules: Optional[FlightRules] = None) -> list:
    """Flight-rule checks on the planned approach and its prediction. Returns :class:`RuleCheck` (blocking ones decide)."""
    r = rules or FlightRules()
    plan = pred.plan
    fin = plan.final
    X = plan.target_site_m
    out = []
    out.append(RuleCheck("max-drive-distance", plan.path_length_m <= r.max_drive_m, plan.path_length_m, r.max_drive_m,
                         "m", f"path length {plan.path_length_m:.2f} m (limit {r.max_drive_m:.2f} m)"))
    d_fin = float(np.linalg.norm(X[:2] - fin.T_site_rover.t[:2]))
    out.append(RuleCheck("min-standoff", d_fin >= r.min_standoff_m, d_fin, r.min_standoff_m, "m",
                         f"final rover-origin-to-target distance {d_fin:.2f} m (minimum {r.min_standoff_m:.2f} m)"))
    mt = plan.clearance.get("min_target_m", float("inf"))
    out.append(RuleCheck("target-keep-out", mt >= r.target_keep_out_m, _fin(mt), r.target_keep_out_m, "m",
                         f"closest rover footprint approach to the target {mt:.2f} m (keep-out {r.target_keep_out_m:.2f} m)"
                         + _searched(plan, "target-keep-out", mt >= r.target_keep_out_m)))
    mr = plan.clearance.get("min_rock_m", float("inf"))
    where = plan.clearance.get("worst_rock_xy")
    out.append(RuleCheck("rock-keep-out", mr >= r.rock_keep_out_m, _fin(mr), r.rock_keep_out_m, "m",
                         (f"closest rover footprint approach to a rock {mr:.2f} m" + (
                             f" at site ({where[0]:.2f}, {where[1]:.2f})" if where else "") if np.isfinite(mr)
                          else "no rocks in the stereo terrain") + f" (keep-out {r.rock_keep_out_m:.2f} m)"
                         + _searched(plan, "rock-keep-out", mr >= r.rock_keep_out_m)))
    # hazcams and arm at the final pose
    from ..core.image_margin import pair_margin_px

    worst_margin = float(pair_margin_px(rover_config, "hazcam", fin.T_site_rover.inverse().apply(X)[None])[0])
    if not np.isfinite(worst_margin):
        where = "target behind a hazcam at the final pose"
    elif worst_margin < 0:
        where = f"target outside a hazcam image at the final pose ({-worst_margin:.0f} px beyond its edge)"
    else:
        where = f"target inside both hazcam images at the final pose ({worst_margin:.0f} px from the edge)"
    out.append(RuleCheck("hazcam-fov-final", worst_margin >= r.hazcam_fov_margin_px, _fin(worst_margin),
                         r.hazcam_fov_margin_px, "px",
                         where + f" (margin {r.hazcam_fov_margin_px:g} px)"
                         + _searched(plan, "hazcam-fov-final", worst_margin >= r.hazcam_fov_margin_px)))
    xy = fin.T_site_rover.inverse().apply(X)[:2]
    in_arm = bool(plan.params.arm.contains(xy[None])[0])
    a = plan.params.arm
    out.append(RuleCheck("arm-workspace", in_arm, float(np.hypot(*xy)), None, "m",
                         f"target at ({xy[0]:.3f}, {xy[1]:.3f}) m in the final rover frame, {np.hypot(*xy):.3f} m "
                         f"away; workspace {a.r_min_m:.2f}-{a.r_max_m:.2f} m ahead, |y| <= {a.half_width_m:.2f} m"))
    am = plan.arm_margin
    if am is not None:
        room = min(float(np.hypot(*xy)) - a.r_min_m, a.r_max_m - float(np.hypot(*xy)))
        kept = room >= am.margin_m
        # in mm with a decimal: a 0.4 mm sigma printed in metres read "needs 0.001 m (2 x 0.000 m)"
        msg = (f"designated point {1000 * room:.1f} mm inside the arm workspace's radial limits; the final drive's "
               f"error needs {1000 * am.margin_m:.1f} mm ({am.n_sigma:g} x {1000 * am.sigma_m:.1f} mm)")
        if not kept and plan.search is not None and plan.search.found and plan.search.kept is not None:
            msg = plan.search.describe_margin()
        out.append(RuleCheck("arm-margin", kept, room, am.margin_m, "m", msg, blocking=False))
    tilt_ok = fin.terrain_known and fin.tilt_rad <= r.max_tilt_rad
    out.append(RuleCheck("final-tilt", tilt_ok, fin.tilt_rad, r.max_tilt_rad, "rad",
                         (f"terrain tilt at the final pose {math.degrees(fin.tilt_rad):.1f} deg "
                          f"(limit {math.degrees(r.max_tilt_rad):.1f} deg)") if fin.terrain_known
                         else "no stereo terrain under the final pose: tilt unknown"))
    conf_ok = pred.confidence >= r.min_confidence
    out.append(RuleCheck("prediction-confidence", conf_ok, pred.confidence, r.min_confidence,
                         "", f"predicted P(success) {pred.confidence:.2f} (minimum {r.min_confidence:.2f}; "
                         + ("calibrated against the chain" if pred.calibration else "not calibrated") + ")"
                         + ("" if conf_ok else _weakest(pred))))
    sim_ok = pred.p_simulated >= r.min_p_simulated
    out.append(RuleCheck("simulated-risk", sim_ok, pred.p_simulated, r.min_p_simulated,
                         "", f"simulated P(geometry and tracking on expected views) {pred.p_simulated:.2f} "
                         f"(minimum {r.min_p_simulated:.2f})" + ("" if sim_ok else _weakest(pred))))
    kf = plan.clearance.get("terrain_known_fraction", 0.0)
    out.append(RuleCheck("terrain-known-along-path", kf >= r.min_terrain_known_fraction, kf,
                         r.min_terrain_known_fraction, "",
                         f"{100 * kf:.0f}% of the path is covered by today's stereo (obstacles elsewhere are unchecked)",
                         blocking=False))
    return out


def _weakest(pred) -> str:
    """For a broken prediction-confidence or simulated-risk: the stop that costs most (the lowest-probability risk) and what would
    raise it."""
    risks = [k for k in pred.risks if k.probability is not None]
    if not risks:
        return ""
    k = min(risks, key=lambda x: (x.probability, x.stop))
    why = "; ".join(k.reasons[:2]) if k.reasons else k.what
    if k.what == "arm":
        fix = "a standoff nearer the workspace centre (--standoff-m) or a closer final image"
    elif any("field of view" in x or "search region" in x for x in k.reasons):
        fix = "images from a closer stop (a shorter drive before re-pointing) or a larger search region (rules tracking.search_radius_px)"
    elif any("occlu" in x for x in k.reasons):
        fix = "another approach bearing (approach.detour_bearings_deg) or a new designation on the visible side"
    else:
        fix = "new images of the target (better light or closer) or a new designation"
    return f"; weakest: stop {k.stop} {k.camera} {k.what} P {k.probability:.2f} ({why}): {fix} would raise it"


def _searched(plan, rule: str, ok: bool) -> str:
    """For a broken planner constraint: what the planner's (bearing, standoff) search tried and what would satisfy
    the rule (:meth:`~scipctl.pipeline.predict.approach_search.ApproachSearch.describe`); "" otherwise."""
    if ok or plan.search is None:
        return ""
    return "; " + plan.search.describe(rule)


def broken(checks: list) -> list:
    return [c for c in checks if c.blocking and not c.ok]


def _fin(x):
    return float(x) if np.isfinite(x) else None


# ============================================================================ handoff choice
def choose_handoff(table1_rows: Optional[list], choice: str = "scip", success_px: float = 4.0,
                   min_p_success: Optional[float] = None) -> dict:
    """The navcam->hazcam handoff the sequence commands (see :data:`HANDOFF_CHOICES`).

    ``scip``: ``scip``'s answer from the near and far navcams with its calibrated ``p_success`` for ``success_px``
    and GO at ``min_p_success`` (the trust model's threshold; None: unknown, never GO); a NO-GO handoff halts the
    sequence before the arm. The saved ``scip`` results, when there are any, are quoted in ``basis``.

    ``best-single``: (primary, fallback) paper methods from near-navcam results (``handoff.json`` table1 rows).
    Primary: the highest success rate (ties: smaller mean error); fallback:
    among the others that always answered, the smallest mean error. Without
    results: the paper's choice (:data:`DEFAULT_HANDOFF`).
    """
    if choice not in HANDOFF_CHOICES:
        raise ValueError(f"handoff choice: {choice!r} is not one of {', '.join(HANDOFF_CHOICES)}")
    if choice == "scip":
        rows = [r for r in (table1_rows or []) if isinstance(r, dict) and r.get("method") == "scip" and r.get("cases")]
        seen = ""
        if rows:
            r = rows[0]
            seen = (f"; saved results: {100 * float(r.get('success_rate') or 0.0):.0f}% of {r['cases']} within "
                    f"{success_px:g} px")
        return {"primary": "scip", "fallback": None, "navcam": "both", "success_px": float(success_px),
                "min_p_success": None if min_p_success is None else float(min_p_success),
                "basis": "the recommended handoff: one answer from the near and far navcams with a calibrated "
                         "p_success; NO-GO halts before the arm" + seen}
    rows = [r for r in (table1_rows or []) if isinstance(r, dict) and r.get("navcam") == "near" and r.get("cases")]
    if not rows:
        why = ("the saved handoff results hold no near-navcam method (run simulate-handoff --methods all)"
               if table1_rows else "no handoff results for this downlink")
        return {"primary": DEFAULT_HANDOFF[0], "fallback": DEFAULT_HANDOFF[1], "navcam": "near",
                "basis": f"the paper's Table 1 ({why})", **FALLBACK_RULE}

    def mean(r):
        s = r.get("all") or {}
        return float(s["mean_px"]) if s.get("mean_px") is not None else float("inf")

    best = sorted(rows, key=lambda r: (-float(r.get("success_rate", 0.0)), mean(r), r["method"]))[0]
    rest = [r for r in rows if r["method"] != best["method"] and r.get("answered") == r.get("cases")]
    fb = sorted(rest, key=lambda r: (mean(r), r["method"]))[0] if rest else None
    return {"primary": best["method"], "fallback": fb["method"] if fb else DEFAULT_HANDOFF[1], "navcam": "near",
            "basis": f"handoff results: {best['method']} near {100 * float(best.get('success_rate', 0)):.0f}% success"
                     + (f", {fb['method']} near mean {mean(fb):.1f} px" if fb else ""), **FALLBACK_RULE}


# ============================================================================ commands
def _exposures(dl, position) -> dict:
    out = {}
    for cam in ("pancam", "navcam", "hazcam"):
        vals = sorted(im.exposure_ms for im in dl.images if im.camera == cam and im.exposure_ms is not None
                      and im.position == position)
        if not vals:
            vals = sorted(im.exposure_ms for im in dl.images if im.camera == cam and im.exposure_ms is not None)
        out[cam] = float(vals[len(vals) // 2]) if vals else None
    return out


def build_commands(pred: Prediction, record: Designation, handoff: dict, exposures: dict,
                   timing: Optional[Timing] = None, chain_params=None) -> list:
    """The command list for the planned approach to the designated target (see the module docstring; stems are
    notional). ``chain_params``: the on-board chain's windows and stereo bands (default
    :class:`~scipctl.pipeline.chain.ChainParams`; the prediction's ``PredictParams.chain``)."""
    from .chain import ChainParams

    tm = timing or Timing()
    cp = chain_params or ChainParams()
    plan = pred.plan
    X = plan.target_site_m
    cmds = [Command("SCIP_BEGIN", [("target", record.id)], tm.misc_s, "single-cycle instrument placement"),
            Command("SCIP_TARGET_SET", [("x_m", X[0]), ("y_m", X[1]), ("z_m", X[2]), ("frame", ("enum", "SITE"))], tm.misc_s,
                    "designated 3-D target, today's site frame"),
            Command("TRK_INIT_TEMPLATE", [("product", record.product_id), ("u_px", record.pixel_uv[0]),
                                          ("v_px", record.pixel_uv[1]),
                                          ("template_half_px", cp.template_half(record.camera))], tm.misc_s,
                    "first tracking window from today's image")]
    prev_heading = plan.stops[0].heading_rad
    for st in plan.stops[1:]:
        # drive legs (waypoints of the planned path), turning at each vertex
        pts = st.path_from_previous
        for a, b in zip(pts[:-1], pts[1:]):
            L = math.hypot(b[0] - a[0], b[1] - a[1])
            if L < 1e-6:
                continue
            hd = math.atan2(b[1] - a[1], b[0] - a[0])
            turn = _wrap(hd - prev_heading)
            if abs(turn) > math.radians(1.0):
                cmds.append(Command("DRV_TURN_TO_HEADING", [("heading_rad", hd)], tm.turn_overhead_s + abs(turn) / tm.turn_rate_rad_s,
                                    f"turn {math.degrees(turn):+.0f} deg", st.index))
            prev_heading = hd
            if st.kind in ("hazcam", "final"):
                continue  # closed-loop approach below
            cmds.append(Command("DRV_GOTO_WAYPOINT", [("x_m", b[0]), ("y_m", b[1]), ("frame", ("enum", "SITE")),
                                                      ("max_dist_m", L * 1.2 + 0.1), ("hazard_avoid", ("enum", "ON"))],
                                tm.drive_overhead_s + L / tm.drive_speed_m_s, f"leg {L:.2f} m", st.index))
        if st.kind in ("hazcam", "final"):
            cmds.append(Command("DRV_APPROACH_TARGET", [("distance_m", st.distance_m), ("max_dist_m", st.leg_m * 1.5 + 0.1)],
                                tm.drive_overhead_s + st.leg_m / tm.drive_speed_m_s,
                                "closed loop on the tracked target" + (" (final approach to the standoff)" if st.kind == "final" else ""),
                                st.index))
        if st.kind == "navcam-hazcam-handoff":
            cmds.append(Command("DRV_TURN_TO_TARGET", [("camera", ("enum", "HAZCAM"))],
                                tm.turn_overhead_s + abs(st.turn_rad) / tm.turn_rate_rad_s,
                                "face the tracked target so the hazcams see it", st.index))
            prev_heading = st.heading_rad
        for sh in st.cameras:
            cam = sh.camera
            if sh.pan_rad is not None:
                cmds.append(Command("MAST_POINT_AT_TARGET", [("camera", ("enum", cam.upper())),
                                                             ("expected_pan_rad", sh.pan_rad), ("expected_tilt_rad", sh.tilt_rad)],
                                    tm.mast_s, "point at the on-board target estimate", st.index))
            exp = exposures.get(cam)
            cmds.append(Command("IMG_STEREO", [("camera", ("enum", cam.upper())),
                                               ("exposure_ms", exp if exp is not None else ("enum", "AUTO"))],
                                tm.image_s, f"expected target pixel ({sh.uv[0]:.0f}, {sh.uv[1]:.0f}), range {sh.range_m:.2f} m"
                                if sh.uv is not None else "target not expected in view", st.index))
            if st.kind == "pancam-navcam-handoff" and cam == "navcam":
                cmds.append(Command("TRK_HANDOFF_SCALED", [("from", ("enum", "PANCAM")), ("to", ("enum", "NAVCAM")),
                                                           ("template_half_px", sh.template_half_px),
                                                           ("search_radius_px", sh.search_radius_px), ("min_ncc", 0.3)],
                                    tm.handoff_scaled_s, "pancam window shrunk by the IFOV ratio, NCC-tracked", st.index))
            elif st.kind == "navcam-hazcam-handoff" and cam == "hazcam" and handoff["primary"] == "scip":
                p_go = handoff["min_p_success"]
                cmds.append(Command("TRK_HANDOFF_SCIP", [("navcam", ("enum", "BOTH")), ("success_px", handoff["success_px"]),
                                                         ("min_p_success", float("nan") if p_go is None else p_go)],
                                    tm.handoff_hazcam_s, handoff["basis"], st.index))
            elif st.kind == "navcam-hazcam-handoff" and cam == "hazcam":
                cmds.append(Command("TRK_HANDOFF_NAVCAM_HAZCAM", [("method", ("enum", _enum(handoff["primary"]))),
                                                                  ("fallback", ("enum", _enum(handoff["fallback"]))),
                                                                  ("navcam", ("enum", "NEAR")),
                                                                  ("fallback_min_ncc", handoff["min_ncc"]),
                                                                  ("fallback_max_disagreement_px", handoff["max_disagreement_px"])],
                                    tm.handoff_hazcam_s, handoff["basis"], st.index))
            else:
                cmds.append(Command("TRK_TRACK", [("camera", ("enum", cam.upper())), ("template_half_px", sh.template_half_px),
                                                  ("search_radius_px", sh.search_radius_px), ("min_ncc", 0.3)],
                                    tm.track_s, "window scaled by the range ratio", st.index))
            cmds.append(Command("TRK_STEREO_UPDATE", [("camera", ("enum", cam.upper())), ("band_px", cp.band(cam))],
                                tm.stereo_s, "re-range the tracked target", st.index))
    fin = plan.final
    cmds.append(Command("ARM_PLACE_AT_TARGET", [("instrument", ("enum", "CONTACT")), ("approach", ("enum", "SURFACE_NORMAL")),
                                                ("max_offset_m", 0.02)],
                        tm.arm_s, f"target expected {fin.distance_m:.2f} m ahead", fin.index))
    cmds.append(Command("SCIP_END", [("target", record.id)], 0.0, ""))
    return cmds


def _enum(s: str) -> str:
    return s.upper().replace("-", "_")


def _wrap(a: float) -> float:
    return float((a + math.pi) % (2 * math.pi) - math.pi)


# ============================================================================ document and formats
def _round(o, nd: int = 6):
    """Round floats recursively (stable text across tiny floating-point differences)."""
    if isinstance(o, float):
        if not math.isfinite(o):
            return None
        v = round(o, nd)
        return 0.0 if v == 0 else v
    if isinstance(o, (np.floating,)):
        return _round(float(o), nd)
    if isinstance(o, (np.integer,)):
        return int(o)
    if isinstance(o, np.ndarray):
        return _round(o.tolist(), nd)
    if isinstance(o, dict):
        return {str(k): _round(v, nd) for k, v in o.items()}
    if isinstance(o, (list, tuple)):
        return [_round(v, nd) for v in o]
    return o


def canonical_hash(obj) -> str:
    return hashlib.sha256(json.dumps(_round(obj), sort_keys=True, separators=(",", ":")).encode()).hexdigest()


def time_tag(seconds: float) -> str:
    """``Rhh:mm:ss`` (whole seconds, rounded up); ``RDDDThh:mm:ss`` from 24 h on: Aerie's SeqN editor flags a relative
    tag whose hours exceed 23 as an unbalanced time (an error), and writes ``DDDThh:mm:ss`` itself."""
    s = int(math.ceil(max(0.0, seconds) - 1e-9))
    hms = f"{(s % 86400) // 3600:02d}:{(s % 3600) // 60:02d}:{s % 60:02d}"
    return f"R{s // 86400:03d}T{hms}" if s >= 86400 else f"R{hms}"


def sequence_document(pred: Prediction, record: Designation, checks: list, commands: list, handoff: dict,
                      provenance: dict, mission: str = "", sol: Optional[int] = None,
                      rules_used: Optional[dict] = None) -> dict:
    """The deterministic document the formats are written from (``rules_used``: the rule set's file, SHA-256
    and effective values, :meth:`scipctl.pipeline.rules.RuleSet.to_dict`)."""
    plan = pred.plan
    seq_id = f"scip_{_ident(record.id)}" + (f"_sol{sol}" if sol is not None else "")
    cmd_docs = []
    prev = 0.0
    t = 0.0
    for i, c in enumerate(commands):
        t += prev
        cmd_docs.append({"index": i, "time_tag": time_tag(prev if i else 0.0), "start_s": t, "stem": c.stem,
                         "args": [_arg_doc(n, v) for n, v in c.args],
                         "duration_s": c.duration_s, "stop": c.stop, "comment": c.comment})
        prev = c.duration_s
    doc = {
        "format": FORMAT,
        "notional": NOTIONAL,
        "sequence_id": seq_id,
        "mission": mission,
        "sol": sol,
        "provenance": provenance,
        "target": {"id": record.id, "product_id": record.product_id, "pixel_uv": list(record.pixel_uv),
                   "xyz_site_m": list(record.xyz_site_m), "range_m": record.range_m,
                   "designated_from": record.designated_from or "targets.json"},
        "plan": {"path_length_m": plan.path_length_m, "bearing_rad": plan.bearing_rad, "detour_rad": plan.detour_rad,
                 "stops": [{"index": s.index, "kind": s.kind, "distance_m": s.distance_m,
                            "xy_site_m": s.T_site_rover.t[:2].tolist(), "heading_rad": s.heading_rad,
                            "tilt_rad": s.tilt_rad, "cameras": [c.camera for c in s.cameras]} for s in plan.stops],
                 "standoff_m": plan.params.final_distance_m,
                 "clearance": {k: v for k, v in plan.clearance.items()},
                 "search": None if plan.search is None else {"tried": len(plan.search.tried),
                                                             "found": plan.search.found,
                                                             "found_with_margin": plan.search.found_with_margin,
                                                             "margin_binding": plan.search.margin_binding()},
                 "arm_margin": None if plan.arm_margin is None else plan.arm_margin.to_dict()},
        "handoff": handoff,
        "prediction": {"confidence": pred.confidence, "p_simulated": pred.p_simulated,
                       "calibration": pred.calibration, "sigma_source": pred.sigma_source,
                       "p_arm_workspace": None if pred.mc is None else pred.mc.p_arm_workspace,
                       "risks": [r.to_dict() for r in pred.risks]},
        "rules": [c.to_dict() for c in checks],
        "rules_used": rules_used,
        "total_duration_s": t + prev,
        "commands": cmd_docs,
    }
    return _round(doc)


def _arg_doc(name: str, v) -> dict:
    if isinstance(v, tuple):
        return {"name": name, "type": "enum", "value": str(v[1])}
    if isinstance(v, (bool, np.bool_)):
        return {"name": name, "type": "bool", "value": bool(v)}
    if isinstance(v, (int, np.integer)):
        return {"name": name, "type": "int", "value": int(v)}
    if isinstance(v, (float, np.floating)):
        if not math.isfinite(v):  # no number to send: a symbol, never a null argument
            return {"name": name, "type": "enum", "value": "UNKNOWN"}
        return {"name": name, "type": "float", "value": float(v)}
    return {"name": name, "type": "string", "value": str(v)}


def _ident(s: str) -> str:
    out = "".join(ch if (ch.isalnum() or ch == "_") else "_" for ch in str(s))
    return out if out and out[0].isalpha() else "t_" + out


def format_json(doc: dict) -> str:
    return json.dumps(doc, indent=2, sort_keys=True, ensure_ascii=True) + "\n"


def _arg_text(a: dict) -> str:
    t, v = a["type"], a["value"]
    if t == "enum":
        return str(v)
    if t == "string":
        return json.dumps(v)
    if t == "bool":
        return "true" if v else "false"
    if t == "int":
        return str(int(v))
    if v is None:
        return "null"
    return _num(float(v))


def _num(x: float) -> str:
    s = f"{x:.6f}".rstrip("0")
    if s.endswith("."):
        s += "0"
    return "0.0" if s in ("-0.0",) else s


def format_seqn(doc: dict) -> str:
    """SeqN-style text: header comments, ``@ID``, ``@METADATA`` lines (compact JSON), one command per line."""
    # comment lines carry names read from the input (target ids): one_line keeps each on its line
    lines = [
        f"# {one_line(doc['sequence_id'])}: single-cycle instrument placement uplink for target "
        f"{one_line(doc['target']['id'])}",
        f"# {one_line(doc['notional'])}",
        "# time tags: R<hh:mm:ss> relative to the previous command (notional durations); frames: SITE = today's site frame",
        f"# {FORMAT}; generated by scipctl (see the provenance metadata)",
        f"@ID {json.dumps(doc['sequence_id'])}",
    ]
    for k, v in _metadata(doc):
        lines.append(f"@METADATA {json.dumps(k)} {json.dumps(v, sort_keys=True, separators=(',', ':'))}")
    stop = None
    for c in doc["commands"]:
        if c["stop"] is not None and c["stop"] != stop:
            stop = c["stop"]
            s = next(s for s in doc["plan"]["stops"] if s["index"] == stop)
            lines.append(f"# stop {stop}: {s['kind']}, {s['distance_m']:.2f} m from the target")
        args = " ".join(_arg_text(a) for a in c["args"])
        cm = f" # {one_line(c['comment'])}" if c["comment"] else ""
        lines.append(f"{c['time_tag']} {c['stem']}" + (f" {args}" if args else "") + cm)
    return "\n".join(lines) + "\n"


def _metadata(doc: dict) -> list:
    """The sequence-level metadata of the SeqN (``@METADATA``) and SeqJSON (``metadata``) forms, in order."""
    return [("format", doc["format"]), ("notional", True), ("provenance", doc["provenance"]), ("target", doc["target"]),
            ("handoff", doc["handoff"]),
            ("prediction", {"confidence": doc["prediction"]["confidence"], "risks": len(doc["prediction"]["risks"])}),
            ("rules", [{"rule": r["rule"], "ok": r["ok"]} for r in doc["rules"]]),
            ("rules_used", doc.get("rules_used")),
            ("total_duration_s", doc["total_duration_s"])]


# our argument types -> SeqJSON's (an enumerated value is a SeqN Enum, which Aerie converts to a symbol argument)
SEQJSON_ARG_TYPE = {"enum": "symbol", "string": "string", "bool": "boolean", "int": "number", "float": "number"}


def format_seqjson(doc: dict) -> str:
    """SeqJSON as NASA AMMOS Aerie/PlanDev imports it (the ``@nasa-jpl/seq-json-schema`` schema): ``id``,
    ``metadata`` (the SeqN's ``@METADATA`` entries) and one ``command`` step per command with its typed
    ``args``, a ``COMMAND_RELATIVE`` time tag (the SeqN tag without its ``R``), the comment as ``description``
    (one line, as in the SeqN: Aerie writes a step's description back as the command's ``#`` comment) and the
    stop in the step's ``metadata``."""
    steps = []
    for c in doc["commands"]:
        step = {"type": "command", "stem": c["stem"], "time": {"type": "COMMAND_RELATIVE", "tag": c["time_tag"][1:]},
                "args": [{"name": a["name"], "type": SEQJSON_ARG_TYPE[a["type"]], "value": a["value"]}
                         for a in c["args"]]}
        if c["comment"]:
            step["description"] = one_line(c["comment"])
        if c["stop"] is not None:
            step["metadata"] = {"stop": c["stop"]}
        steps.append(step)
    out = {"id": doc["sequence_id"], "metadata": {k: v for k, v in _metadata(doc)}, "steps": steps}
    return json.dumps(out, indent=2, sort_keys=True, ensure_ascii=True) + "\n"


def format_text(doc: dict) -> str:
    """A plain, human-readable rendering (plan, rule checks, risks, commands)."""
    out = [f"{doc['sequence_id']}  ({doc['notional']})", "",
           f"target {doc['target']['id']}: site ({', '.join(f'{x:.3f}' for x in doc['target']['xyz_site_m'])}) m, "
           f"from {doc['target']['product_id']} pixel ({doc['target']['pixel_uv'][0]:.1f}, {doc['target']['pixel_uv'][1]:.1f})",
           f"path {doc['plan']['path_length_m']:.2f} m, approach bearing {math.degrees(doc['plan']['bearing_rad']):.1f} deg "
           f"(detour {math.degrees(doc['plan']['detour_rad']):+.0f} deg), {len(doc['plan']['stops']) - 1} stops, "
           f"~{doc['total_duration_s'] / 60:.0f} min",
           f"handoff navcam->hazcam: {doc['handoff']['primary']}"
           + (f" (fallback {doc['handoff']['fallback']})" if doc['handoff'].get('fallback') else "")
           + f"; {doc['handoff']['basis']}",
           f"predicted P(success) {doc['prediction']['confidence']:.2f}"]
    ru = doc.get("rules_used")
    if ru:
        out.append(f"rules: {ru['file']} (sha256 {ru['sha256'][:12]}...)"
                   + (f", options {', '.join(f'{k} {v:g}' for k, v in ru['overrides'].items())}" if ru["overrides"] else ""))
    out += ["", "stops:"]
    for s in doc["plan"]["stops"]:
        out.append(f"  {s['index']:2d} {s['kind']:<22s} {s['distance_m']:6.2f} m  xy ({s['xy_site_m'][0]:7.2f}, {s['xy_site_m'][1]:7.2f})"
                   f"  heading {math.degrees(s['heading_rad']):6.1f} deg  tilt {math.degrees(s['tilt_rad']):4.1f} deg  {'+'.join(s['cameras'])}")
    out += ["", "flight rules:"]
    for r in doc["rules"]:
        out.append(f"  [{'ok ' if r['ok'] else 'NO '}] {r['rule']:<26s} {r['message']}" + ("" if r["blocking"] else "  (advisory)"))
    out += ["", "risks:" if doc["prediction"]["risks"] else "risks: none"]
    for k in doc["prediction"]["risks"]:
        p = "" if k["probability"] is None else f" P={k['probability']:.2f}"
        out.append(f"  stop {k['stop']} {k['camera']} ({k['what']}){p}: " + "; ".join(k["reasons"]))
    out += ["", "commands:"]
    for c in doc["commands"]:
        args = ", ".join(f"{a['name']}={_arg_text(a)}" for a in c["args"])
        out.append(f"  {c['time_tag']}  {c['stem']}({args})" + (f"  -- {c['comment']}" if c["comment"] else ""))
    pv = doc["provenance"]
    out += ["", f"made by {pv.get('tool', 'scipctl')} {pv.get('version', '?')}: {one_line(pv.get('command', '?'))}"]
    out += [f"  input {k}: sha256 {v.get('sha256', '?')}" + (f" ({one_line(v['path'])})" if v.get("path") else "")
            for k, v in sorted(pv.get("inputs", {}).items())]
    return "\n".join(out) + "\n"


FORMATTERS = {"seqn": format_seqn, "seqjson": format_seqjson, "json": format_json, "text": format_text}
