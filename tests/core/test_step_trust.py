"""The chain's step trust model: evaluation (numpy) and its JSON form."""

import math

import numpy as np
import pytest

from scipctl.core.step_trust import STEP_FEATURES, StepEvidence, StepTrustModel


def _model(**kw):
    spec = {"ncc_peak": STEP_FEATURES["ncc_peak"], "status_failed": STEP_FEATURES["status_failed"],
            "pancam_track": STEP_FEATURES["pancam_track"]}
    args = dict(features=spec, fill=[0.7, 0.0, 0.0], mean=[0.7, 0.1, 0.3], scale=[0.1, 0.3, 0.5],
                coef=[2.0, -1.5, 0.5], intercept=1.0, go_min_p=0.9, success_mm=6.5)
    args.update(kw)
    return StepTrustModel(**args)


def test_probability_is_the_logistic_of_the_standardised_features():
    m = _model()
    ev = [StepEvidence(kind="pancam-track", ncc_peak=0.9), StepEvidence(kind="navcam-track", status_failed=1.0),
          StepEvidence(kind="navcam-track")]  # the last: NCC unknown -> the fill value
    p = m.probability(ev)
    z = np.array([[(0.9 - 0.7) / 0.1, (0 - 0.1) / 0.3, (1 - 0.3) / 0.5],
                  [0.0, (1 - 0.1) / 0.3, (0 - 0.3) / 0.5],
                  [0.0, (0 - 0.1) / 0.3, (0 - 0.3) / 0.5]])
    want = 1 / (1 + np.exp(-(z @ np.array([2.0, -1.5, 0.5]) + 1.0)))
    assert p == pytest.approx(want, rel=1e-12)
    # a feature far outside the training range is clipped at clip_z standard deviations
    far = m.probability([StepEvidence(kind="navcam-track", ncc_peak=100.0)])[0]
    assert far == pytest.approx(1 / (1 + math.exp(-(2.0 * 5.0 + 1.5 * 0.1 / 0.3 - 0.5 * 0.6 + 1.0))), rel=1e-12)


def test_model_round_trips_through_its_dict():
    m = _model(provenance={"tool": "scipctl"})
    back = StepTrustModel.from_dict(m.to_dict())
    assert back.to_dict() == m.to_dict()
    ev = [StepEvidence(kind="pancam-track", ncc_peak=0.5)]
    assert back.probability(ev) == pytest.approx(m.probability(ev), rel=0, abs=0)


@pytest.mark.parametrize("change, what", [
    ({"coef": [1.0]}, "one per feature"),
    ({"go_min_p": 0.0}, "go_min_p"),
    ({"success_mm": -1.0}, "success_mm"),
])
def test_bad_model_is_refused(change, what):
    with pytest.raises(ValueError) as e:
        _model(**change)
    assert what in str(e.value)


def test_evidence_round_trips_with_unknowns_as_null():
    ev = StepEvidence(kind="navcam-handoff", same_stop=1.0, ncc_peak=0.8)
    d = ev.to_dict()
    assert d["ncc_ratio"] is None and d["kind"] == "navcam-handoff"
    back = StepEvidence.from_dict(d)
    assert back.kind == ev.kind and back.ncc_peak == 0.8 and math.isnan(back.ncc_ratio)
    assert back.is_navcam_handoff == 1.0 and back.is_pancam_track == 0.0
