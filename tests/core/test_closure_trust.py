"""The closure's trust model (core/closure_trust.py): the logistic it evaluates, its file form, bad files refused."""

import math

import numpy as np
import pytest

from scipctl.core.closure_trust import CLOSURE_FEATURES, ClosureEvidence, ClosureTrustModel


def _model(**kw):
    feats = {k: CLOSURE_FEATURES[k] for k in ("ncc_peak", "log_handoff_px", "from_pancam")}
    d = dict(features=feats, fill=[0.6, 1.0, 0.5], mean=[0.6, 1.2, 0.5], scale=[0.1, 0.8, 0.5],
             coef=[1.5, -0.7, 0.4], intercept=0.9, go_min_p=0.95, success_px=4.0, provenance={"n": 3})
    d.update(kw)
    return ClosureTrustModel(**d)


def test_probability_is_the_logistic_of_the_standardised_features():
    m = _model()
    evs = [ClosureEvidence(ncc_peak=0.8, handoff_px=2.0, from_pancam=1.0),
           ClosureEvidence(ncc_peak=math.nan, handoff_px=300.0, from_pancam=0.0),  # NaN at its fill
           ClosureEvidence(ncc_peak=10.0, handoff_px=0.0, from_pancam=1.0)]  # clipped to +-5
    want = []
    for ncc, h, fp in ((0.8, 2.0, 1.0), (0.6, 300.0, 0.0), (10.0, 0.0, 1.0)):
        z = np.array([(ncc - 0.6) / 0.1, (math.log1p(h) - 1.2) / 0.8, (fp - 0.5) / 0.5]).clip(-5, 5)
        want.append(1 / (1 + math.exp(-(z @ [1.5, -0.7, 0.4] + 0.9))))
    np.testing.assert_allclose(m.probability(evs), want, rtol=1e-12)  # the same arithmetic, a few ulp apart
    assert m.probability([]).shape == (0,)


def test_model_round_trips_through_its_dict():
    m = _model()
    again = ClosureTrustModel.from_dict(m.to_dict())
    assert again == m
    e = ClosureEvidence(ncc_peak=0.7, local_inliers=math.nan)
    assert ClosureEvidence.from_dict(e.to_dict()).to_dict() == e.to_dict()
    assert e.to_dict()["local_inliers"] is None


@pytest.mark.parametrize("change, what", [({"coef": [1.0]}, "one per feature"), ({"go_min_p": 0.0}, "go_min_p"),
                                          ({"success_px": -1.0}, "success_px"),
                                          ({"features": {"a": ("ncc_peak", "cube"), "b": ("x", "x"),
                                                         "c": ("y", "x")}}, "transform")])
def test_bad_model_is_refused(change, what):
    with pytest.raises(ValueError, match=what):
        _model(**change)
    with pytest.raises(ValueError, match="closure trust model"):
        ClosureTrustModel.from_dict({"features": []})
