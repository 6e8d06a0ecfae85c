"""How far to trust a designation: P(its 3-D point is within a tolerance of ideal point stereo) and GO/NO-GO
(issue #14 item 5; docs/stereo-and-tracking.md, "Point stereo: how far to trust a designation").

The designation's own ``range_sigma_m`` assumes a quarter-pixel disparity error; on the simulated population
1 in 10 designations was off by more than twice it, a few by metres with a match score of 0.78-0.96 (a wrong
match along the epipolar line). The trust model is a logistic regression per tolerance on the match's own
evidence (:class:`DesignationEvidence`), of the same form as ``scip``'s (:class:`~scipctl.core.handoff.
trust_model.TrustModel`, evaluated in numpy): its radii are in **percent of the range** (0.5, 1, 2 %), not
pixels. The tolerance an operator needs is ``DEFAULT_TOLERANCE_PCT`` (1 % of the range: 10 cm at 10 m).

Fitted by ``docs/scripts/fit_designation_trust.py --with-window-gap`` on ``tests/data/designation/`` (leave one family
out for the GO threshold); packaged as ``scipctl/data/designation_model.json``. Its features are
:data:`FEATURES_WITH_WINDOW_GAP`: the match's own figures and the window range gap (point stereo's range against
the median dense-stereo range over its window), which sees a window that straddles a depth edge.
"""

from __future__ import annotations

import math
from collections import defaultdict
from dataclasses import dataclass
from typing import Optional

import numpy as np

from ..core.handoff.trust_model import LogisticFit, TrustModel, evidence_from_dict, evidence_to_dict, feature_matrix
# fitted as scip's trust model is: the same regularisation, clipping, standardisation and rounding
from .trust_fit import C_REG, CLIP_Z, fit_logistic, round_sig, standardise

RADII_PCT = (0.5, 1.0, 2.0)
DEFAULT_TOLERANCE_PCT = 1.0
GO_PRECISION = 0.98  # the GO threshold: smallest p on GO_GRID whose held-out GO designations are right this often
GO_GRID = tuple(round(0.90 + 0.01 * i, 2) for i in range(10))
# the designation's warnings that are evidence (pipeline/designate.py writes them, DesignationEvidence reads them)
SATURATED_WARNING = "saturated pixels in the window"
LOW_TEXTURE_WARNING = "low texture"
#: the cameras the packaged designation trust model was fitted on; another camera's p_ok is outside its data
FITTED_CAMERAS = ("pancam", "navcam")
OTHER_CAMERA_WARNING = ("the designation trust model was fitted on pancam and navcam designations: p_ok for a {camera} "
                        "designation is outside its data")
VETO_WARNING_PREFIX = "NO-GO whatever p_ok: "  # the warning that says why assess() vetoed a GO

# feature name -> (DesignationEvidence field, transform of core.handoff.trust_model.transform)
FEATURES = {
    "score": ("match_score", "x"),
    "log_ratio": ("match_ratio", "log"),
    "saturated": ("saturated", "x"),
    "low_texture": ("low_texture", "x"),
    "navcam": ("navcam", "x"),
    "log_epipolar_px": ("epipolar_abs_px", "log1p"),
    "log_ray_miss_mm": ("ray_miss_mm", "log1p"),
}
#: the same and the window range gap (core/window_ranges.py): the packaged model's since session 45 (fit script
#: ``--with-window-gap``; docs/stereo-and-tracking.md, "The window range gap")
FEATURES_WITH_WINDOW_GAP = dict(FEATURES, log_window_gap=("window_gap_pct", "log1p"))


@dataclass(frozen=True)
class DesignationEvidence:
    """What the designation's point stereo says about its own match (NaN where it did not say)."""

    match_score: float
    match_ratio: float
    saturated: float  # 1.0 when the window holds saturated pixels
    low_texture: float
    navcam: float  # 1.0 for a navcam designation, 0.0 for pancam (other cameras: outside the fitted data)
    epipolar_abs_px: float
    ray_miss_mm: float
    # |point range - median dense range over the window| in % of the range (core/window_ranges.py): a window that
    # straddles a depth edge; NaN when not measured (rows and records made before it, too few dense pixels)
    window_gap_pct: float = math.nan

    @classmethod
    def of(cls, rec) -> "DesignationEvidence":
        """From a :class:`~scipctl.pipeline.designate.Designation`."""
        def f(x, scale=1.0):
            return math.nan if x is None else abs(float(x)) * scale
        w = tuple(rec.warnings or ())
        return cls(f(rec.match_score), f(rec.match_ratio), float(SATURATED_WARNING in w),
                   float(LOW_TEXTURE_WARNING in w), float(rec.camera == "navcam"), f(rec.epipolar_offset_px),
                   f(rec.ray_miss_m, 1000.0), f(rec.window_range_gap_pct))

    def to_dict(self) -> dict:
        return evidence_to_dict(self)

    @classmethod
    def from_dict(cls, d: dict) -> "DesignationEvidence":
        return evidence_from_dict(cls, d)


def uses_window_gap(model: TrustModel) -> bool:
    """True when ``model`` reads the window range gap (so a caller must measure it: one more dense stereo)."""
    return "window_gap_pct" in {field for field, _ in model.features.values()}


@dataclass(frozen=True)
class DesignationTrust:
    """``p_ok``: P(the designated point is within ``tolerance_pct`` % of the range of ideal point stereo);
    ``go``: ``p_ok >= go_min_p``; both None/False when there is no model or no stereo point."""

    p_ok: Optional[float]
    go: bool
    tolerance_pct: float
    go_min_p: Optional[float]
    veto: Optional[str] = None  # why the designation is NO-GO whatever p_ok says (None: p_ok decides)


def assess(model: Optional[TrustModel], rec, tolerance_pct: float = DEFAULT_TOLERANCE_PCT) -> DesignationTrust:
    """The trust of designation ``rec`` under ``model`` (None: no model -> p_ok None, NO-GO).

    A window with no texture (the ``low texture`` warning: its standard deviation under 1 % of full scale) is NO-GO
    whatever ``p_ok`` says (``veto``): its NCC peak is the noise of a flat patch and says nothing about where the
    match is. The model cannot learn that from one such row in its table; on the blind populations `pop6`-`pop9`
    (1501 designations) the 6 with the warning were all more than 1 % of the range off, 4 of them by more than
    10 %, and one (880 %, a saturated far-navcam window) had p_ok 0.96 (docs/stereo-and-tracking.md, "How far to
    trust a designation").
    """
    if model is None or not rec.has_position:
        return DesignationTrust(None, False, tolerance_pct, None)
    ev = DesignationEvidence.of(rec)
    p = model.probability([ev], tolerance_pct)
    go_min = model.go_threshold(tolerance_pct)
    if p is None or go_min is None:
        return DesignationTrust(None, False, tolerance_pct, None)
    p_ok = float(round(float(p[0]), 4))
    if ev.low_texture == 1.0:
        return DesignationTrust(p_ok, False, tolerance_pct, float(go_min), veto="the window has no texture to match")
    return DesignationTrust(p_ok, bool(p_ok >= go_min), tolerance_pct, float(go_min))


# ----------------------------------------------------------------------------- fitting (scikit-learn)
@dataclass(frozen=True)
class DesignationRow:
    """One designation of the fitting population: its family, evidence and error (percent of the range) from
    ideal point stereo (the two marks triangulated with the downlinked models)."""

    family: str
    evidence: DesignationEvidence
    error_pct: float


def _fit(rows: list[DesignationRow], features: Optional[dict] = None) -> TrustModel:
    """One logistic regression per tolerance on ``features`` (name -> (evidence field, transform); default
    :data:`FEATURES`)."""
    features = dict(FEATURES if features is None else features)
    X = feature_matrix([r.evidence for r in rows], features)
    fill, mean, scale = standardise(X)
    Z = np.clip((np.where(np.isfinite(X), X, fill) - mean) / scale, -CLIP_Z, CLIP_Z)
    err = np.array([r.error_pct for r in rows], float)
    fits = []
    for tol in RADII_PCT:
        coef, b = fit_logistic(Z, err <= tol)
        fits.append(LogisticFit(float(tol), [round_sig(c) for c in coef], round_sig(b), 1.0))
    return TrustModel(features, [round_sig(v) for v in fill], [round_sig(v) for v in mean],
                      [round_sig(v) for v in scale], fits, clip_z=CLIP_Z)


def held_out(rows: list[DesignationRow], features: Optional[dict] = None) -> dict:
    """Leave one family out: per tolerance, ``[(family, p, error_pct)]`` with ``p`` from a model fitted on the
    other families (with ``features``, as :func:`_fit`)."""
    fams = sorted({r.family for r in rows})
    out = defaultdict(list)
    for fam in fams:
        train = [r for r in rows if r.family != fam] if len(fams) > 1 else rows
        test = [r for r in rows if r.family == fam]
        m = _fit(train, features)
        for tol in RADII_PCT:
            p = m.probability([r.evidence for r in test], tol)
            out[tol] += [(fam, float(pi), r.error_pct) for pi, r in zip(p, test)]
    return out


def fit_designation_model(rows: list[DesignationRow], provenance: Optional[dict] = None,
                          features: Optional[dict] = None) -> TrustModel:
    """The model fitted on all ``rows`` with ``features`` (default :data:`FEATURES`); each tolerance's GO threshold
    from leave-one-family-out answers."""
    if not rows:
        raise ValueError("no designation row to fit on")
    model = _fit(rows, features)
    oof = held_out(rows, features)
    for fit in model.fits:
        pairs = oof[fit.success_px]
        fit.go_min_p = GO_GRID[-1]
        for t in GO_GRID:
            go = [e for _, p, e in pairs if p >= t]
            if go and sum(e <= fit.success_px for e in go) / len(go) >= GO_PRECISION:
                fit.go_min_p = t
                break
    fams = sorted({r.family for r in rows})
    model.provenance = dict(provenance or {}, radius_unit="percent of range", training_families=fams,
                            n_rows=len(rows), per_family={f: sum(r.family == f for r in rows) for f in fams},
                            C=C_REG, go_precision=GO_PRECISION)
    return model


def report(rows: list[DesignationRow], model: TrustModel) -> dict:
    """Held-out figures per family and pooled at each tolerance: n, share within, Brier (and of the constant
    base rate), GO count, GO precision, miss recall (share of misses NO-GO), with the packaged GO thresholds."""
    oof = held_out(rows, model.features)
    out = {}
    for fit in model.fits:
        tol, t = fit.success_px, fit.go_min_p
        pairs = oof[tol]
        res = {}
        for fam in sorted({f for f, _, _ in pairs}) + ["pooled"]:
            sel = [(p, e) for f, p, e in pairs if fam == "pooled" or f == fam]
            p = np.array([x for x, _ in sel]); y = np.array([e <= tol for _, e in sel])
            go = p >= t
            res[fam] = {"n": int(len(sel)), "within": float(y.mean()), "brier": float(np.mean((p - y) ** 2)),
                        "brier_base_rate": float(np.mean((y.mean() - y) ** 2)), "go": int(go.sum()),
                        "go_precision": float(y[go].mean()) if go.any() else None,
                        "miss_recall": float((~go[~y]).mean()) if (~y).any() else None}
        out[f"{tol:g}%"] = {"go_min_p": t, "families": res}
    return out
