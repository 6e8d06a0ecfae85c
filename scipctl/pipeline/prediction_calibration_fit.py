"""Fitting and judging the pre-uplink prediction's calibration on campaign records (scikit-learn; docs/sequence.md,
"Calibrated against the chain").

A row is one approach: the prediction made from today's stop of a downlink (a ``campaign`` prediction record, its
route the campaign's ``--predict-route``) and the chain then run over that downlink's later stops (a ``campaign``
chain record of the same downlink, matched by SHA-256, and target). The outcome is the chain's last hazcam answer
within ``success_px`` of the target's mark (no hazcam answer: a miss), as ``docs/scripts/prediction_vs_chain.py``
scores it. The model is an L2-regularised logistic regression on the standardised ``p_simulated`` (the same fit and
regularisation as ``scip``'s, :mod:`scipctl.pipeline.trust_fit`), one per route.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Optional

import numpy as np

from ..core.handoff.trust_model import feature_matrix
from ..core.prediction_calibration import PREDICTION_FEATURES, PredictionCalibration, PredictionEvidence
from .trust_fit import CLIP_Z, fit_logistic, round_sig, standardise

SUCCESS_PX = 4.0  # the final hazcam radius of issue #15's outcome (the chain's, issue #14's: 1 cm at 1 m)


def last_hazcam_error_px(steps: list) -> Optional[float]:
    """The chain's outcome the prediction is scored against: the error (px) of its last hazcam step, from a campaign
    chain record's ``steps`` (dicts); None when the chain made no hazcam step or that step has no error."""
    haz = [s for s in steps if s.get("camera") == "hazcam"]
    return haz[-1].get("error_px") if haz else None


@dataclass
class PredictionRow:
    """One approach: its route, family, downlink (``folder/file`` name and SHA-256), target, what the prediction
    simulated (``p_simulated``) and the chain's final hazcam error (px; None: the chain gave no hazcam answer)."""

    route: str
    family: str
    downlink: str
    downlink_sha256: str
    target: str
    p_simulated: float
    chain_error_px: Optional[float]

    def success(self, success_px: float = SUCCESS_PX) -> bool:
        return self.chain_error_px is not None and self.chain_error_px <= success_px

    def to_dict(self) -> dict:
        return dict(self.__dict__)

    @classmethod
    def from_dict(cls, d: dict) -> "PredictionRow":
        return cls(**{k: d.get(k) for k in cls.__dataclass_fields__})


def _campaign_files(folder: Path):
    """``(header, records)`` of every downlink of a campaign folder that ran (status ``ok``), in file-name order."""
    for f in sorted(Path(folder, "records").glob("*.jsonl")):
        lines = [json.loads(line) for line in f.read_text(encoding="utf-8").splitlines() if line.strip()]
        if lines and lines[0].get("kind") == "downlink" and lines[0].get("status") == "ok":
            yield lines[0], lines[1:]


def campaign_route(folder: Path) -> str:
    """The predicted route a campaign folder ran with (its manifest's ``options.predict_route``; ``plan`` when the
    manifest predates the option)."""
    manifest = json.loads(Path(folder, "manifest.json").read_text(encoding="utf-8"))
    return str((manifest.get("options") or {}).get("predict_route") or "plan")


def p_simulated_of(record: dict) -> Optional[float]:
    """The simulated probability of a campaign prediction record: ``prediction.p_simulated``, or, in records made
    before the calibration existed (no such field), ``confidence``, which was then the simulated probability."""
    pred = record.get("prediction") or {}
    v = pred["p_simulated"] if "p_simulated" in pred else record.get("confidence")
    return None if v is None else float(v)


def approach_rows(pred_dirs: list, chain_dirs: list) -> list:
    """The :class:`PredictionRow` of every predicted target whose downlink (same SHA-256) and target have a chain
    record in ``chain_dirs`` (a downlink in several chain folders: its first's). Predictions that failed (no
    ``confidence``) and targets without a chain are left out."""
    chains = {}
    for d in chain_dirs:
        for head, recs in _campaign_files(Path(d)):
            chains.setdefault(head["downlink_sha256"], {r["record"]["target"]: r["record"] for r in recs
                                                        if r.get("kind") == "chain"})
    rows = []
    for d in pred_dirs:
        route = campaign_route(Path(d))
        for head, recs in _campaign_files(Path(d)):
            ch = chains.get(head["downlink_sha256"], {})
            path = Path((head.get("job") or {}).get("path") or head.get("downlink"))
            name = f"{path.parent.name}/{path.name}"
            for r in recs:
                rec = r.get("record") or {}
                if r.get("kind") != "prediction" or rec.get("target") not in ch:
                    continue
                p = p_simulated_of(rec)
                if p is None:
                    continue
                err = last_hazcam_error_px(ch[rec["target"]].get("steps", []))
                rows.append(PredictionRow(route, str(head.get("family") or "default"), name,
                                          head["downlink_sha256"], str(rec["target"]), p,
                                          None if err is None else float(err)))
    return sorted(rows, key=lambda r: (r.route, r.family, r.downlink, r.target))


def training_data(rows: list, success_px: float = SUCCESS_PX):
    """``(evidence list, y bool (N,), families)``."""
    return ([PredictionEvidence(r.p_simulated) for r in rows], np.array([r.success(success_px) for r in rows], bool),
            [r.family for r in rows])


def fit_calibration(evidence: list, y: np.ndarray, success_px: float = SUCCESS_PX,
                    provenance: Optional[dict] = None) -> PredictionCalibration:
    """One logistic model on ``evidence``/``y``; when ``p_simulated`` does not vary in the data, the intercept alone
    (the base rate)."""
    spec = dict(PREDICTION_FEATURES)
    X = feature_matrix(evidence, spec)
    fill, mean, scale = standardise(X)
    Z = np.clip((np.where(np.isfinite(X), X, fill) - mean) / scale, -CLIP_Z, CLIP_Z)
    coef, icpt = fit_logistic(Z, y)
    return PredictionCalibration(spec, [round_sig(v) for v in fill], [round_sig(v) for v in mean],
                                 [round_sig(v) for v in scale], [round_sig(v) for v in coef], round_sig(icpt), 1.0,
                                 success_px, dict(provenance or {}), CLIP_Z)


def held_out(rows: list, success_px: float = SUCCESS_PX) -> list:
    """``[(row, p, success)]`` for every row, each ``p`` from a calibration fitted on the other families' rows of
    the same route (one class only among them: their rate)."""
    out = []
    for route in sorted({r.route for r in rows}):
        R = [r for r in rows if r.route == route]
        for fam in sorted({r.family for r in R}):
            ev, y, _ = training_data([r for r in R if r.family != fam], success_px)
            test = [r for r in R if r.family == fam]
            if len(set(y.tolist())) < 2:
                ps = np.full(len(test), float(y.mean()) if len(y) else 0.5)
            else:
                ps = fit_calibration(ev, y, success_px).probability([PredictionEvidence(r.p_simulated) for r in test])
            out += [(r, float(p), r.success(success_px)) for r, p in zip(test, ps)]
    return out


BINS = ((0.0, 0.2), (0.2, 0.5), (0.5, 0.7), (0.7, 0.9), (0.9, 1.0001))


def scores(pairs: list) -> dict:
    """Brier score (and the base rate's, the pairs' own), ROC AUC (scikit-learn's) and the reliability of
    ``[(row, p, success)]``."""
    p = np.array([x[1] for x in pairs], float)
    y = np.array([x[2] for x in pairs], bool)
    out = {"n": int(len(p)), "success": int(y.sum()), "mean_p": float(p.mean()) if len(p) else None,
           "brier": float(np.mean((p - y) ** 2)) if len(p) else None,
           "brier_base_rate": float(np.mean((y.mean() - y) ** 2)) if len(p) else None, "auc": None,
           "reliability": []}
    if 0 < y.sum() < len(y):
        from sklearn.metrics import roc_auc_score

        out["auc"] = float(roc_auc_score(y, p))
    for lo, hi in BINS:
        m = (p >= lo) & (p < hi)
        out["reliability"].append({"lo": lo, "hi": min(hi, 1.0), "n": int(m.sum()),
                                   "mean_p": float(p[m].mean()) if m.any() else None,
                                   "observed": float(y[m].mean()) if m.any() else None})
    return out
