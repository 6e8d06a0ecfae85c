"""Fitting and judging the closure's trust model on campaign chain records (scikit-learn; docs/stereo-and-tracking.md,
"Closure as the answer").

A row is one chain whose closure was confirmed and found a pixel (the only closures the chain adopts): its
:class:`~scipctl.core.closure_trust.ClosureEvidence` and whether the closure pixel lay within ``success_px`` of the
target's mark in the final hazcam image. The model is an L2-regularised logistic regression on standardised
features (the same fit and the same regularisation as ``scip``'s, :mod:`scipctl.pipeline.trust_fit`); its GO
threshold is the smallest p on ``GO_GRID`` whose leave-one-family-out GO answers are right ``GO_PRECISION`` of the
time (1.0, never GO, when none is).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Optional

import numpy as np

from ..core.closure_trust import CLOSURE_FEATURES, ClosureEvidence, ClosureTrustModel
from ..core.handoff.trust_model import feature_matrix
from .trust_fit import CLIP_Z, GO_GRID, GO_PRECISION, fit_logistic, round_sig, standardise, usable_features

SUCCESS_PX = 4.0  # the hazcam success radius of issue #14 (1 cm at 1 m)


@dataclass
class ClosureRow:
    """One chain's confirmed closure: where it comes from, its evidence (dict of
    :meth:`ClosureEvidence.to_dict`), the closure pixel's and the handoff path's distances to the mark (hazcam
    px; None: no mark)."""

    family: str
    downlink: str
    target: str
    evidence: dict
    closure_error_px: Optional[float]
    handoff_error_px: Optional[float]

    def to_dict(self) -> dict:
        return dict(self.__dict__)

    @classmethod
    def from_dict(cls, d: dict) -> "ClosureRow":
        return cls(**{k: d.get(k) for k in cls.__dataclass_fields__})


def closure_row(record: dict, family: str, downlink: str, step_model=None) -> Optional[ClosureRow]:
    """The :class:`ClosureRow` of one chain record (``campaign``'s ``record`` of kind ``chain``), or None when its
    closure was not confirmed with a pixel. Works on chains that adopted the closure as their answer (the handoff
    path's pixel is then in the final step's ``extra["handoff"]``) and on chains that only checked it.

    ``step_model``: a :class:`~scipctl.core.step_trust.StepTrustModel` that scores the chain's tracking steps
    again (:func:`~scipctl.pipeline.chain_trust.score_steps`) before the evidence is read, so that the reference's
    ``ref_p_success`` is that model's, as a chain run with it would have it; None: the ``p_success`` recorded."""
    from .chain import ChainStep
    from .chain_closure import closure_evidence
    from .chain_trust import score_steps

    steps = [ChainStep.from_dict(s) for s in record.get("steps", [])]
    if step_model is not None:
        score_steps(steps, step_model)
    final = next((s for s in steps if s.camera == "hazcam" and s.extra.get("final")), None)
    if final is None:
        return None
    cl = final.extra.get("closure") or {}
    if cl.get("status") != "confirmed" or cl.get("uv") is None:
        return None
    mk = final.mark_uv
    ce = None if mk is None else float(math.dist(cl["uv"], mk))
    handoff = final.extra.get("handoff")
    h_uv = handoff.get("uv") if isinstance(handoff, dict) else final.tracked_uv
    he = None if (mk is None or h_uv is None) else float(math.dist(h_uv, mk))
    return ClosureRow(family, downlink, str(record.get("target") or ""),
                      closure_evidence(steps, cl).to_dict(), ce, he)


def training_rows(rows: list, success_px: float = SUCCESS_PX):
    """``(evidence list, y bool (N,), families)`` of the rows with a mark."""
    keep = [r for r in rows if r.closure_error_px is not None]
    return ([ClosureEvidence.from_dict(r.evidence) for r in keep],
            np.array([r.closure_error_px <= success_px for r in keep], bool), [r.family for r in keep])


def fit_closure_model(evidence: list, y: np.ndarray, success_px: float = SUCCESS_PX, go_min_p: float = 1.0,
                      provenance: Optional[dict] = None) -> ClosureTrustModel:
    """One logistic model on ``evidence``/``y`` (the features that vary in the data; unknown at the mean)."""
    spec = dict(CLOSURE_FEATURES)
    X = feature_matrix(evidence, spec)
    spec = {n: spec[n] for n in usable_features(X, list(spec))}
    X = feature_matrix(evidence, spec)
    fill, mean, scale = standardise(X)
    Z = np.clip((np.where(np.isfinite(X), X, fill) - mean) / scale, -CLIP_Z, CLIP_Z)
    coef, icpt = fit_logistic(Z, y)
    return ClosureTrustModel(spec, [round_sig(v) for v in fill], [round_sig(v) for v in mean],
                             [round_sig(v) for v in scale], [round_sig(v) for v in coef], round_sig(icpt), go_min_p,
                             success_px, dict(provenance or {}), CLIP_Z)


def held_out(rows: list, success_px: float = SUCCESS_PX) -> list:
    """``[(row, p, within)]`` for every row with a mark, each ``p`` from a model fitted on the other families."""
    out = []
    for fam in sorted({r.family for r in rows}):
        ev, y, _ = training_rows([r for r in rows if r.family != fam], success_px)
        test = [r for r in rows if r.family == fam and r.closure_error_px is not None]
        if not test:
            continue
        if len(set(y.tolist())) < 2:  # one class only: no model; the training rate
            ps = np.full(len(test), float(y.mean()) if len(y) else 0.5)
        else:
            m = fit_closure_model(ev, y, success_px)
            ps = m.probability([ClosureEvidence.from_dict(r.evidence) for r in test])
        out += [(r, float(p), r.closure_error_px <= success_px) for r, p in zip(test, ps)]
    return out


def choose_go_min_p(pairs: list, grid=GO_GRID, precision: float = GO_PRECISION) -> float:
    """The smallest ``p`` on ``grid`` whose GO answers (``p >= t``) among ``pairs`` ``[(row, p, within)]`` are
    right at least ``precision`` of the time and at least one is GO; 1.0 (never GO) when none is."""
    for t in grid:
        go = [w for _, p, w in pairs if p >= t]
        if go and sum(go) / len(go) >= precision:
            return float(t)
    return 1.0
