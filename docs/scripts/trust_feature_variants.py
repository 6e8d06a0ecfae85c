"""Feature variants of scip's trust model, and gradient boosting, on the evidence tables, held out by family.

    python docs/scripts/trust_feature_variants.py BROKEN_TABLE [BROKEN_TABLE ...] [--tables T ...]

For each variant of the logistic model's features (below), fitted at 4 px with ``fit_raw_model`` on the tables
(default: the three of ``tests/data/trust``), one line: each family's targets answered by a fit on the other
families (pooled: GO at p >= 0.90, false GO, Brier; occluded targets apart), and the p of scip's answer per target
of each BROKEN_TABLE (``evidence_rows`` of a deliberately broken downlink, e.g. the 5 cm occluder of
``tests/pipeline/test_handoff_broken.py``) under the fit on every table. Then the same for scikit-learn's
HistGradientBoostingClassifier on the 19 features. Used for docs/handoff.md, "Occluded targets in the training
data (session 22; measured, not adopted)".

The variants add derived evidence (properties set on ``Evidence`` here, not in the package):
``geo_best_sigma`` (the smaller of the near / far views' sigma), the best view's navcam residual
(``geo_best_nav_res_px``, in the package), each view's sigma capped at 10, and one interaction term,
``app_geo_conflict`` = log1p(smaller sigma) / (1 + the smaller of the two views' tracking offsets, px): large when
the expected windows track to the answer and its geometry disagrees (NaN without geometry; no tracking counts as
no agreement).
"""

from __future__ import annotations

import argparse
import math
import os

import numpy as np

from scipctl.commands.trust import read_rows
from scipctl.core.handoff.evidence import Evidence, _nanmin
from scipctl.core.handoff.trust_model import FEATURES, feature_matrix
from scipctl.pipeline import trust_fit as tf

R_PX = 4.0
GO_P = 0.90
SIGMA_CAP = 10.0
TABLES = ("tests/data/trust/evidence-20dl-11fam.jsonl.gz", "tests/data/trust/evidence-36dl-16fam.jsonl.gz",
          "tests/data/trust/evidence-32dl-16fam-occluded.jsonl.gz")


def _cap(v: float) -> float:
    return v if not math.isfinite(v) else min(v, SIGMA_CAP)


Evidence.geo_best_sigma = property(lambda e: _nanmin(e.geo_near_sigma, e.geo_far_sigma))
Evidence.geo_near_sigma_cap = property(lambda e: _cap(e.geo_near_sigma))
Evidence.geo_far_sigma_cap = property(lambda e: _cap(e.geo_far_sigma))
Evidence.geo_best_sigma_cap = property(lambda e: _nanmin(e.geo_near_sigma_cap, e.geo_far_sigma_cap))


def _conflict(e) -> float:
    s = e.geo_best_sigma
    if not math.isfinite(s):
        return math.nan
    off = _nanmin(e.app_near_offset_px, e.app_far_offset_px)
    return math.log1p(s) * (1.0 / (1.0 + off) if math.isfinite(off) else 0.0)


Evidence.app_geo_conflict = property(_conflict)


def variants() -> dict:
    base = dict(FEATURES)
    capped = {k: ((v[0] + "_cap", v[1]) if k.startswith("geo_") and k.endswith("log_sigma") else v) for k, v in base.items()}
    return {"the 19 features": base,
            "+ log smaller sigma": dict(base, geo_best_log_sigma=("geo_best_sigma", "log1p")),
            "+ log best navcam residual": dict(base, geo_best_log_nav_res=("geo_best_nav_res_px", "log1p")),
            "sigma capped at 10": capped,
            "capped + smaller one": dict(capped, geo_best_log_sigma=("geo_best_sigma_cap", "log1p")),
            "+ appearance x geometry": dict(base, app_geo_conflict=("app_geo_conflict", "x"))}


def report(name: str, pooled: list, broken: dict) -> None:
    s = tf.choice_summary([c for c in pooled if not c[5]], R_PX, GO_P)
    o = tf.occluded_summary([c for c in pooled if c[5]], GO_P)
    bk = " ".join(f"{k}: {v}" for k, v in broken.items())
    print(f"{name:28s} held out: n {s['n']} within {s['within'] * 100:.1f}% GO {s['go']} ({s['go_rate'] * 100:.1f}%) "
          f"false GO {s['false_go']} Brier {s['brier']:.4f} | occluded n {o['n']} GO {o['go']} max p {o['max_p']:.3f} "
          f"| broken p {bk}", flush=True)


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("broken", nargs="+", help="evidence tables of broken downlinks")
    ap.add_argument("--tables", nargs="+", default=list(TABLES))
    a = ap.parse_args(argv)
    for p in a.broken + a.tables:
        if not os.path.isfile(p):
            ap.error(f"no such file: {p}")
    rows = tf.fit_rows(read_rows(a.tables))
    broken = {os.path.basename(p): read_rows([p]) for p in a.broken}
    fams = tf.families_of(rows)
    for name, spec in variants().items():
        pooled = []
        for fam in fams:
            m = tf.fit_raw_model([r for r in rows if r.family != fam], (R_PX,), spec)
            pooled += tf.scip_choices(m, [r for r in rows if r.family == fam], R_PX)
        full = tf.fit_raw_model(rows, (R_PX,), spec)
        report(name, pooled, {k: [round(c[1], 3) for c in tf.scip_choices(full, v, R_PX)] for k, v in broken.items()})

    from sklearn.ensemble import HistGradientBoostingClassifier

    spec = dict(FEATURES)

    def X_of(rs):
        return feature_matrix([Evidence.from_dict(r.evidence) for r in rs], spec)

    def gb_fit(rs):
        g = HistGradientBoostingClassifier(max_iter=200, learning_rate=0.05, max_leaf_nodes=15, random_state=0)
        return g.fit(X_of(rs), np.array([r.is_right(R_PX) for r in rs]))

    def choices(g, rs):
        out = []
        for _, ts in sorted(tf.targets_of(rs).items()):
            p = g.predict_proba(X_of(ts))[:, 1]
            i = int(np.argmax(p))
            out.append((ts[0].family, float(p[i]), None if ts[i].occluded else ts[i].error_px, [], ts[0].kind, ts[0].occluded))
        return out

    pooled = []
    for fam in fams:
        pooled += choices(gb_fit([r for r in rows if r.family != fam]), [r for r in rows if r.family == fam])
    g = gb_fit(rows)
    report("gradient boosting", pooled, {k: [round(c[1], 3) for c in choices(g, v)] for k, v in broken.items()})


if __name__ == "__main__":
    main()
