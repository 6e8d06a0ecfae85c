"""The trust model of ``scip``: P(a candidate answer is within ``success_px`` | its evidence) (pure numerics).

A fitted model is a :class:`TrustModel` (JSON <-> dataclass: :meth:`TrustModel.to_dict` /
:meth:`TrustModel.from_dict`; the packaged one is ``scipctl/data/trust_model.json``, read by
``scipctl.io.trust_model``, refitted by ``scipctl fit-trust``). Evaluating it needs numpy only:

    z = clip((f(evidence) - mean) / scale, +-clip_z)   (f: the named transforms of FEATURES; NaN -> the training mean)
    p = 1 / (1 + exp(-(coef . z + intercept)))

one logistic model per success radius it was fitted for (``success_px`` 1, 2, 4, 8 px by default). For a
radius between two fitted ones the logit is interpolated linearly in log(radius) (the probabilities of the two
are first made non-decreasing in the radius); outside the fitted range there is no probability (None): a
probability fitted for 4 px is never reused for 1 px.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields
from typing import Optional

import numpy as np

# feature name -> (Evidence field, transform): the default feature set of a fit. Evidence kept out of it (measured
# leave-one-family-out, docs/handoff.md "Trust: scip"): the NCC peak's ratio and sharpness (sharpness is per px^2,
# so it moves with the image scale; neither helped held out), the registration's fitness/RMS (one value per
# downlink: too few downlinks to fit it on) and the registration check's evidence of issue #14 item 2 (no gain
# held out on the 20-downlink table). OPTIONAL_FEATURES are there to be added when a refit has more data.
FEATURES: dict[str, tuple[str, str]] = {}
OPTIONAL_FEATURES: dict[str, tuple[str, str]] = {}
for _v in ("near", "far"):
    FEATURES.update({
        f"app_{_v}_score_at": (f"app_{_v}_score_at", "x"),
        f"app_{_v}_peak": (f"app_{_v}_peak", "x"),
        f"app_{_v}_log_offset": (f"app_{_v}_offset_px", "log1p"),
        f"app_{_v}_known": (f"app_{_v}_score_at", "known"),
        f"fb_{_v}_log_error": (f"fb_{_v}_error_px", "log1p"),
        f"geo_{_v}_log_sigma": (f"geo_{_v}_sigma", "log1p"),
        f"geo_{_v}_log_nav_res": (f"geo_{_v}_nav_res_px", "log1p"),
    })
    OPTIONAL_FEATURES.update({
        f"app_{_v}_log_ratio": (f"app_{_v}_ratio", "log"),
        f"app_{_v}_log_sharpness": (f"app_{_v}_sharpness", "log1p"),
        f"reg_{_v}_fitness": (f"reg_{_v}_fitness", "x"),
        f"reg_{_v}_rmse_cm": (f"reg_{_v}_rmse_m", "x100"),
        f"reg_{_v}_log_global_agree": (f"reg_{_v}_global_agree_px", "log1p"),
        f"reg_{_v}_log_seed_spread": (f"reg_{_v}_seed_spread_px", "log1p"),
        f"reg_{_v}_target_residual_cm": (f"reg_{_v}_target_residual_m", "x100"),
    })
FEATURES.update({
    "geo_haz_point": ("geo_haz_point", "x"),
    "support_groups": ("support_groups", "x"),
    "support_other_families": ("support_other_families", "x"),
    "log_other_navcam": ("other_navcam_px", "log1p"),
    "from_far": ("navcam", "is_far"),
})
# session 24: the occlusion evidence (a surface in front of the predicted target over the 4 px disk), last so that
# the features before it keep their order
FEATURES.update({f"occ_{_v}_log_front": (f"occ_{_v}_front_sigma", "log1p") for _v in ("near", "far")})
del _v

TRANSFORMS = ("x", "log1p", "log", "x100", "known", "is_far")


def transform(value, kind: str) -> float:
    """One feature value from an evidence value (NaN stays NaN except for ``known``/``is_far``)."""
    if kind == "is_far":
        return 1.0 if value == "far" else 0.0
    v = float(value)
    if kind == "known":
        return 1.0 if math.isfinite(v) else 0.0
    if not math.isfinite(v):
        return math.nan
    if kind == "x":
        return v
    if kind == "x100":
        return 100.0 * v
    if kind == "log1p":
        return math.log1p(max(v, 0.0))
    if kind == "log":
        return math.log(max(v, 1e-3))
    raise ValueError(f"unknown feature transform {kind!r} (known: {', '.join(TRANSFORMS)})")


def evidence_to_dict(ev) -> dict:
    """A dataclass of evidence as JSON-ready values: its fields in order, NaN (not measured) as None."""
    return {f.name: (None if isinstance(v, float) and not math.isfinite(v) else v)
            for f in fields(ev) for v in (getattr(ev, f.name),)}


def evidence_from_dict(cls, d: dict):
    """``cls`` (an evidence dataclass) from :func:`evidence_to_dict`'s output: unknown keys ignored, missing
    fields at their defaults, null numbers NaN; fields annotated ``str`` kept as text."""
    kw = {}
    for f in fields(cls):
        if f.name in d:
            v = d[f.name]
            kw[f.name] = (v if v is None else str(v)) if f.type in ("str", str) else (math.nan if v is None else float(v))
    return cls(**kw)


class EvidenceRecord:
    """Mixin for an evidence dataclass: its JSON form (:func:`evidence_to_dict` / :func:`evidence_from_dict`)."""

    def to_dict(self) -> dict:
        return evidence_to_dict(self)

    @classmethod
    def from_dict(cls, d: dict):
        return evidence_from_dict(cls, d)


def feature_matrix(evidence: list, spec: dict) -> np.ndarray:
    """(N, F) raw features of ``evidence`` (list of :class:`~scipctl.core.handoff.evidence.Evidence`) for ``spec``
    (feature name -> (Evidence field, transform)); NaN where unknown."""
    rows = [[transform(getattr(ev, fld), kind) for fld, kind in spec.values()] for ev in evidence]
    return np.asarray(rows, float).reshape(len(evidence), len(spec))


def logistic_probability(evidence: list, features: dict, fill, mean, scale, coef, intercept: float,
                         clip_z: float) -> np.ndarray:
    """``(N,)`` ``sigmoid(coef . clip((f(evidence) - mean) / scale, +-clip_z) + intercept)``, unknown raw features
    at ``fill``: one logistic model over any evidence dataclass (``features``: name -> (attribute, transform))."""
    if not evidence:
        return np.zeros(0)
    X = feature_matrix(evidence, features)
    X = np.where(np.isfinite(X), X, np.asarray(fill, float))
    Z = np.clip((X - np.asarray(mean, float)) / np.asarray(scale, float), -clip_z, clip_z)
    return 1.0 / (1.0 + np.exp(-(Z @ np.asarray(coef, float) + intercept)))


@dataclass
class LogisticFit:
    """One fitted success radius: ``p = sigmoid(coef . z + intercept)``, and the GO threshold chosen for it."""

    success_px: float
    coef: list  # (F,) per standardised feature
    intercept: float
    go_min_p: float

    def to_dict(self) -> dict:
        return {"success_px": self.success_px, "coef": list(self.coef), "intercept": self.intercept,
                "go_min_p": self.go_min_p}

    @classmethod
    def from_dict(cls, d: dict) -> "LogisticFit":
        return cls(float(d["success_px"]), [float(c) for c in d["coef"]], float(d["intercept"]), float(d["go_min_p"]))


@dataclass
class TrustModel:
    """A fitted trust model (see the module docstring). ``features``: name -> [Evidence field, transform];
    ``fill`` / ``mean`` / ``scale``: per feature (training means of the raw features, and the standardisation);
    ``fits``: one :class:`LogisticFit` per success radius, increasing; ``provenance``: how it was made."""

    features: dict
    fill: list
    mean: list
    scale: list
    fits: list
    provenance: dict = field(default_factory=dict)
    kind: str = "logistic"
    clip_z: float = 5.0  # standardised features are clipped to +-clip_z (no extrapolation far outside the data)

    def __post_init__(self):
        F = len(self.features)
        if not (len(self.fill) == len(self.mean) == len(self.scale) == F):
            raise ValueError(f"TrustModel: fill/mean/scale must have {F} entries (one per feature)")
        for fit in self.fits:
            if len(fit.coef) != F:
                raise ValueError(f"TrustModel: the {fit.success_px:g} px fit has {len(fit.coef)} coefficients, want {F}")
        if not self.clip_z > 0:
            raise ValueError(f"TrustModel.clip_z = {self.clip_z!r}: must be > 0")
        if self.kind != "logistic":
            raise ValueError(f"TrustModel.kind {self.kind!r}: only 'logistic' is evaluated")
        for _, kind in self.features.values():
            if kind not in TRANSFORMS:
                raise ValueError(f"TrustModel: unknown feature transform {kind!r}")
        self.fits = sorted(self.fits, key=lambda f: f.success_px)

    @property
    def success_radii_px(self) -> tuple:
        return tuple(f.success_px for f in self.fits)

    def standardised(self, evidence: list) -> np.ndarray:
        """(N, F) standardised features (unknown values at the training mean, i.e. 0)."""
        X = feature_matrix(evidence, self.features)
        X = np.where(np.isfinite(X), X, np.asarray(self.fill, float))
        Z = (X - np.asarray(self.mean, float)) / np.asarray(self.scale, float)
        return np.clip(Z, -self.clip_z, self.clip_z)

    def _logits(self, Z: np.ndarray) -> np.ndarray:
        """(N, K) logit of every fitted radius, made non-decreasing along the radii."""
        L = np.stack([Z @ np.asarray(f.coef, float) + f.intercept for f in self.fits], axis=1)
        return np.maximum.accumulate(L, axis=1)

    def probability(self, evidence: list, success_px: float) -> Optional[np.ndarray]:
        """P(within ``success_px``) ``(N,)`` for each evidence; None when ``success_px`` is outside the fitted
        radii (no extrapolation)."""
        radii = np.asarray(self.success_radii_px, float)
        if not len(radii) or not radii[0] - 1e-9 <= success_px <= radii[-1] + 1e-9:
            return None
        if not evidence:
            return np.zeros(0)
        L = self._logits(self.standardised(evidence))
        x = np.log(radii)
        t = math.log(success_px)
        logit = np.array([np.interp(t, x, row) for row in L]) if len(radii) > 1 else L[:, 0]
        return 1.0 / (1.0 + np.exp(-logit))

    def go_threshold(self, success_px: float) -> Optional[float]:
        """The GO threshold chosen at fit time for ``success_px`` (the larger of the two bracketing fits' when
        it lies between two; None outside the fitted radii)."""
        radii = self.success_radii_px
        if not radii or not radii[0] - 1e-9 <= success_px <= radii[-1] + 1e-9:
            return None
        lo = max((f for f in self.fits if f.success_px <= success_px + 1e-9), key=lambda f: f.success_px)
        hi = min((f for f in self.fits if f.success_px >= success_px - 1e-9), key=lambda f: f.success_px)
        return max(lo.go_min_p, hi.go_min_p)

    def to_dict(self) -> dict:
        # features as an ordered list: the coefficients follow their order (a JSON object's keys may be re-sorted)
        return {"kind": self.kind, "features": [[k, v[0], v[1]] for k, v in self.features.items()],
                "fill": list(self.fill), "mean": list(self.mean), "scale": list(self.scale),
                "fits": [f.to_dict() for f in self.fits], "provenance": dict(self.provenance), "clip_z": self.clip_z}

    @classmethod
    def from_dict(cls, d: dict) -> "TrustModel":
        """From :meth:`to_dict`'s output; ``ValueError`` naming what is wrong."""
        try:
            if not isinstance(d["features"], list):
                raise ValueError("trust model: features must be a list of [name, evidence field, transform]")
            return cls(features={str(f[0]): (str(f[1]), str(f[2])) for f in d["features"]},
                       fill=[float(x) for x in d["fill"]], mean=[float(x) for x in d["mean"]],
                       scale=[float(x) for x in d["scale"]], fits=[LogisticFit.from_dict(f) for f in d["fits"]],
                       provenance=dict(d.get("provenance", {})), kind=str(d.get("kind", "logistic")),
                       clip_z=float(d.get("clip_z", 5.0)))
        except (KeyError, TypeError, IndexError) as e:
            raise ValueError(f"trust model: missing or malformed field ({e})") from None
