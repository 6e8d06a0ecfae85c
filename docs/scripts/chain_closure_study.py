"""The chain's closure check as evidence for a whole-chain verdict, each scene family held out
(docs/stereo-and-tracking.md, "Closure").

    PYTHONPATH=. .venv/bin/python docs/scripts/chain_closure_study.py CAMPAIGN_DIR... [--json OUT.json]

Reads the chain records of campaigns (``scipctl campaign ... --no-handoff --no-predict``; records carry each
step's ``p_success`` and the final hazcam step's ``extra["closure"]``). Per chain: whether its final hazcam answer
is within 4 px of the mark (the label), and

* ``steps``: the chain's verdict today (every step GO);
* ``closure``: a rule with no fitted number: GO when scip's answer is GO, the closure is confirmed (from a trusted
  pancam track) and lands within ``CLOSURE_AGREE_PX`` (4, the success radius) of the answer; ``closure+ref_go``:
  also the pancam track GO by the step model;
* ``logistic`` (features with and without the closure): a logistic regression (scikit-learn, C = 0.1,
  standardised) of the label on [scip's logit, the lowest tracking step's logit, the reference pancam track's
  logit] (+ [closure confirmed, log(closure px + 0.5)]), fitted with each family left out; GO at p >= 0.9.

Printed per family and pooled: chains, within 4 px, GO, GO precision, misses GO, Brier (logistic).
"""
import argparse
import glob
import json
import math
from pathlib import Path

import numpy as np

from scipctl.campaign.jobs import family_of_file

CLOSURE_AGREE_PX = 4.0
SUCCESS_PX = 4.0


def _logit(p):
    p = min(max(0.0 if p is None else float(p), 1e-4), 1 - 1e-4)
    return math.log(p / (1 - p))


def chain_rows(dirs):
    rows = []
    for d in dirs:
        for f in sorted(glob.glob(str(Path(d) / "records" / "*.jsonl"))):
            family = None
            for line in open(f):
                r = json.loads(line)
                if r.get("kind") == "downlink" and (r.get("job") or {}).get("path"):
                    # the family from the simulation record beside the file (campaigns before the fix of
                    # campaign/jobs.family_of_file recorded synth --family downlinks as 'default')
                    family = family_of_file(Path(r["job"]["path"]))
                if r.get("kind") != "chain" or "steps" not in r["record"]:
                    continue
                r["family"] = family or r["family"]
                steps = r["record"]["steps"]
                fin = next((i for i, s in enumerate(steps) if s["camera"] == "hazcam" and s["extra"].get("final")), None)
                row = {"family": r["family"], "downlink": r["downlink"], "target": r["record"]["target"],
                       "chain_go": bool(r["record"].get("go")), "final": fin is not None}
                if fin is None:
                    row.update(within=False, x=None, x0=None, rule=False)
                    rows.append(row)
                    continue
                H = steps[fin]
                row["within"] = H["error_px"] is not None and H["error_px"] <= SUCCESS_PX
                row["final_px"] = H["error_px"]
                c = H["extra"].get("closure") or {"status": "absent"}
                row["closure"] = c
                track = [s for s in steps[1:fin] if s["camera"] != "hazcam"]
                lo = min((_logit(s["p_success"]) for s in track), default=_logit(1.0))
                ref = steps[c["reference_step"]] if c.get("reference_step") is not None else None
                ref_l = _logit(ref["p_success"]) if ref is not None else _logit(0.0)
                x0 = [_logit(H["p_success"]), lo, ref_l]
                conf = 1.0 if c["status"] == "confirmed" else 0.0
                cpx = c.get("closure_px")
                x = x0 + [conf, math.log((cpx if cpx is not None else 100.0) + 0.5)]
                row.update(x=x, x0=x0)
                row["rule"] = bool(H["go"] and c["status"] == "confirmed" and cpx is not None and cpx <= CLOSURE_AGREE_PX)
                row["rule_ref_go"] = bool(row["rule"] and ref is not None and ref["go"])
                rows.append(row)
    return rows


def family_out(rows, key):
    from sklearn.linear_model import LogisticRegression

    fams = sorted({r["family"] for r in rows})
    for fam in fams:
        tr = [r for r in rows if r["family"] != fam and r[key] is not None]
        X = np.array([r[key] for r in tr])
        y = np.array([r["within"] for r in tr])
        for r in rows:
            if r["family"] == fam:
                r["p_" + key] = 0.0
        if len(set(y)) < 2:
            continue
        mu, sd = X.mean(0), X.std(0) + 1e-9
        m = LogisticRegression(C=0.1).fit((X - mu) / sd, y)
        for r in rows:
            if r["family"] == fam and r[key] is not None:
                r["p_" + key] = float(m.predict_proba(((np.array(r[key]) - mu) / sd)[None])[0, 1])


def figures(rows, go_of):
    n = len(rows)
    y = np.array([r["within"] for r in rows], bool)
    go = np.array([go_of(r) for r in rows], bool)
    return {"chains": n, "within": int(y.sum()), "go": int(go.sum()), "go_within": int((go & y).sum()),
            "go_precision": None if not go.any() else round(float((go & y).sum() / go.sum()), 3),
            "misses": int((~y).sum()), "misses_go": int((go & ~y).sum())}


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("dirs", nargs="+")
    ap.add_argument("--json")
    ap.add_argument("--rows", action="store_true", help="print one line per chain")
    a = ap.parse_args()
    rows = chain_rows(a.dirs)
    family_out(rows, "x")
    family_out(rows, "x0")
    verdicts = {"steps": lambda r: r["chain_go"], "closure": lambda r: r["rule"],
                "closure+ref_go": lambda r: r.get("rule_ref_go", False),
                "logistic+closure": lambda r: r.get("p_x", 0) >= 0.9, "logistic": lambda r: r.get("p_x0", 0) >= 0.9}
    out = {}
    for fam in sorted({r["family"] for r in rows}) + ["pooled"]:
        sel = rows if fam == "pooled" else [r for r in rows if r["family"] == fam]
        out[fam] = {k: figures(sel, g) for k, g in verdicts.items()}
        y = np.array([r["within"] for r in sel], float)
        for key in ("x", "x0"):
            p = np.array([r.get("p_" + key, 0.0) for r in sel])
            out[fam]["brier_" + key] = round(float(((p - y) ** 2).mean()), 3)
        out[fam]["brier_base"] = round(float(((y.mean() - y) ** 2).mean()), 3)
        print(fam, json.dumps(out[fam]))
    cl = [r for r in rows if r["final"]]
    st = {}
    for r in cl:
        st[r["closure"]["status"]] = st.get(r["closure"]["status"], 0) + 1
    print("closure status over chains with a final answer:", st)
    for r in (cl if a.rows else []):
        c = r["closure"]
        print(f'{r["family"]:>16s} {r["downlink"][-22:]:>22s} {r["target"]:>4s} final {r["final_px"]:6.2f} '
              f'closure {c["status"]:>12s} px {c.get("closure_px") if c.get("closure_px") is None else round(c["closure_px"], 2)} '
              f'rule {int(r["rule"])} p {r.get("p_x", 0):.2f} p0 {r.get("p_x0", 0):.2f} steps {int(r["chain_go"])}')
    if a.json:
        Path(a.json).write_text(json.dumps({"figures": out, "rows": rows}, indent=1))


if __name__ == "__main__":
    main()
