"""One logistic regression over the fields of an evidence dataclass, with a single success radius: the shared
arithmetic and file form of the chain's step model (:mod:`scipctl.core.step_trust`) and the closure's
(:mod:`scipctl.core.closure_trust`) (pure numerics).

    z = clip((f(evidence) - mean) / scale, +-clip_z)   (f: the named transforms; NaN -> fill)
    p = 1 / (1 + exp(-(coef . z + intercept)))
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .handoff.trust_model import TRANSFORMS, logistic_probability


class SingleLogistic:
    """Mixin for a dataclass with the fields ``features`` (name -> (evidence attribute, transform)), ``fill``,
    ``mean``, ``scale``, ``coef`` (one per feature), ``intercept``, ``go_min_p``, the radius field named
    :attr:`RADIUS`, ``provenance`` and ``clip_z``. :attr:`WHAT` names the model in errors read from a file."""

    RADIUS = "success_px"
    WHAT = "model"

    def _check(self) -> None:
        name = type(self).__name__
        F = len(self.features)
        if not (len(self.fill) == len(self.mean) == len(self.scale) == len(self.coef) == F):
            raise ValueError(f"{name}: fill/mean/scale/coef must have {F} entries (one per feature)")
        if not (0.0 < self.go_min_p <= 1.0):
            raise ValueError(f"{name}.go_min_p = {self.go_min_p!r}: must be in (0, 1]")
        if not (getattr(self, self.RADIUS) > 0 and self.clip_z > 0):
            raise ValueError(f"{name}: {self.RADIUS} and clip_z must be > 0")
        for _, kind in self.features.values():
            if kind not in TRANSFORMS:
                raise ValueError(f"{name}: unknown feature transform {kind!r}")

    def __post_init__(self):
        self._check()

    def probability(self, evidence: list) -> np.ndarray:
        """P(within the success radius) ``(N,)`` for each evidence."""
        return logistic_probability(evidence, self.features, self.fill, self.mean, self.scale, self.coef,
                                    self.intercept, self.clip_z)

    def to_dict(self) -> dict:
        return {"kind": "logistic", "features": [[k, v[0], v[1]] for k, v in self.features.items()],
                "fill": list(self.fill), "mean": list(self.mean), "scale": list(self.scale), "coef": list(self.coef),
                "intercept": self.intercept, "go_min_p": self.go_min_p, self.RADIUS: getattr(self, self.RADIUS),
                "clip_z": self.clip_z, "provenance": dict(self.provenance)}

    @classmethod
    def from_dict(cls, d: dict):
        """From :meth:`to_dict`'s output; ``ValueError`` naming what is wrong."""
        try:
            if d.get("kind", "logistic") != "logistic":
                raise ValueError(f"{cls.WHAT}: kind {d.get('kind')!r}, only 'logistic' is evaluated")
            return cls(features={str(f[0]): (str(f[1]), str(f[2])) for f in d["features"]},
                       fill=[float(x) for x in d["fill"]], mean=[float(x) for x in d["mean"]],
                       scale=[float(x) for x in d["scale"]], coef=[float(x) for x in d["coef"]],
                       intercept=float(d["intercept"]), go_min_p=float(d["go_min_p"]),
                       **{cls.RADIUS: float(d[cls.RADIUS])}, provenance=dict(d.get("provenance", {})),
                       clip_z=float(d.get("clip_z", 5.0)))
        except (KeyError, TypeError, IndexError, AttributeError) as e:
            raise ValueError(f"{cls.WHAT}: missing or malformed field ({e})") from None


@dataclass
class PixelLogistic(SingleLogistic):
    """A :class:`SingleLogistic` with its fields declared, for models whose radius is in image pixels
    (``success_px``): the closure's (:mod:`scipctl.core.closure_trust`) and the prediction's calibration
    (:mod:`scipctl.core.prediction_calibration`). Subclasses set :attr:`WHAT`."""

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
