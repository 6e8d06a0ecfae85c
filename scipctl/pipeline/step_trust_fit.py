"""Fitting and judging the chain's step trust model (scikit-learn at fit time only; docs/stereo-and-tracking.md,
"Trust along the chain").

Data: chains as a campaign records them (``kind: "chain"`` records of ``OUT/records/*.jsonl``), each turned into
a :class:`ChainRow` (:func:`chain_rows`): per step its :class:`~scipctl.core.step_trust.StepEvidence`, its error
against the mark and its pixel footprint, the hazcam handoff's ``scip`` answer. :func:`fit_step_model` fits one
L2-regularised logistic regression of "within ``success_mm``" on the tracking steps; :func:`held_out` answers
each family with a model fitted on the others (leave one family out), which is what the GO threshold is chosen
on and what the chain figures of :func:`chain_table` are measured on.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Optional

import numpy as np

from ..core.step_trust import STEP_FEATURES, StepEvidence, StepTrustModel
from ..core.handoff.trust_model import feature_matrix
from .trust_fit import CLIP_Z, round_sig, standardise, usable_features
from .trust_fit import fit_logistic as logistic  # the same regularisation (C_REG) as the scip model

# GO threshold: the smallest p on GO_GRID at which every held-out chain that misses (final hazcam answer not within
# 4 px, or none) is NO-GO at or before the step where it went wrong -- issue #14's requirement for the chain, chosen
# on the leave-one-family-out probabilities (so the held-out figure at that threshold is not independent of it)
GO_GRID = tuple(round(0.50 + 0.01 * i, 2) for i in range(50))  # 0.50 .. 0.99
HAZCAM_SUCCESS_PX = 4.0


@dataclass
class StepRow:
    """One chain step as the fit sees it. ``kind``: the tracking kind (``pancam-track``, ...), or ``designate``
    / ``hazcam-handoff``; ``error_px`` None: no pixel or no mark (``marked`` says which)."""

    index: int
    kind: str
    position: list
    error_px: Optional[float]
    marked: bool
    answered: bool
    px_mm: Optional[float]
    evidence: Optional[StepEvidence]  # tracking steps only
    p_scip: Optional[float] = None  # the hazcam handoff's
    go_scip: Optional[bool] = None
    final: bool = False

    def to_dict(self) -> dict:
        return {"index": self.index, "kind": self.kind, "position": list(self.position), "error_px": self.error_px,
                "marked": self.marked, "answered": self.answered, "px_mm": self.px_mm,
                "evidence": None if self.evidence is None else self.evidence.to_dict(), "p_scip": self.p_scip,
                "go_scip": self.go_scip, "final": self.final}

    @classmethod
    def from_dict(cls, d: dict) -> "StepRow":
        return cls(int(d["index"]), str(d["kind"]), list(d["position"]), d["error_px"], bool(d["marked"]),
                   bool(d["answered"]), d["px_mm"], None if d["evidence"] is None else StepEvidence.from_dict(d["evidence"]),
                   d.get("p_scip"), d.get("go_scip"), bool(d.get("final", False)))


@dataclass
class ChainRow:
    """One chain: its family (held out whole), downlink, target and steps."""

    family: str
    downlink: str
    target: str
    steps: list = field(default_factory=list)  # StepRow
    error: Optional[str] = None

    def to_dict(self) -> dict:
        return {"family": self.family, "downlink": self.downlink, "target": self.target, "error": self.error,
                "steps": [s.to_dict() for s in self.steps]}

    @classmethod
    def from_dict(cls, d: dict) -> "ChainRow":
        return cls(str(d["family"]), str(d["downlink"]), str(d["target"]),
                   [StepRow.from_dict(s) for s in d["steps"]], d.get("error"))


def chain_row(record: dict, family: str) -> ChainRow:
    """A :class:`ChainRow` from a campaign chain record (``{"downlink", "target", "steps": [ChainStep dicts]}``)."""
    from .chain import ChainStep
    from .chain_trust import step_evidence, step_kind

    steps = [ChainStep.from_dict(d, "chain record", i) for i, d in enumerate(record.get("steps") or [])]
    rows = []
    for i, s in enumerate(steps):
        k = step_kind(s)
        kind = k or ("designate" if s.kind == "designate" else f"{s.camera}-{s.kind}")
        rows.append(StepRow(i, kind, list(s.position), s.error_px, s.mark_uv is not None, s.tracked_uv is not None,
                            (s.extra or {}).get("px_mm"), None if k is None else step_evidence(steps, i),
                            # scip's own (chain_trust.score_hazcam_handoffs keeps it beside the chain's product)
                            (s.extra or {}).get("scip_p_success", s.p_success) if s.camera == "hazcam" else None,
                            (s.extra or {}).get("scip_go", s.go) if s.camera == "hazcam" else None,
                            bool((s.extra or {}).get("final"))))
    return ChainRow(family, str(record.get("downlink", "")), str(record["target"]), rows, record.get("error"))


def success_mm_of(chains: list) -> float:
    """``HAZCAM_SUCCESS_PX`` hazcam pixels at the final handoff's range, median over the chains that reached one
    (the hazcam's success radius, in mm across the line of sight): what a tracking step may be off by."""
    v = [s.px_mm for c in chains for s in c.steps if s.final and s.px_mm is not None]
    if not v:
        raise ValueError("no final hazcam step with a pixel footprint: cannot set success_mm")
    return round(HAZCAM_SUCCESS_PX * float(np.median(v)), 2)


def step_within(s: StepRow, success_mm: float) -> Optional[bool]:
    """A step's outcome: within ``success_mm`` (tracking steps; the hazcam handoff: within 4 px); None when it
    has no mark; False when it has no pixel."""
    if not s.marked:
        return None
    if not s.answered or s.error_px is None:
        return False
    if s.kind == "hazcam-handoff":
        return s.error_px <= HAZCAM_SUCCESS_PX
    if s.px_mm is None:
        return None
    return s.error_px * s.px_mm <= success_mm


def training_steps(chains: list, success_mm: float):
    """(evidence list, outcome array, family list) of the tracking steps that have a pixel and a mark."""
    ev, y, fam = [], [], []
    for c in chains:
        for s in c.steps:
            if s.evidence is None or not s.answered:
                continue
            w = step_within(s, success_mm)
            if w is None:
                continue
            ev.append(s.evidence)
            y.append(w)
            fam.append(c.family)
    return ev, np.array(y, bool), fam


def fit_logistic(evidence: list, y: np.ndarray, success_mm: float, go_min_p: float = 0.5,
                 features: Optional[dict] = None, provenance: Optional[dict] = None) -> StepTrustModel:
    """One logistic model on ``evidence``/``y`` (features that vary in the data only; unknown at the mean)."""
    spec = dict(STEP_FEATURES if features is None else features)
    X = feature_matrix(evidence, spec)
    names = usable_features(X, list(spec))
    spec = {n: spec[n] for n in names}
    X = feature_matrix(evidence, spec)
    fill, mean, scale = standardise(X)
    Z = np.clip((np.where(np.isfinite(X), X, fill) - mean) / scale, -CLIP_Z, CLIP_Z)
    coef, icpt = logistic(Z, y)
    return StepTrustModel(spec, [round_sig(v) for v in fill], [round_sig(v) for v in mean], [round_sig(v) for v in scale],
                          [round_sig(v) for v in coef], round_sig(icpt), go_min_p, success_mm, dict(provenance or {}),
                          CLIP_Z)


def held_out(chains: list, success_mm: float) -> dict:
    """``{family: (model fitted on the other families, [per chain: [p per step or None]])}``: each family's
    tracking steps answered by a model that never saw it."""
    out = {}
    for fam in sorted({c.family for c in chains}):
        ev, y, _ = training_steps([c for c in chains if c.family != fam], success_mm)
        m = fit_logistic(ev, y, success_mm)
        out[fam] = (m, [chain_probabilities(c, m) for c in chains if c.family == fam])
    return out


def chain_probabilities(c: ChainRow, model: StepTrustModel) -> list:
    """Per step of ``c``: the model's p for a tracking step with a pixel, 0 for a lost one, the scip p for the
    hazcam handoff, None for the designation."""
    idx = [i for i, s in enumerate(c.steps) if s.evidence is not None]
    p = model.probability([c.steps[i].evidence for i in idx]) if idx else []
    by = dict(zip(idx, p))
    out = []
    for i, s in enumerate(c.steps):
        if s.evidence is not None:
            out.append(float(by[i]) if s.answered else 0.0)
        elif s.kind == "hazcam-handoff":
            out.append(s.p_scip)
        else:
            out.append(None)
    return out


def choose_threshold(chains: list, held: dict, success_mm: float, grid=GO_GRID) -> float:
    """The smallest p on ``grid`` at which every chain of ``chains`` that misses is NO-GO at or before the step
    where it went wrong, each family's steps scored by ``held`` (:func:`held_out`); the grid's top when none."""
    for t in grid:
        ok = True
        for fam, (_, probs) in held.items():
            for c, pc in zip([c for c in chains if c.family == fam], probs):
                if not judge_chain(c, pc, t, success_mm).caught:
                    ok = False
                    break
            if not ok:
                break
        if ok:
            return float(t)
    return float(grid[-1])


@dataclass
class ChainOutcome:
    """One chain judged: its final hazcam error (None: no final answer), whether it is within 4 px, its GO, the
    first NO-GO step, the step where it went wrong (first step outside its radius; None: it did not)."""

    family: str
    final_error_px: Optional[float]
    within: bool
    go: bool
    first_nogo: Optional[int]
    wrong_at: Optional[int]

    @property
    def caught(self) -> bool:
        """A miss that is NO-GO at or before the step where it went wrong (a hit: True)."""
        if self.within:
            return True
        return self.first_nogo is not None and (self.wrong_at is None or self.first_nogo <= self.wrong_at)


def judge_chain(c: ChainRow, probs: list, go_min_p: float, success_mm: float) -> ChainOutcome:
    """:class:`ChainOutcome` of ``c`` with step probabilities ``probs`` (tracking steps GO at ``go_min_p``, the
    hazcam handoff at scip's GO, the designation GO), by the rule of :func:`~scipctl.pipeline.chain_trust.chain_verdict`."""
    if not c.steps:  # the chain stopped on its designation (no stereo there): NO-GO, wrong, at step 0
        return ChainOutcome(c.family, None, False, False, 0, 0)
    final = next((i for i, s in enumerate(c.steps) if s.final), None)
    upto = c.steps if final is None else c.steps[: final + 1]
    first_nogo, wrong_at = None, None
    for i, s in enumerate(upto):
        if s.kind == "hazcam-handoff" and i != final:
            continue
        if s.kind == "designate":
            go = True
        elif s.kind == "hazcam-handoff":
            go = bool(s.go_scip)
        else:
            go = probs[i] is not None and probs[i] >= go_min_p
        if not go and first_nogo is None:
            first_nogo = i
        w = step_within(s, success_mm)
        if w is False and wrong_at is None:
            wrong_at = i
    fs = c.steps[final] if final is not None else None
    err = None if fs is None else fs.error_px
    within = err is not None and err <= HAZCAM_SUCCESS_PX
    if final is None:
        # no final answer: the chain says NO-GO where it stopped (its last step) if no step said so before
        first_nogo = first_nogo if first_nogo is not None else len(c.steps) - 1
        if wrong_at is None:
            wrong_at = len(c.steps) - 1
    return ChainOutcome(c.family, err, within, final is not None and first_nogo is None, first_nogo, wrong_at)
