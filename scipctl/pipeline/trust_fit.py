"""Fitting and judging ``scip``'s trust model on evidence tables (scikit-learn; docs/handoff.md, "Trust: scip").

:func:`fit_trust_model` fits one L2-regularised logistic regression per success radius on every candidate row
(standardised features of :data:`~scipctl.core.handoff.trust_model.FEATURES`, unknown values at the training
mean) and picks each radius's GO threshold from leave-one-family-out predictions. :func:`evaluate` reports,
per family held out, what ``scip`` would have answered with a model fitted on the other families (and, for the
same folds, a gradient-boosting and an isotonic-calibrated alternative, so that the kept model earns its place).

Rows of occluded targets (hidden from the hazcam, :attr:`~.trust_data.EvidenceRow.occluded`) are wrong at every
radius: they are fitted on and count as false GO when answered GO, and the evaluation reports them apart
(``held_out_occluded``), so that the figures of the other targets stay comparable with tables that have none.
"""

from __future__ import annotations

import math
from collections import defaultdict
from typing import NamedTuple, Optional

import numpy as np

from ..core.handoff.evidence import Evidence
from ..core.handoff.trust_model import FEATURES, LogisticFit, TrustModel, feature_matrix
from .trust_data import EvidenceRow

RADII_PX = (1.0, 2.0, 4.0, 8.0)
C_REG = 0.1  # inverse L2 strength (scikit-learn's C), standardised features: the most regularised of the variants measured (docs/handoff.md "Trust: scip")
CLIP_Z = 5.0  # standardised features clipped to +-5 in the fit and at run time (TrustModel.clip_z)
# GO threshold: the smallest p on GO_GRID whose leave-one-family-out GO answers are right at least GO_PRECISION of
# the time (the target is 97 %: one point of margin). The grid starts at 0.90: a calibrated p under 0.9
# admits a 1-in-10 miss for that one answer, whatever the pooled precision says
GO_PRECISION = 0.98
GO_GRID = tuple(round(0.90 + 0.01 * i, 2) for i in range(10))  # 0.90 .. 0.99
SIG = 10  # significant digits kept in the model file (bit-for-bit reproducible across BLAS builds)


def round_sig(x: float) -> float:
    """``x`` to SIG significant digits: what a model file keeps (the same file from every BLAS build)."""
    return float(f"{x:.{SIG}g}")


def _errors(rows: list[EvidenceRow]) -> np.ndarray:
    """``(N,)`` the rows' true errors (px): an occluded target's, or an unknown one, is infinite (never right)."""
    return np.array([math.inf if (r.error_px is None or r.occluded) else r.error_px for r in rows], float)


def _prep(rows: list[EvidenceRow], spec: dict):
    ev = [Evidence.from_dict(r.evidence) for r in rows]
    return feature_matrix(ev, spec), _errors(rows)


def fit_rows(rows: list[EvidenceRow]) -> list[EvidenceRow]:
    """The rows a fit or an evaluation uses: those with a true error, and those of occluded targets."""
    return [r for r in rows if r.error_px is not None or r.occluded]


def usable_features(X: np.ndarray, names: list) -> list:
    """The features that vary in the training rows (a feature never known or constant carries nothing)."""
    keep = []
    for j, n in enumerate(names):
        col = X[:, j]
        fin = col[np.isfinite(col)]
        if len(fin) >= 2 and np.ptp(fin) > 0:
            keep.append(n)
    return keep


def standardise(X: np.ndarray):
    """``(fill, mean, scale)`` of the feature matrix ``X`` (N, F): NaN is filled with the column's mean, then
    each column is centred and scaled (a constant column keeps scale 1)."""
    fill = np.array([np.nanmean(c) if np.isfinite(c).any() else 0.0 for c in X.T])
    Xf = np.where(np.isfinite(X), X, fill)
    mean = Xf.mean(axis=0)
    scale = Xf.std(axis=0)
    scale = np.where(scale > 1e-12, scale, 1.0)
    return fill, mean, scale


def fit_logistic(Z: np.ndarray, y: np.ndarray):
    """L2 logistic regression of ``y`` (N,) bool on standardised ``Z`` (N, F): ``(coef (F,), intercept)``; a
    constant model when ``y`` has one class."""
    from sklearn.linear_model import LogisticRegression

    if y.all() or not y.any():  # one class only: a constant model
        p = 0.999 if y.all() else 0.001
        return np.zeros(Z.shape[1]), math.log(p / (1 - p))
    lr = LogisticRegression(C=C_REG, solver="lbfgs", max_iter=10000, tol=1e-10)
    lr.fit(Z, y)
    return lr.coef_[0], float(lr.intercept_[0])


def fit_raw_model(rows: list[EvidenceRow], radii=RADII_PX, features: Optional[dict] = None) -> TrustModel:
    spec = dict(FEATURES if features is None else features)
    X, err = _prep(rows, spec)  # every feature of every row, built once
    names = usable_features(X, list(spec))
    # the columns kept (each column is its feature's alone), C-ordered as feature_matrix makes them: the column
    # means and sums, and so the fit, round as they did (a Fortran-ordered copy moved coefficients in the 10th digit)
    X = np.ascontiguousarray(X[:, [list(spec).index(n) for n in names]])
    spec = {n: spec[n] for n in names}
    fill, mean, scale = standardise(X)
    Z = np.clip((np.where(np.isfinite(X), X, fill) - mean) / scale, -CLIP_Z, CLIP_Z)  # as TrustModel evaluates
    fits = []
    for r in radii:
        coef, b = fit_logistic(Z, err <= r)
        fits.append(LogisticFit(float(r), [round_sig(c) for c in coef], round_sig(b), 1.0))
    return TrustModel(spec, [round_sig(v) for v in fill], [round_sig(v) for v in mean], [round_sig(v) for v in scale], fits,
                      clip_z=CLIP_Z)


def targets_of(rows: list[EvidenceRow]) -> dict:
    """(group, target) -> its rows (candidates), in row order."""
    out = defaultdict(list)
    for r in rows:
        out[(r.group, r.target)].append(r)
    return out


class ScipChoice(NamedTuple):
    """scip's answer for one target of an evidence table (a tuple: scripts read it by index too)."""

    family: str
    p: float  # p_success of scip's answer
    error_px: Optional[float]  # its error; None for an occluded target (no answer is right)
    candidates: list  # [(p, error px or None)] per candidate, in row order
    kind: str  # the target's kind ("flat", "extra", "occluded", ...)
    occluded: bool


def scip_choices(model: TrustModel, rows: list[EvidenceRow], success_px: float) -> list[ScipChoice]:
    """Per target, in sorted (group, target) order: :class:`ScipChoice`."""
    out = []
    for (_, _), rs in sorted(targets_of(rows).items()):
        p = model.probability([Evidence.from_dict(r.evidence) for r in rs], success_px)
        i = int(np.argmax(p))
        errs = [None if r.occluded else r.error_px for r in rs]
        out.append(ScipChoice(rs[0].family, float(p[i]), errs[i], list(zip(p.tolist(), errs)), rs[0].kind,
                              rs[0].occluded))
    return out


def families_of(rows: list[EvidenceRow]) -> list[str]:
    return sorted({r.family for r in rows})


def _choose_go(pairs: list, success_px: float) -> float:
    """Smallest threshold on the grid whose GO answers (p >= t) are right at least GO_PRECISION of the time."""
    for t in GO_GRID:
        go = [(p, e) for p, e in pairs if p >= t]
        if go and sum(e is not None and e <= success_px for _, e in go) / len(go) >= GO_PRECISION:
            return t
    return GO_GRID[-1]


def fit_trust_model(rows: list[EvidenceRow], radii=RADII_PX, provenance: Optional[dict] = None) -> TrustModel:
    """The trust model fitted on all ``rows``, GO thresholds from leave-one-family-out answers (all families
    pooled; with one family, from the in-sample answers)."""
    rows = fit_rows(rows)
    if not rows:
        raise ValueError("no evidence row with a true error to fit on")
    err = _errors(rows)
    for r in radii:  # fit_logistic makes a constant model of one class: GO always (or never) whatever the evidence
        if (err <= r).all() or not (err <= r).any():
            raise ValueError(f"every candidate is a {'success' if (err <= r).all() else 'failure'} within {r:g} px "
                             f"({len(rows)} rows): a trust model needs both")
    model = fit_raw_model(rows, radii)
    fams = families_of(rows)
    oof = defaultdict(list)
    for fam in fams:
        train = [r for r in rows if r.family != fam] if len(fams) > 1 else rows
        test = [r for r in rows if r.family == fam]
        m = fit_raw_model(train, radii)
        for r in radii:
            oof[r] += [(c.p, c.error_px) for c in scip_choices(m, test, r)]
    for fit in model.fits:
        fit.go_min_p = _choose_go(oof[fit.success_px], fit.success_px)
    n_targets = len(targets_of(rows))
    extra = {"n_occluded_targets": len({(r.group, r.target) for r in rows if r.occluded})} if any(r.occluded for r in rows) else {}
    model.provenance = dict(provenance or {}, training_families=fams, n_rows=len(rows), n_targets=n_targets, **extra,
                            per_family={f: sum(1 for k, v in targets_of(rows).items() if v[0].family == f) for f in fams},
                            C=C_REG, go_precision=GO_PRECISION)
    return model


# ----------------------------------------------------------------------------- evaluation
def _brier(p, y):
    p, y = np.asarray(p, float), np.asarray(y, float)
    return float(np.mean((p - y) ** 2)) if len(p) else math.nan


def _logloss(p, y):
    p = np.clip(np.asarray(p, float), 1e-6, 1 - 1e-6)
    y = np.asarray(y, float)
    return float(-np.mean(y * np.log(p) + (1 - y) * np.log(1 - p))) if len(p) else math.nan


BINS = (0.0, 0.2, 0.5, 0.8, 0.9, 0.95, 1.0001)


def reliability(p, y) -> list[dict]:
    """Per bin of predicted p: n, mean p, observed success rate."""
    p, y = np.asarray(p, float), np.asarray(y, float)
    out = []
    for lo, hi in zip(BINS[:-1], BINS[1:]):
        m = (p >= lo) & (p < hi)
        out.append({"bin": f"[{lo:.2f}, {min(hi, 1):.2f})", "n": int(m.sum()),
                    "mean_p": float(p[m].mean()) if m.any() else None,
                    "observed": float(y[m].mean()) if m.any() else None})
    return out


def _method_rates(rows: list[EvidenceRow], success_px: float) -> dict:
    """(method/navcam) -> success rate over the targets of ``rows`` (no answer = miss)."""
    tg = targets_of(rows)
    hits = defaultdict(int)
    for rs in tg.values():
        for r in rs:
            for s in r.sources:
                if r.is_right(success_px):
                    hits[s] += 1
    names = {s for r in rows for s in r.sources}
    return {s: hits[s] / len(tg) for s in sorted(names)}


def choice_summary(choices: list, success_px: float, go_min: float) -> dict:
    p = [c.p for c in choices]
    y = [c.error_px is not None and c.error_px <= success_px for c in choices]
    go = [pi >= go_min for pi in p]
    errs = np.array([c.error_px for c in choices], float)
    n_go = sum(go)
    return {
        "n": len(choices), "within": float(np.mean(y)) if y else None,
        "median_px": float(np.median(errs)) if len(errs) else None,
        "brier": _brier(p, y), "log_loss": _logloss(p, y),
        "go": n_go, "go_rate": n_go / len(choices) if choices else None,
        "false_go": sum(g and not yy for g, yy in zip(go, y)), "missed_go": sum((not g) and yy for g, yy in zip(go, y)),
        "go_precision": (sum(g and yy for g, yy in zip(go, y)) / n_go) if n_go else None,
        "miss_recall": (sum((not g) and not yy for g, yy in zip(go, y)) / sum(not yy for yy in y)) if not all(y) else None,
        "reliability": reliability(p, y),
    }


def _alt_candidate_metrics(train: list, test: list, success_px: float) -> dict:
    """Candidate-level Brier / log loss on ``test`` of the logistic model and of two alternatives fitted on
    ``train``: gradient boosting (scikit-learn's HistGradientBoostingClassifier, NaN-aware) and the logistic
    model followed by isotonic calibration (fitted on the training rows' out-of-fold... here in-sample)."""
    from sklearn.ensemble import HistGradientBoostingClassifier
    from sklearn.isotonic import IsotonicRegression

    m = fit_raw_model(train, (success_px,))
    ev_tr = [Evidence.from_dict(r.evidence) for r in train]
    ev_te = [Evidence.from_dict(r.evidence) for r in test]
    y_tr = np.array([r.is_right(success_px) for r in train])
    y_te = np.array([r.is_right(success_px) for r in test])
    p_lr = m.probability(ev_te, success_px)
    out = {"logistic": {"brier": _brier(p_lr, y_te), "log_loss": _logloss(p_lr, y_te)}}
    X_tr = feature_matrix(ev_tr, m.features)
    X_te = feature_matrix(ev_te, m.features)
    if y_tr.any() and not y_tr.all():
        gb = HistGradientBoostingClassifier(max_iter=200, learning_rate=0.05, max_leaf_nodes=15, random_state=0)
        gb.fit(X_tr, y_tr)
        p_gb = gb.predict_proba(X_te)[:, 1]
        out["gradient_boosting"] = {"brier": _brier(p_gb, y_te), "log_loss": _logloss(p_gb, y_te)}
        iso = IsotonicRegression(out_of_bounds="clip", y_min=0.0, y_max=1.0)
        iso.fit(m.probability(ev_tr, success_px), y_tr)
        p_iso = iso.predict(p_lr)
        out["logistic_isotonic"] = {"brier": _brier(p_iso, y_te), "log_loss": _logloss(p_iso, y_te)}
    out["n_candidates"] = int(len(test))
    return out


def evaluate(rows: list[EvidenceRow], success_px: float = 4.0, model: Optional[TrustModel] = None) -> dict:
    """Leave-one-family-out and fit-family (in-sample, ``model`` or one fitted on all rows) figures of ``scip``
    at ``success_px``: per family held out, its targets answered by a model fitted on the others."""
    rows = fit_rows(rows)
    fams = families_of(rows)
    full = model or fit_trust_model(rows)
    go_full = full.go_threshold(success_px)
    report = {"success_px": success_px, "families": fams, "go_min_p": go_full, "held_out": {}, "fit": {}}
    pooled = []
    for fam in fams:
        train = [r for r in rows if r.family != fam]
        test = [r for r in rows if r.family == fam]
        if not train:
            continue
        m = fit_raw_model(train, RADII_PX)
        ch_all = scip_choices(m, test, success_px)
        pooled += ch_all
        ch = [c for c in ch_all if not c.occluded]
        test = [r for r in test if not r.occluded]
        if not ch:  # a family of occluded targets only
            continue
        rates_test = _method_rates(test, success_px)
        rates_train = _method_rates(train, success_px)
        best_train = max(rates_train, key=rates_train.get)
        best_test = max(rates_test, key=rates_test.get)
        s = choice_summary(ch, success_px, go_full)
        s.update({"best_method_on_train": best_train, "its_within": rates_test.get(best_train, 0.0),
                  "best_method_here": best_test, "best_within_here": rates_test[best_test],
                  "any_candidate_within": float(np.mean([any(e is not None and e <= success_px for _, e in c.candidates) for c in ch])),
                  "candidate_models": _alt_candidate_metrics(train, test, success_px),
                  "occluded": occluded_summary([c for c in ch_all if c.occluded], go_full)})
        report["held_out"][fam] = s
    seen = [c for c in pooled if not c.occluded]
    report["held_out_pooled"] = choice_summary(seen, success_px, go_full)
    # the scenarios' own marked targets (flat, point, edge, sand, contrast) apart from the random extra ones
    report["held_out_pooled_marked"] = choice_summary([c for c in seen if c.kind not in ("extra", "occluded")], success_px, go_full)
    report["held_out_occluded"] = occluded_summary([c for c in pooled if c.occluded], go_full)
    ch = scip_choices(full, rows, success_px)  # in-sample: every target once, split by family below
    for fam in fams:
        seen_f = [c for c in ch if c.family == fam and not c.occluded]
        if seen_f:
            report["fit"][fam] = choice_summary(seen_f, success_px, go_full)
    report["fit_pooled"] = choice_summary([c for c in ch if not c.occluded], success_px, go_full)
    report["fit_occluded"] = occluded_summary([c for c in ch if c.occluded], go_full)
    return report


def occluded_summary(choices: list, go_min: float) -> dict:
    """What ``scip`` answered for occluded targets (every answer wrong): n, GO (all false), mean and max p."""
    p = [c.p for c in choices]
    return {"n": len(choices), "go": sum(pi >= go_min for pi in p), "mean_p": float(np.mean(p)) if p else None,
            "max_p": max(p) if p else None, "brier": _brier(p, [0.0] * len(p))}
