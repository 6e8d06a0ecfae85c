"""The pre-uplink prediction's calibration: P(tomorrow's chain puts the final hazcam answer within ``success_px`` of
the target | what the prediction simulated today) (pure numerics).

The prediction (``scipctl/pipeline/predict``) simulates tomorrow's approach from today's downlink: a Monte Carlo of
the pose, pointing and range errors (is the target in every view, in the search region, visible; does the arm reach
it), then the chain tracked on views rendered from today's images. Its product, ``p_simulated``, is what the
simulation can see. It cannot see what breaks the real chain most often: a view rendered from today's image is
tracked in today's image texture, so the simulated tracking hardly ever fails, while the real chain's tracking
across the drive (a 10 m designation found again at 4.5 m, the navcam tracks, the closure) fails for reasons today's
images do not show (measured: docs/sequence.md, "Calibrated against the chain"). ``p_simulated`` was therefore far
from the chain's real success rate (1.0 for 108 of 196 held-out approaches, of which 65 % succeeded).

The calibration maps ``p_simulated`` to the probability of what actually happened, learnt from approaches whose
chain was run: one logistic regression on the standardised ``p_simulated`` (:class:`PredictionCalibration`; the
same arithmetic and file form as the chain's step and closure models, :mod:`scipctl.core.logistic_model`), one
model per predicted route (the planner's approach, ``plan``; the downlink's own stops, ``downlink``), because
``p_simulated`` means something different on each. The packaged models are
``scipctl/data/prediction_calibration_{plan,downlink}.json`` (read by ``scipctl.io.prediction_calibration``,
refitted by ``docs/scripts/fit_prediction_calibration.py``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from .handoff.trust_model import EvidenceRecord
from .logistic_model import PixelLogistic


@dataclass
class PredictionEvidence(EvidenceRecord):
    """What the prediction knows of an approach (NaN: unknown). ``p_simulated``: P(geometry ok in the Monte Carlo)
    x the fraction of the chain runs on rendered views that kept the target (``confidence_of``)."""

    p_simulated: float = math.nan


# feature name -> (PredictionEvidence attribute, transform of core.handoff.trust_model.transform)
PREDICTION_FEATURES: dict[str, tuple[str, str]] = {
    "p_simulated": ("p_simulated", "x"),
}


@dataclass
class PredictionCalibration(PixelLogistic):
    """A fitted calibration of the prediction (see the module docstring). ``features``: name ->
    [PredictionEvidence attribute, transform]; ``fill``/``mean``/``scale``/``coef``: one value per feature;
    ``success_px``: the final hazcam radius (image pixels) the probability is for. ``go_min_p`` is 1.0 and unused:
    the prediction has no GO of its own, the flight rules decide (``FlightRules.min_confidence``). Evaluation and
    file form: :class:`~scipctl.core.logistic_model.SingleLogistic`."""

    WHAT = "prediction calibration"

    def p_success(self, p_simulated: float) -> float:
        """The calibrated P(success) of one approach whose simulated probability is ``p_simulated`` (in [0, 1])."""
        p = float(p_simulated)
        if not (0.0 <= p <= 1.0):
            raise ValueError(f"p_simulated: expected a probability in [0, 1], got {p_simulated!r}")
        return float(self.probability([PredictionEvidence(p)])[0])
