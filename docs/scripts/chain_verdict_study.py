"""A verdict on the whole chain, measured only (not shipped; docs/stereo-and-tracking.md, "The drift's cause").

    PYTHONPATH=. .venv/bin/python docs/scripts/chain_verdict_study.py CHAINS.jsonl.gz

CHAINS: a table of ``docs/scripts/fit_step_trust.py table``. Each family's tracking steps are scored by a step
model fitted on the other families (``held_out``). Per chain: the lowest and mean logit of its tracking steps' p,
how many are below 0.5, scip's logit at the final handoff, and the number of tracking steps. A logistic
regression of "final hazcam answer within 4 px" on those features is also fitted with each family left out
(scikit-learn, C = 0.1). A chain with no final answer gets p = 0. Printed: Brier against the base rate, GO
figures at several thresholds, and the reliability bins.
"""
import gzip, json, sys
import numpy as np
from sklearn.linear_model import LogisticRegression
from scipctl.pipeline.step_trust_fit import ChainRow, held_out, success_mm_of, step_within

chains = [ChainRow.from_dict(json.loads(l)) for l in gzip.open(sys.argv[1], "rt")]
smm = success_mm_of(chains)
held = held_out(chains, smm)
rows = []
for fam, (_, probs) in held.items():
    for c, pc in zip([c for c in chains if c.family == fam], probs):
        final = next((i for i, s in enumerate(c.steps) if s.final), None)
        if final is None:
            rows.append((fam, None, False)); continue
        fe = c.steps[final].error_px
        within = fe is not None and fe <= 4.0
        tp = [p for s, p in zip(c.steps[:final], pc[:final]) if s.evidence is not None]
        tp = np.clip(np.array(tp if tp else [1.0]), 1e-4, 1 - 1e-4)
        lg = np.log(tp / (1 - tp))
        ps = c.steps[final].p_scip or 0.0
        ps = min(max(ps, 1e-4), 1 - 1e-4)
        x = [lg.min(), lg.mean(), float((tp < 0.5).sum()), np.log(ps / (1 - ps)), float(len(tp))]
        rows.append((fam, x, within))
fams = sorted({r[0] for r in rows})
P, Y, F = [], [], []
for fam in fams:
    tr = [r for r in rows if r[0] != fam and r[1] is not None]
    te = [r for r in rows if r[0] == fam]
    X = np.array([r[1] for r in tr]); y = np.array([r[2] for r in tr])
    mu, sd = X.mean(0), X.std(0) + 1e-9
    m = LogisticRegression(C=0.1).fit((X - mu) / sd, y)
    for r in te:
        p = 0.0 if r[1] is None else float(m.predict_proba(((np.array(r[1]) - mu) / sd)[None])[0, 1])
        P.append(p); Y.append(r[2]); F.append(fam)
P, Y = np.array(P), np.array(Y)
print("chains", len(P), "within", Y.sum(), "Brier", round(float(((P - Y) ** 2).mean()), 3), "base", round(float(((Y.mean() - Y) ** 2).mean()), 3))
for t in (0.5, 0.7, 0.8, 0.9, 0.95):
    go = P >= t
    print(f"t={t}: GO {go.sum()} ({go.mean():.0%}), GO within {(go & Y).sum()}, precision {((go & Y).sum() / max(go.sum(), 1)):.0%}, misses GO {(go & ~Y).sum()} of {(~Y).sum()}")
for lo, hi in ((0, .2), (.2, .5), (.5, .8), (.8, .9), (.9, 1.01)):
    k = (P >= lo) & (P < hi)
    print(f"[{lo},{hi}) n={k.sum()} meanP={P[k].mean() if k.any() else float('nan'):.2f} obs={Y[k].mean() if k.any() else float('nan'):.2f}")
