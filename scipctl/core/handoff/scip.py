"""``scip``: the recommended navcam -> hazcam handoff, one answer per target with a calibrated ``p_success`` and a
GO/NO-GO (pure numerics).

Every method of :data:`~scipctl.core.handoff.evidence.CANDIDATE_METHODS` answers from every navcam view it has
(near, far); each distinct answer is a candidate; each candidate gets its :class:`~.evidence.Evidence` and the
trust model's P(within ``success_px`` | evidence); the answer is the most probable candidate, ``p_success`` its
probability, ``go`` = ``p_success >= go_min_p`` unless the geometry vetoes the answer (its hazcam point is
farther than ``geometry_veto_px`` from the navcam target in every view). Without a trust model (or for a
``success_px`` the model was not fitted around) ``p_success`` is None and the answer NO-GO.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Optional

import numpy as np

from . import geometric, kinematic, registration
from .case import HandoffCase
from .evidence import CANDIDATE_METHODS, Candidate, Evidence, candidate_evidence, candidates_of, target_views
from .params import HandoffParams
from .result import MethodResult, NoAnswer
from .run import call_method

SCIP = "scip"


@dataclass
class ScoredCandidate:
    """A candidate with its evidence and probability (None without a usable model)."""

    candidate: Candidate
    evidence: Evidence
    p_success: Optional[float]


@dataclass
class ScipOutcome:
    """``scip``'s answer for one target (``result.method == "scip"``, ``result.navcam``: ``near``, ``far`` or
    ``both``) and every candidate it weighed."""

    result: MethodResult
    scored: list  # list[ScoredCandidate]
    p_success: Optional[float]
    go: bool

    def p_of(self, method: str, navcam: str) -> Optional[float]:
        """The probability of the candidate ``method``/``navcam`` answered (None if it gave none or no model)."""
        for s in self.scored:
            if (method, navcam) in s.candidate.sources:
                return s.p_success
        return None


def _navcam_used(sources) -> str:
    ncs = {nc for _, nc in sources}
    return "both" if len(ncs) > 1 else next(iter(ncs))


def scip_from_results(cases: dict[str, HandoffCase], nav_uvs: dict, results: list[MethodResult],
                      params: HandoffParams) -> ScipOutcome:
    """``scip`` for one target from the candidate methods' ``results`` (any order; methods outside
    :data:`CANDIDATE_METHODS` are ignored). ``cases`` / ``nav_uvs``: navcam label -> case / navcam-left pixel
    (2,) (None: the target is not seen there). The result has ``ok=False`` when no method answered."""
    sp = params.scip
    cands = candidates_of(results, sp.dedup_px)
    if not cands:
        res = MethodResult(SCIP, "both" if len(cases) > 1 else next(iter(cases), "near"), False, None,
                           "no candidate method answered", {"p_success": None, "go": False})
        return ScipOutcome(res, [], None, False)
    regs = {r.navcam: r for r in results if r.method == "mesh-registration" and r.ok}
    views = target_views(cases, nav_uvs, params, sp, regs)
    if not views:
        ev = [Evidence(c.sources[0][0], c.sources[0][1]) for c in cands]
    else:
        ev = [candidate_evidence(views, cands, i, sp) for i in range(len(cands))]
    model = sp.model
    p = model.probability(ev, sp.success_px) if model is not None else None
    go_min = sp.go_min_p if sp.go_min_p is not None else (model.go_threshold(sp.success_px) if model else None)
    diag: dict = {}
    if p is None:
        # no probability: the candidate most groups agree with (first on ties), NO-GO
        best = max(range(len(cands)), key=lambda i: (ev[i].support_groups if np.isfinite(ev[i].support_groups) else -1, -i))
        p_best, go = None, False
        diag["no_probability"] = ("no trust model loaded" if model is None else
                                  f"the trust model is fitted for success radii {', '.join(f'{r:g}' for r in model.success_radii_px)} px, "
                                  f"not around {sp.success_px:g} px")
    else:
        best = int(np.argmax(p))
        p_best = float(p[best])
        go = bool(go_min is not None and p_best >= go_min)
        res_px = ev[best].geo_best_nav_res_px
        if go and sp.geometry_veto_px is not None and res_px > sp.geometry_veto_px:  # NaN (unknown): no veto
            go = False
            diag["geometry_veto"] = (f"the hazcam point at the answer lands {res_px:.1f} px from the navcam target "
                                     f"in the view that agrees best (veto above {sp.geometry_veto_px:g} px)")
    scored = [ScoredCandidate(c, e, None if p is None else float(p[i])) for i, (c, e) in enumerate(zip(cands, ev))]
    chosen = cands[best]
    diag.update({
        "p_success": p_best, "go": go, "go_min_p": go_min, "success_px": sp.success_px,
        "chosen": [f"{m}/{nc}" for m, nc in chosen.sources],
        "candidates": [{"uv": s.candidate.uv.tolist(), "sources": [f"{m}/{nc}" for m, nc in s.candidate.sources],
                        "p_success": s.p_success} for s in scored],
        "evidence": ev[best].to_dict(),
        "views": sorted(views),
    })
    res = MethodResult(SCIP, _navcam_used(chosen.sources), True, chosen.uv.copy(), "" if go else "NO-GO", diag)
    return ScipOutcome(res, scored, p_best, go)


# the candidate methods' functions (their registry names: evidence.CANDIDATE_METHODS), as combined.py names its own
CANDIDATE_FNS = {
    "pure-kinematic": kinematic.pure_kinematic, "alt-pure-kinematic": kinematic.alt_pure_kinematic,
    "refined-kinematic": kinematic.refined_kinematic, "pure-geometric": geometric.pure_geometric,
    "refined-geometric": geometric.refined_geometric, "mesh-registration": registration.mesh_registration,
    "coarse-fine-geometric": geometric.coarse_fine_geometric,
}


def run_candidates(case: HandoffCase, nav_uv, params: HandoffParams, *,
                   near_hint: Optional[MethodResult] = None, skip=()) -> list[MethodResult]:
    """The candidate methods' results on one case (those named in ``skip`` are not run)."""
    return [call_method(CANDIDATE_FNS[m], m, case, nav_uv, params, near_hint=near_hint)
            for m in CANDIDATE_METHODS if m not in skip]


def scip(case: HandoffCase, nav_uv, params: HandoffParams, *, near_hint: Optional[MethodResult] = None) -> MethodResult:
    """``scip`` from one navcam view (the registry's single-case form; the pipeline's
    :func:`~scipctl.pipeline.handoff.run_targets` weighs the near and far views together)."""
    results = run_candidates(case, nav_uv, params, near_hint=near_hint)
    out = scip_from_results({case.label: case}, {case.label: nav_uv}, results, params)
    if not out.result.ok:
        raise NoAnswer(out.result.reason, out.result.diagnostics)
    return out.result
