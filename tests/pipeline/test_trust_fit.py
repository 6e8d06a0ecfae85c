"""scipctl/pipeline/trust_fit.py: the trust model's fit reproduces scikit-learn's logistic regression, picks GO
thresholds from held-out families, and reports per family held out."""

import math

import numpy as np
import pytest

from scipctl.core.handoff.evidence import Evidence
from scipctl.core.handoff.trust_model import FEATURES, TrustModel, feature_matrix
from scipctl.pipeline.trust_fit import C_REG, CLIP_Z, GO_GRID, RADII_PX, evaluate, fit_trust_model
from tests.pipeline.trust_table import FAMILIES, small_table


@pytest.fixture(scope="module")
def rows():
    return small_table()


@pytest.fixture(scope="module")
def model(rows):
    return fit_trust_model(rows)


def test_coefficients_are_sklearns_within_solver_tolerance(rows, model):
    from sklearn.linear_model import LogisticRegression

    ev = [Evidence.from_dict(r.evidence) for r in rows]
    X = feature_matrix(ev, model.features)
    X = np.where(np.isfinite(X), X, np.nanmean(X, axis=0))
    Z = np.clip((X - X.mean(axis=0)) / np.where(X.std(axis=0) > 1e-12, X.std(axis=0), 1.0), -CLIP_Z, CLIP_Z)
    err = np.array([r.error_px for r in rows])
    for fit in model.fits:
        ref = LogisticRegression(C=C_REG, max_iter=10000, tol=1e-10).fit(Z, err <= fit.success_px)
        # the model keeps 10 significant digits; lbfgs stops at tol 1e-10 on the gradient
        np.testing.assert_allclose(fit.coef, ref.coef_[0], rtol=1e-6, atol=1e-7)
        assert math.isclose(fit.intercept, ref.intercept_[0], rel_tol=1e-6, abs_tol=1e-7)


def test_only_features_that_vary_are_kept(model):
    assert set(model.features) <= set(FEATURES)
    # the table has near appearance, forward-backward and support, never geometry
    assert "app_near_log_offset" in model.features and "fb_near_log_error" in model.features
    assert not any(n.startswith("geo_") for n in model.features)


def test_fit_is_deterministic(rows, model):
    again = fit_trust_model(rows)
    assert again.to_dict() == model.to_dict()


def test_go_thresholds_on_the_grid_and_provenance(model):
    assert [f.success_px for f in model.fits] == list(RADII_PX)
    assert all(f.go_min_p in GO_GRID for f in model.fits)
    prov = model.provenance
    assert prov["training_families"] == list(FAMILIES) and prov["n_targets"] == 90 and prov["n_rows"] == 360


def test_probability_increases_with_the_radius(rows, model):
    ev = [Evidence.from_dict(r.evidence) for r in rows[:40]]
    ps = [model.probability(ev, r) for r in (1.0, 1.5, 2.0, 3.0, 4.0, 8.0)]
    for a, b in zip(ps, ps[1:]):
        assert np.all(b >= a - 1e-12)


def test_evaluation_holds_each_family_out(rows, model):
    rep = evaluate(rows, 4.0, model)
    assert sorted(rep["held_out"]) == list(FAMILIES)
    for fam, s in rep["held_out"].items():
        assert s["n"] == 30
        assert s["go"] + (s["n"] - s["go"]) == s["n"]
        assert s["false_go"] <= s["go"] and s["missed_go"] <= s["n"] - s["go"]
        assert sum(b["n"] for b in s["reliability"]) == s["n"]
        assert {"logistic", "gradient_boosting", "logistic_isotonic"} <= set(s["candidate_models"])
    assert rep["held_out_pooled"]["n"] == 90


def test_round_trip_through_json(model):
    import json

    from scipctl.io.trust_model import trust_model_from_text, trust_model_json

    text = trust_model_json(model)
    back = trust_model_from_text(text, "test")
    assert isinstance(back, TrustModel) and back.to_dict() == json.loads(text)
    assert trust_model_json(back) == text
    assert list(back.features) == list(model.features)  # the order the coefficients follow
    ev = [Evidence.from_dict(r.evidence) for r in small_table(4)]
    for r in RADII_PX:
        np.testing.assert_array_equal(back.probability(ev, r), model.probability(ev, r))


def _with_occluded(rows, every: int = 6):
    """``rows`` with every ``every``-th target of each family occluded (its rows flagged, no error)."""
    import dataclasses

    out = []
    for r in rows:
        hidden = int(r.target[1:]) % every == 0
        out.append(dataclasses.replace(r, error_px=None, occluded=True) if hidden else r)
    return out


def test_occluded_rows_are_wrong_at_every_radius(rows):
    """An occluded target's rows are fitted as failures: the same model as when they carry an error larger than
    every radius."""
    import dataclasses

    occ = _with_occluded(rows)
    far = [dataclasses.replace(r, error_px=1e9, occluded=False) if r.occluded else r for r in occ]
    a, b = fit_trust_model(occ), fit_trust_model(far)
    assert [f.to_dict() for f in a.fits] == [f.to_dict() for f in b.fits]
    assert a.provenance["n_occluded_targets"] == 15 and "n_occluded_targets" not in b.provenance
    assert all(not r.is_right(1e12) for r in occ if r.occluded)


def test_evaluation_reports_occluded_targets_apart(rows):
    occ = _with_occluded(rows)
    rep = evaluate(occ, 4.0)
    o = rep["held_out_occluded"]
    assert o["n"] == 15 and rep["held_out_pooled"]["n"] == 75
    assert 0 <= o["go"] <= o["n"] and 0.0 <= o["mean_p"] <= o["max_p"] <= 1.0
    assert sum(s["occluded"]["n"] for s in rep["held_out"].values()) == 15
    assert o["go"] == sum(s["occluded"]["go"] for s in rep["held_out"].values())


def test_evidence_row_keeps_old_tables_bytes():
    from scipctl.pipeline.trust_data import EvidenceRow

    r = small_table(1)[0]
    d = r.to_dict()
    assert "occluded" not in d and EvidenceRow.from_dict(d) == r
    import dataclasses

    h = dataclasses.replace(r, error_px=None, occluded=True)
    assert h.to_dict()["occluded"] is True and EvidenceRow.from_dict(h.to_dict()) == h


def test_a_fit_builds_each_rows_features_once(rows, monkeypatch):
    # fit_raw_model parsed every row's evidence and built its features twice: once to find the features that vary,
    # then again for those (fit-trust spent half its time on the second pass over 12777 rows, 17 fits)
    from scipctl.pipeline import trust_fit as tf

    built, parsed = [], []
    monkeypatch.setattr(tf, "feature_matrix", lambda ev, spec: built.append(len(ev)) or feature_matrix(ev, spec))
    from_dict = Evidence.from_dict
    monkeypatch.setattr(Evidence, "from_dict", classmethod(lambda cls, d: parsed.append(1) or from_dict(d)))
    used = tf.fit_rows(rows)
    m = tf.fit_raw_model(used)
    assert built == [len(used)] and len(parsed) == len(used)
    monkeypatch.undo()
    # the columns kept are those features' own: the model's standardisation is that of their matrix built alone
    # (the packaged model, made again byte for byte, is tests/commands/test_scip_cli.py's)
    X = feature_matrix([Evidence.from_dict(r.evidence) for r in used], m.features)
    assert [m.fill, m.mean, m.scale] == [[tf.round_sig(v) for v in a] for a in tf.standardise(X)]
