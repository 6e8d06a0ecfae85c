"""The prediction's calibration (core/prediction_calibration.py): the logistic it evaluates, its file form, the
packaged models' shape, bad input refused."""

import math

import numpy as np
import pytest

from scipctl.core.prediction_calibration import PREDICTION_FEATURES, PredictionCalibration


def _model(**kw):
    d = dict(features=dict(PREDICTION_FEATURES), fill=[0.8], mean=[0.8], scale=[0.3], coef=[0.5], intercept=0.4,
             go_min_p=1.0, success_px=4.0, provenance={"route": "plan", "n_rows": 10})
    d.update(kw)
    return PredictionCalibration(**d)


def test_p_success_is_the_logistic_of_the_standardised_simulated_probability():
    m = _model()
    for p in (0.0, 0.37, 0.8, 1.0):
        z = float(np.clip((p - 0.8) / 0.3, -5, 5))
        assert m.p_success(p) == pytest.approx(1 / (1 + math.exp(-(0.5 * z + 0.4))), rel=1e-12)
    # a positive weight: more simulated success, more predicted success; a negative one the other way
    ps = [m.p_success(p) for p in np.linspace(0, 1, 11)]
    assert all(b > a for a, b in zip(ps, ps[1:]))
    flat = _model(coef=[0.0])
    assert flat.p_success(0.0) == flat.p_success(1.0) == pytest.approx(1 / (1 + math.exp(-0.4)))


@pytest.mark.parametrize("bad", [-0.01, 1.01, math.nan])
def test_a_simulated_probability_outside_0_1_is_refused(bad):
    with pytest.raises(ValueError, match="p_simulated"):
        _model().p_success(bad)


def test_model_round_trips_through_its_dict_and_bad_files_are_refused():
    m = _model()
    assert PredictionCalibration.from_dict(m.to_dict()) == m
    with pytest.raises(ValueError, match="prediction calibration"):
        PredictionCalibration.from_dict({"features": []})
    with pytest.raises(ValueError, match="one per feature"):
        _model(coef=[1.0, 2.0])


@pytest.mark.parametrize("route", ["plan", "downlink"])
def test_the_packaged_calibrations_are_probabilities_for_the_chains_outcome(route):
    """Each route's packaged model is fitted on its own route's approaches and maps [0, 1] into (0, 1)."""
    from scipctl.io.prediction_calibration import load_packaged_prediction_calibration

    m = load_packaged_prediction_calibration(route)
    assert m is not None and m.provenance["route"] == route and m.success_px == 4.0
    assert m.provenance["n_rows"] >= 100 and len(m.provenance["training_families"]) >= 10
    for p in (0.0, 0.5, 1.0):
        assert 0.0 < m.p_success(p) < 1.0
