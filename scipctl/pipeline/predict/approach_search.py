"""The record of the planner's search over (approach bearing, final standoff): what was tried, what each
candidate broke, and, when nothing cleared, which constraint bound and what would satisfy it."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Optional

# the planner's constraints, by the flight-rule names of pipeline/sequence.py
ROCK, TARGET, FOV = "rock-keep-out", "target-keep-out", "hazcam-fov-final"
# the preference the planner keeps when it can: the final drive's error margin inside the arm workspace
ARM_MARGIN = "arm-margin"


def _num(x) -> Optional[float]:
    return float(x) if x is not None and math.isfinite(x) else None


@dataclass
class ApproachSearch:
    """Candidates tried by :func:`~scipctl.pipeline.predict.planning.plan_approach`, in order.

    Each entry of ``tried``: ``detour_deg``, ``standoff_m``, ``min_rock_m``, ``min_target_m``
    (footprint clearances over the swept path), ``hazcam_margin_px`` (target from the hazcam images' edges at
    the final pose), ``bound_by`` (the constraints it breaks; empty for a clear plan), ``arm_room_m`` (the
    designated point's distance inside the arm workspace's radial limits), ``arm_margin_m`` (the room the final
    drive's error needs, :mod:`~.arm_margin`; None when not asked) and ``short_of_margin`` (room < margin).
    """

    rock_keep_out_m: float
    target_keep_out_m: float
    tried: list = field(default_factory=list)
    kept: Optional[int] = None  # the index in ``tried`` of the plan kept

    def add(self, detour_deg: float, standoff_m: float, clearance: dict, hazcam_margin_px: float,
            fov_margin_px: float, arm_room_m: Optional[float] = None, arm_margin_m: Optional[float] = None) -> None:
        bound = []
        if not clearance["min_rock_m"] >= self.rock_keep_out_m:
            bound.append(ROCK)
        if not clearance["min_target_m"] >= self.target_keep_out_m:
            bound.append(TARGET)
        if not hazcam_margin_px >= fov_margin_px:
            bound.append(FOV)
        self.tried.append({"detour_deg": float(detour_deg), "standoff_m": float(standoff_m),
                           "min_rock_m": _num(clearance["min_rock_m"]), "min_target_m": _num(clearance["min_target_m"]),
                           "hazcam_margin_px": _num(hazcam_margin_px), "bound_by": bound,
                           "arm_room_m": _num(arm_room_m), "arm_margin_m": _num(arm_margin_m),
                           "short_of_margin": bool(arm_margin_m is not None
                                                  and (arm_room_m is None or not arm_room_m >= arm_margin_m))})

    @property
    def found(self) -> bool:
        return any(not t["bound_by"] for t in self.tried)

    @property
    def found_with_margin(self) -> bool:
        return any(not t["bound_by"] and not t["short_of_margin"] for t in self.tried)

    def margin_binding(self) -> list:
        """When a plan cleared but none with the arm margin: the constraints the candidates with the margin broke
        (as :meth:`binding` over them; ``[arm-margin]`` alone when no candidate had the room). Else empty."""
        if self.found_with_margin or not self.found:
            return []
        roomy = [t for t in self.tried if not t["short_of_margin"]]
        if not roomy:
            return [ARM_MARGIN]
        sub = ApproachSearch(self.rock_keep_out_m, self.target_keep_out_m, roomy)
        return sub.binding()

    def describe_margin(self) -> str:
        """One sentence for a kept plan short of the arm margin: its room, what was searched and the binding
        constraint."""
        kept = self.tried[self.kept]
        span = f"{len(self.tried)} approaches tried"
        head = (f"the designated point is {kept['arm_room_m']:.3f} m inside the arm workspace's edge, the final "
                f"drive's error needs {kept['arm_margin_m']:.3f} m (approach.arm_margin_sigmas)")
        b = self.margin_binding()
        if b == [ARM_MARGIN]:
            return f"{head}; {span} and no standoff inside the workspace has that room"
        return (f"{head}; {span}: the candidates with that room break {', '.join(b)}, so the plan kept is "
                f"the first that clears the flight rules")

    def binding(self) -> list:
        """The constraints no candidate met (each alone); when every one was met by some candidate but never all
        at once, the constraints of the candidate that broke the fewest. Empty when a plan cleared."""
        if not self.tried or self.found:
            return []
        names = [ROCK, TARGET, FOV]
        never = [n for n in names if all(n in t["bound_by"] for t in self.tried)]
        if never:
            return never
        fewest = min(self.tried, key=lambda t: len(t["bound_by"]))
        return list(fewest["bound_by"])

    def best_for(self, rule: str) -> Optional[dict]:
        """The candidate that came closest to meeting ``rule`` (largest clearance or margin)."""
        key = {ROCK: "min_rock_m", TARGET: "min_target_m", FOV: "hazcam_margin_px"}[rule]
        c = [t for t in self.tried if t[key] is not None]
        return max(c, key=lambda t: t[key]) if c else None

    def describe(self, rule: str) -> str:
        """One sentence for a refusal on ``rule``: what was searched, the closest candidate, what would satisfy it."""
        if not self.tried:
            return "no approach was planned"
        det = sorted({t["detour_deg"] for t in self.tried})
        sto = sorted({t["standoff_m"] for t in self.tried})
        span = (f"{len(self.tried)} approaches tried (detour {det[0]:+.0f}..{det[-1]:+.0f} deg, standoff "
                f"{sto[0]:.2f}-{sto[-1]:.2f} m)")
        if self.found:
            return f"{span}; the plan kept clears it"
        if any(rule not in t["bound_by"] for t in self.tried):
            others = ", ".join(r for r in self.binding() if r != rule) or "the other constraints"
            return (f"{span}: some clear {rule}, none together with {others}; the plan kept is the one closest to "
                    f"clearing them all")
        b = self.best_for(rule)
        if rule == ROCK:
            best = "" if b is None else (f"; the best comes to {b['min_rock_m']:.2f} m (detour {b['detour_deg']:+.0f} deg, "
                                         f"standoff {b['standoff_m']:.2f} m)")
            fix = ("another approach side (a detour beyond those in approach.detour_bearings_deg), a target on the "
                   "rock's far side, or a new designation")
        elif rule == TARGET:
            best = "" if b is None else (f"; the best comes to {b['min_target_m']:.2f} m (detour {b['detour_deg']:+.0f} "
                                         f"deg, standoff {b['standoff_m']:.2f} m)")
            fix = "a longer standoff (the arm workspace's outer radius) or a smaller footprint keep-out"
        else:
            best = "" if b is None or b["hazcam_margin_px"] is None else (
                f"; the best leaves {b['hazcam_margin_px']:.0f} px (detour {b['detour_deg']:+.0f} deg, standoff "
                f"{b['standoff_m']:.2f} m)")
            fix = "a target lower on the rock or a standoff farther out"
        return f"{span} and none clears {rule}{best}: {fix} would"

    def to_dict(self) -> dict:
        return {"tried": [dict(t, bound_by=list(t["bound_by"])) for t in self.tried], "found": self.found,
                "binding": self.binding(), "found_with_margin": self.found_with_margin,
                "margin_binding": self.margin_binding(), "kept": self.kept}
