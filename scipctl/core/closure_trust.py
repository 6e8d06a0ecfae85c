"""The trust model of the chain's closure answer: P(the closure pixel is within ``success_px`` hazcam pixels of the
target | the closure's own evidence) (pure numerics).

When the chain's final answer is its closure (``ChainParams.answer = "closure"``,
``scipctl/pipeline/chain_closure.py``), the answer no longer comes from ``scip``'s handoff of the navcam pixel,
so ``scip``'s probability does not describe it. The closure is described by a :class:`ClosureEvidence` (its
feature step's diagnostics, the reference it started from and that reference's own step probability, and how far
the independent handoff path landed from it). The model is one logistic regression on standardised features,
evaluated as the step model is (:func:`~scipctl.core.handoff.trust_model.logistic_probability`):

    z = clip((f(evidence) - mean) / scale, +-clip_z)   (f: the named transforms of CLOSURE_FEATURES; NaN -> fill)
    p = 1 / (1 + exp(-(coef . z + intercept)))

The packaged model is ``scipctl/data/closure_trust_model.json`` (read by ``scipctl.io.closure_trust_model``,
refitted by ``docs/scripts/fit_closure_trust.py``; docs/stereo-and-tracking.md, "Closure as the answer").
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .handoff.trust_model import TRANSFORMS, evidence_from_dict, evidence_to_dict, logistic_probability


@dataclass
class ClosureEvidence:
    """What a closure knows about itself (NaN: unknown). ``from_pancam``: 1 when it started from the 4.5 m pancam
    track, 0 from the navcam handoff; ``ref_p_success``: the reference step's own probability (step model);
    ``handoff_px``: distance (hazcam px) from the closure pixel to the handoff path's answer (``closure_px``)."""

    ncc_peak: float = math.nan
    local_inliers: float = math.nan
    confirmed: float = math.nan
    shift_px: float = math.nan
    scale: float = math.nan
    from_pancam: float = 0.0
    ref_p_success: float = math.nan
    handoff_px: float = math.nan

    def to_dict(self) -> dict:
        return evidence_to_dict(self)

    @classmethod
    def from_dict(cls, d: dict) -> "ClosureEvidence":
        return evidence_from_dict(cls, d)


# feature name -> (ClosureEvidence attribute, transform of core.handoff.trust_model.transform)
CLOSURE_FEATURES: dict[str, tuple[str, str]] = {
    "ncc_peak": ("ncc_peak", "x"),
    "log_local_inliers": ("local_inliers", "log1p"),
    "log_confirmed": ("confirmed", "log1p"),
    "log_shift": ("shift_px", "log1p"),
    "log_scale": ("scale", "log"),
    "from_pancam": ("from_pancam", "x"),
    "ref_p_success": ("ref_p_success", "x"),
    "log_handoff_px": ("handoff_px", "log1p"),
}


@dataclass
class ClosureTrustModel:
    """A fitted closure model (see the module docstring). ``features``: name -> [ClosureEvidence attribute,
    transform]; ``fill``/``mean``/``scale``/``coef``: one value per feature; ``go_min_p``: the GO threshold;
    ``success_px``: the radius (final hazcam image pixels) the probability is for."""

    features: dict
    fill: list
    mean: list
    scale: list
    coef: list
    intercept: float
    go_min_p: float
    success_px: float
    provenance: dict = field(default_factory=dict)
    clip_z: float = 5.0

    def __post_init__(self):
        F = len(self.features)
        if not (len(self.fill) == len(self.mean) == len(self.scale) == len(self.coef) == F):
            raise ValueError(f"ClosureTrustModel: fill/mean/scale/coef must have {F} entries (one per feature)")
        if not (0.0 < self.go_min_p <= 1.0):
            raise ValueError(f"ClosureTrustModel.go_min_p = {self.go_min_p!r}: must be in (0, 1]")
        if not (self.success_px > 0 and self.clip_z > 0):
            raise ValueError("ClosureTrustModel: success_px and clip_z must be > 0")
        for _, kind in self.features.values():
            if kind not in TRANSFORMS:
                raise ValueError(f"ClosureTrustModel: unknown feature transform {kind!r}")

    def probability(self, evidence: list) -> np.ndarray:
        """P(within ``success_px``) ``(N,)`` for each :class:`ClosureEvidence`."""
        return logistic_probability(evidence, self.features, self.fill, self.mean, self.scale, self.coef,
                                    self.intercept, self.clip_z)

    def to_dict(self) -> dict:
        return {"kind": "logistic", "features": [[k, v[0], v[1]] for k, v in self.features.items()],
                "fill": list(self.fill), "mean": list(self.mean), "scale": list(self.scale), "coef": list(self.coef),
                "intercept": self.intercept, "go_min_p": self.go_min_p, "success_px": self.success_px,
                "clip_z": self.clip_z, "provenance": dict(self.provenance)}

    @classmethod
    def from_dict(cls, d: dict) -> "ClosureTrustModel":
        """From :meth:`to_dict`'s output; ``ValueError`` naming what is wrong."""
        try:
            if d.get("kind", "logistic") != "logistic":
                raise ValueError(f"closure trust model: kind {d.get('kind')!r}, only 'logistic' is evaluated")
            return cls(features={str(f[0]): (str(f[1]), str(f[2])) for f in d["features"]},
                       fill=[float(x) for x in d["fill"]], mean=[float(x) for x in d["mean"]],
                       scale=[float(x) for x in d["scale"]], coef=[float(x) for x in d["coef"]],
                       intercept=float(d["intercept"]), go_min_p=float(d["go_min_p"]),
                       success_px=float(d["success_px"]), provenance=dict(d.get("provenance", {})),
                       clip_z=float(d.get("clip_z", 5.0)))
        except (KeyError, TypeError, IndexError, AttributeError) as e:
            raise ValueError(f"closure trust model: missing or malformed field ({e})") from None
