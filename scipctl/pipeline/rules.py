"""The rule set a sequence is planned and checked with: flight-rule limits and approach parameters from a rules
file (docs/sequence.md, "Rules file"; the default ``scipctl/data/rules.yaml`` equals the dataclass defaults).

:func:`load_rules` reads the file (``scipctl.io.rules_file``), applies the operator's option overrides and
builds :class:`~scipctl.pipeline.sequence.FlightRules` and :class:`~scipctl.pipeline.predict.PredictParams`
(each ``check()``-ed). A value out of range is an :class:`InputError` naming the file (or the option) and the key.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Optional

from ..errors import InputError

# {section: {key: kind}} (kinds: scipctl.io.rules_file.KINDS); the default file gives every key
SPEC = {
    "flight_rules": {"max_drive_m": "number", "min_standoff_m": "number", "target_keep_out_m": "number",
                     "rock_keep_out_m": "number", "max_tilt_deg": "number", "min_p_success": "number",
                     "min_p_simulated": "number",
                     "hazcam_fov_margin_px": "number", "min_terrain_known_fraction": "number"},
    "approach": {"stop_fraction": "number", "min_leg_m": "number", "merge_m": "number", "pancam_handoff_m": "number",
                 "hazcam_handoff_m": "number", "hazcam_stops_m": "numbers", "standoff_m": "number?", "standoff_step_m": "number",
                 "arm_margin_sigmas": "number",
                 "detour_bearings_deg": "numbers", "path_step_m": "number", "turn_step_deg": "number",
                 "rock_height_m": "number", "rock_cell_m": "number", "ground_window_m": "number"},
    "arm_workspace": {"r_min_m": "number", "r_max_m": "number", "half_width_m": "number"},
    "rover_body": {"front_m": "number", "rear_m": "number", "half_width_m": "number"},
    "uncertainty": {"sigma_position_m": "number?", "sigma_yaw_deg": "number?", "default_sigma_position_m": "number",
                    "default_sigma_yaw_deg": "number", "drive_error_frac": "number", "yaw_error_deg_per_m": "number",
                    "disparity_sigma_px": "number", "n_samples": "int", "n_track_samples": "int", "seed": "int"},
    "tracking": {"template_half_px": "camera_ints", "search_radius_px": "camera_numbers",
                 "handoff_template_half_px": "int", "handoff_search_radius_px": "number"},
    "prediction": {"occlusion_tol_m": "number", "low_texture_std": "number", "min_coverage": "number",
                   "max_incidence_deg": "number", "max_foreshortening_change": "number",
                   "risk_probability": "number", "search_margin_px": "number"},
}

# the operator's options that override a key of the file: option -> (section, key)
OPTIONS = {
    "--min-p-success": ("flight_rules", "min_p_success"),
    "--min-p-simulated": ("flight_rules", "min_p_simulated"),
    "--rock-keep-out-m": ("flight_rules", "rock_keep_out_m"),
    "--target-keep-out-m": ("flight_rules", "target_keep_out_m"),
    "--max-drive-m": ("flight_rules", "max_drive_m"),
    "--standoff-m": ("approach", "standoff_m"),
    "--sigma-position-m": ("uncertainty", "sigma_position_m"),
    "--sigma-yaw-deg": ("uncertainty", "sigma_yaw_deg"),
}


@dataclass(frozen=True)
class RuleSet:
    """The effective rules: the flight rules, the prediction parameters and where they came from."""

    flight: object  # FlightRules
    predict: object  # PredictParams
    source: str  # the rules file as given, or a built-in's label, e.g. "default (scipctl/data/rules.yaml)"
    sha256: str  # of the rules file's bytes
    values: dict  # effective values, {section: {key: value}} in the file's keys and units
    overrides: dict  # {option: value} the operator gave on the command line
    chosen_by: str = ""  # why this file, when the operator did not name it (rules_for_downlink); "" otherwise

    def summary(self) -> dict:
        """Which rules file, as ``sequence --json`` and a campaign's prediction records report it (``rules_file``)."""
        out = {"file": self.source, "sha256": self.sha256, "overrides": dict(self.overrides)}
        if self.chosen_by:
            out["chosen_by"] = self.chosen_by
        return out

    def to_dict(self) -> dict:
        """What the sequence's metadata records (``rules_used``)."""
        out = {"file": self.source, "sha256": self.sha256, "overrides": dict(self.overrides),
               "values": {s: dict(kv) for s, kv in self.values.items()}}
        if self.chosen_by:
            out["chosen_by"] = self.chosen_by
        return out


# the downlink missions (as the readers spell them, any case) and rover configuration name prefixes of Mars 2020
M2020_MISSIONS = ("m2020", "mars2020", "mars 2020", "m20", "perseverance")
M2020_ROVER_PREFIX = "m2020"


def rules_for_downlink(dl) -> tuple:
    """``(built-in name, reason)``: the built-in rules file for a downlink whose rules the operator did not name:
    ``m2020`` when the downlink says its rover is Mars 2020 (its rover configuration's name starts with
    ``m2020``, as the simulator's does, or its mission is Mars 2020, as real M2020 products' labels say), else
    ``default``."""
    name = str(getattr(dl.rover_config, "name", "") or "")
    mission = str(dl.mission or "")
    if name.lower().startswith(M2020_ROVER_PREFIX):
        return "m2020", f"the downlink's rover configuration is {name!r}"
    if mission.strip().lower() in M2020_MISSIONS:
        return "m2020", f"the downlink's mission is {mission!r}"
    return "default", f"the downlink's rover ({name!r}, mission {mission!r}) is not Mars 2020"


def load_rules(path=None, overrides: Optional[dict] = None, chosen_by: str = "") -> RuleSet:
    """The rule set from the rules file ``path`` (None: the package default; a name of
    :data:`~scipctl.io.rules_file.BUILTIN_RULES`, e.g. ``"m2020"``: that built-in file, whose missing keys keep
    the default's values as a user's file's do) with ``overrides`` (``{option: value}``, options in
    :data:`OPTIONS`; a None value is not given). ``chosen_by``: recorded in ``rules_used`` (why this file).
    :class:`InputError` for a bad file or value (naming the file or option, and the key)."""
    from ..io.rules_file import BUILTIN_RULES, DEFAULT_RULES_PATH, builtin_label, read_rules_file

    default = read_rules_file(DEFAULT_RULES_PATH, SPEC, label=builtin_label("default"))
    if path is None or str(path) == "default":
        content = default
    elif str(path) in BUILTIN_RULES:
        content = read_rules_file(BUILTIN_RULES[str(path)], SPEC, label=builtin_label(str(path)))
    else:
        content = read_rules_file(path, SPEC)
    values = {s: dict(default.values.get(s, {})) for s in SPEC}
    for s, kv in content.values.items():
        values[s].update(kv)
    given = {}
    origin = {}  # (section, key) -> the option that set it
    for opt, v in (overrides or {}).items():
        if v is None:
            continue
        s, k = OPTIONS[opt]
        values[s][k] = v
        given[opt] = v
        origin[(s, k)] = opt
    flight, predict = build(values, content.label, origin)
    return RuleSet(flight, predict, content.label, content.sha256, values, given, chosen_by)


# which (section, key) each dataclass field comes from, for error messages
_FIELD_KEY = {
    "FlightRules.max_tilt_rad": ("flight_rules", "max_tilt_deg"),
    "FlightRules.min_confidence": ("flight_rules", "min_p_success"),
    "ApproachParams.detour_bearings_rad": ("approach", "detour_bearings_deg"),
    "ApproachParams.detour_bearings_rad[]": ("approach", "detour_bearings_deg"),
    "ApproachParams.hazcam_stops_m[]": ("approach", "hazcam_stops_m"),
    "ApproachParams.turn_step_rad": ("approach", "turn_step_deg"),
    "UncertaintyParams.sigma_yaw_rad": ("uncertainty", "sigma_yaw_deg"),
    "UncertaintyParams.default_sigma_yaw_rad": ("uncertainty", "default_sigma_yaw_deg"),
    "UncertaintyParams.yaw_error_rad_per_m": ("uncertainty", "yaw_error_deg_per_m"),
    "PredictParams.max_incidence_rad": ("prediction", "max_incidence_deg"),
    "PredictParams.handoff.template_half_px": ("tracking", "handoff_template_half_px"),
    "PredictParams.handoff.search_radius_px": ("tracking", "handoff_search_radius_px"),
}
_CLASS_SECTION = {"FlightRules": "flight_rules", "ApproachParams": "approach", "ArmWorkspace": "arm_workspace",
                  "RoverBody": "rover_body", "UncertaintyParams": "uncertainty", "PredictParams": "prediction"}


def build(values: dict, label: str, origin: Optional[dict] = None):
    """``(FlightRules, PredictParams)`` from complete ``values`` (``{section: {key: value}}``, every key of
    :data:`SPEC`), each ``check()``-ed; a range error is an :class:`InputError` naming ``label`` (or the option
    in ``origin`` that set the key) and ``section.key``."""
    from .chain import ChainParams
    from .predict import ApproachParams, ArmWorkspace, PredictParams, RoverBody, UncertaintyParams
    from .sequence import FlightRules

    f, a, u, t, p = (values[s] for s in ("flight_rules", "approach", "uncertainty", "tracking", "prediction"))
    try:
        flight = FlightRules(max_drive_m=f["max_drive_m"], min_standoff_m=f["min_standoff_m"],
                             target_keep_out_m=f["target_keep_out_m"], rock_keep_out_m=f["rock_keep_out_m"],
                             max_tilt_rad=math.radians(f["max_tilt_deg"]), min_confidence=f["min_p_success"],
                             min_p_simulated=f["min_p_simulated"],
                             hazcam_fov_margin_px=f["hazcam_fov_margin_px"],
                             min_terrain_known_fraction=f["min_terrain_known_fraction"]).check()
        approach = ApproachParams(
            stop_fraction=a["stop_fraction"], min_leg_m=a["min_leg_m"], merge_m=a["merge_m"],
            pancam_handoff_m=a["pancam_handoff_m"], hazcam_handoff_m=a["hazcam_handoff_m"],
            hazcam_stops_m=tuple(a["hazcam_stops_m"]), standoff_m=a["standoff_m"], standoff_step_m=a["standoff_step_m"],
            arm_margin_sigmas=a["arm_margin_sigmas"],
            detour_bearings_rad=tuple(math.radians(b) for b in a["detour_bearings_deg"]),
            path_step_m=a["path_step_m"], turn_step_rad=math.radians(a["turn_step_deg"]),
            rock_height_m=a["rock_height_m"], rock_cell_m=a["rock_cell_m"], ground_window_m=a["ground_window_m"],
            # one home for the keep-outs: the flight rules; the planner keeps the same clearances
            rock_keep_out_m=f["rock_keep_out_m"], target_keep_out_m=f["target_keep_out_m"],
            arm=ArmWorkspace(**values["arm_workspace"]), body=RoverBody(**values["rover_body"]))
        uncertainty = UncertaintyParams(
            sigma_position_m=u["sigma_position_m"],
            sigma_yaw_rad=None if u["sigma_yaw_deg"] is None else math.radians(u["sigma_yaw_deg"]),
            default_sigma_position_m=u["default_sigma_position_m"],
            default_sigma_yaw_rad=math.radians(u["default_sigma_yaw_deg"]),
            drive_error_frac=u["drive_error_frac"], yaw_error_rad_per_m=math.radians(u["yaw_error_deg_per_m"]),
            disparity_sigma_px=u["disparity_sigma_px"], n_samples=u["n_samples"],
            n_track_samples=u["n_track_samples"], seed=u["seed"])
        base = PredictParams()
        chain = replace(ChainParams(), template_half_px=dict(t["template_half_px"]),
                        search_radius_px=dict(t["search_radius_px"]))
        handoff = replace(base.handoff, template_half_px=t["handoff_template_half_px"],
                          search_radius_px=t["handoff_search_radius_px"])
        predict = replace(base, approach=approach, uncertainty=uncertainty, chain=chain, handoff=handoff,
                          occlusion_tol_m=p["occlusion_tol_m"], low_texture_std=p["low_texture_std"],
                          min_coverage=p["min_coverage"], max_incidence_rad=math.radians(p["max_incidence_deg"]),
                          max_foreshortening_change=p["max_foreshortening_change"],
                          risk_probability=p["risk_probability"], search_margin_px=p["search_margin_px"]).check()
    except ValueError as e:
        s, k = _key_of(str(e))
        opt = (origin or {}).get((s, k))
        raise InputError(opt or label, f"{s}.{k}", str(e)) from None
    return flight, predict


def _key_of(message: str):
    """``(section, key)`` a check() message ``"Owner.field: ..."`` is about (ChainParams' per-camera dicts:
    ``tracking``)."""
    head = message.split(":", 1)[0].strip()
    if head in _FIELD_KEY:
        return _FIELD_KEY[head]
    owner, _, fld = head.partition(".")
    if owner == "ChainParams" or head.split("[")[0] in ("template_half_px", "search_radius_px"):
        return "tracking", (fld or head).split("[")[0]
    return _CLASS_SECTION.get(owner, "rules"), fld.rstrip("[]") or head
