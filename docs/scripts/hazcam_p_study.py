"""How well the chain's final hazcam answer's p_success predicts that answer's success, for chains answered by the
handoff path (no adopted closure): scip's own p (what the step carried before session 15) against scip's p times
its input navcam step's (``chain_trust.score_hazcam_handoffs``, recomputed here from the records, so campaigns made
before it compare too) (docs/stereo-and-tracking.md, "The hazcam handoff's p_success is the chain's").

    PYTHONPATH=. .venv/bin/python docs/scripts/hazcam_p_study.py CAMPAIGN_DIR [CAMPAIGN_DIR ...] [--markdown]

Success: the final answer within 4 hazcam px of the mark. Per campaign and overall: chains, success rate, Brier
score of each p and of the base rate (the success rate as a constant), and the reliability bins of each p.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
SUCCESS_PX = 4.0
BINS = (0.0, 0.2, 0.4, 0.6, 0.8, 1.0 + 1e-9)


def rows(campaign: str) -> list:
    """``(scip p, chain p, success)`` of each chain of ``campaign`` whose final hazcam answer is the handoff's."""
    from campaign_chains import campaign_chains
    from scipctl.pipeline.chain import ChainStep
    from scipctl.pipeline.chain_trust import score_hazcam_handoffs

    out = []
    for _, _, record in campaign_chains([campaign], {}):
        steps = [ChainStep.from_dict(d, "chain record", i) for i, d in enumerate(record.get("steps") or [])]
        fin = next((i for i, s in enumerate(steps) if s.camera == "hazcam" and s.extra.get("final")), None)
        if fin is None or steps[fin].extra.get("answer") == "closure":
            continue
        H = steps[fin]
        if H.error_px is None or H.p_success is None:
            continue
        if "scip_p_success" in H.extra:  # scored by the chain itself (session 15 on)
            p_scip, p_chain = H.extra["scip_p_success"], H.p_success
        else:
            p_scip = H.p_success
            score_hazcam_handoffs(steps)
            p_chain = steps[fin].p_success
        if p_chain is None:
            continue
        out.append((float(p_scip), float(p_chain), float(H.error_px <= SUCCESS_PX)))
    return out


def summary(r: list) -> dict:
    a = np.array(r, float).reshape(-1, 3)
    y = a[:, 2]
    base = float(y.mean()) if len(y) else float("nan")
    d = {"chains": len(y), "success": base, "brier_scip": float(np.mean((a[:, 0] - y) ** 2)),
         "brier_chain": float(np.mean((a[:, 1] - y) ** 2)), "brier_base": base * (1 - base), "bins": {}}
    for name, col in (("scip", 0), ("chain", 1)):
        b = []
        for lo, hi in zip(BINS[:-1], BINS[1:]):
            m = (a[:, col] >= lo) & (a[:, col] < hi)
            if m.any():
                b.append((lo, min(hi, 1.0), int(m.sum()), float(a[m, col].mean()), float(y[m].mean())))
        d["bins"][name] = b
    return d


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("campaigns", nargs="+")
    ap.add_argument("--markdown", action="store_true")
    a = ap.parse_args()
    per = {c: rows(c) for c in a.campaigns}
    allr = [x for r in per.values() for x in r]
    print("| campaign | chains | success | Brier: scip's p | scip's x navcam step's | base rate |")
    print("| --- | --- | --- | --- | --- | --- |")
    for name, r in list(per.items()) + [("all", allr)]:
        s = summary(r)
        print(f"| {name} | {s['chains']} | {s['success']:.2f} | {s['brier_scip']:.3f} | {s['brier_chain']:.3f} | "
              f"{s['brier_base']:.3f} |")
    s = summary(allr)
    for name in ("scip", "chain"):
        print(f"\nreliability, {name} p (all): bin, chains, mean p, success")
        for lo, hi, n, mp, sr in s["bins"][name]:
            print(f"  [{lo:.1f}, {hi:.1f}) {n:4d} {mp:.2f} {sr:.2f}")


if __name__ == "__main__":
    main()
