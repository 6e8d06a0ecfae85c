"""The stops and handoffs of a predicted approach that are at risk, and why."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Optional

from .chain_sim import ChainResult
from .montecarlo import McResult
from .params import PredictParams
from .planning import ApproachPlan


@dataclass
class Risk:
    stop: int
    camera: str
    what: str  # "view" | "handoff pancam->navcam" | "handoff navcam->hazcam" | "arm"
    probability: Optional[float]
    reasons: list

    def to_dict(self) -> dict:
        return dict(self.__dict__)


def assess_risks(plan: ApproachPlan, mc: Optional[McResult], chain: Optional[ChainResult],
                 params: PredictParams) -> list:
    """Stops and handoffs at risk, each with the reasons (occlusion, out of field of view, outside the
    search region, low texture, no terrain data, too oblique, tracking loses the target, drift, arm workspace;
    :func:`run_prediction` adds the foreshortening changes)."""
    risks = []
    mcv = {(v.stop, v.camera): v for v in (mc.views if mc else [])}
    chv = {(v["stop"], v["camera"]): v for v in (chain.per_view if chain else [])}
    for st in plan.stops[1:]:
        for sh in st.cameras:
            reasons = []
            key = (st.index, sh.camera)
            v = mcv.get(key)
            c = chv.get(key)
            what = c["kind"] if c is not None and c["kind"] != "track" else "view"
            if sh.uv is None:
                reasons.append(sh.note or "target not in view")
            else:
                if not sh.in_fov:
                    reasons.append("out of field of view (nominal)")
                if sh.occluded:
                    reasons.append("occlusion (nominal line of sight blocked)")
                if sh.coverage is not None and sh.coverage < params.min_coverage:
                    reasons.append(f"no terrain data around the target ({100 * sh.coverage:.0f}% of the window)")
                if sh.texture_std is not None and sh.texture_std < params.low_texture_std:
                    reasons.append(f"low texture (window std {sh.texture_std:.3f})")
                if sh.incidence_rad is not None and sh.incidence_rad > params.max_incidence_rad:
                    reasons.append(f"too oblique (incidence {math.degrees(sh.incidence_rad):.0f} deg)")
            if v is not None:
                if v.p_in_fov < params.risk_probability and sh.in_fov:
                    reasons.append(f"out of field of view (P in view {v.p_in_fov:.2f})")
                if params.tracker_reach == "search" and v.p_in_search < params.risk_probability:
                    reasons.append(f"outside the search region (P {v.p_in_search:.2f}, offset {v.offset_px_p90:.0f} px at the 90th percentile of the samples in view)")
                if v.p_visible < params.risk_probability:
                    reasons.append(f"occlusion (P visible {v.p_visible:.2f})")
            if c is not None:
                pk = c.get("p_kept_given_visible")
                geometric = ("target lost earlier", "out of the field of view", "occluded", "target behind the camera",
                             "cannot point", "target not in view")
                if not c["nominal_kept"] and c["nominal_reason"] not in geometric and c["nominal_reason"] != sh.note:
                    reasons.append(f"tracking loses the target on the nominal expected view ({c['nominal_reason']})")
                elif pk is not None and pk < params.risk_probability:
                    reasons.append(f"tracking loses the target on expected views (P kept {pk:.2f})")
                elif not c["nominal_ok"] and c["nominal_error_m"] is not None:
                    reasons.append(c["nominal_reason"])
            prob = None
            if v is not None:
                prob = v.p_ok
                if c is not None and c.get("p_kept_given_visible") is not None:
                    prob = prob * c["p_kept_given_visible"]
            if reasons:
                risks.append(Risk(st.index, sh.camera, what, prob, reasons))
    if mc is not None and mc.p_arm_workspace is not None and mc.p_arm_workspace < params.risk_probability:
        risks.append(Risk(plan.stops[-1].index, "arm", "arm", mc.p_arm_workspace,
                          [f"target may fall outside the arm workspace (P inside {mc.p_arm_workspace:.2f})"]))
    return risks


def foreshortening_changes(plan: ApproachPlan) -> dict:
    """``cos(incidence)`` ratio of each view to the previous view of the chain: ``{(stop, camera): ratio}``.

    A planar target's apparent aspect scales with ``cos(incidence)``; the chain
    rescales windows isotropically (range / IFOV), so a ratio far from 1 is an
    anisotropic change NCC has to absorb.
    """
    out = {}
    prev = None
    for st in plan.stops[1:]:
        for sh in st.cameras:
            if sh.uv is None or sh.incidence_rad is None:
                continue
            c = max(math.cos(sh.incidence_rad), 1e-3)
            if prev is not None:
                out[(st.index, sh.camera)] = c / prev
            prev = c
    return out
