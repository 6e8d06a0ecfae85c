"""The pre-uplink prediction against what the chain then did (docs/sequence.md, "Measured").

    python docs/scripts/prediction_vs_chain.py PRED_CAMPAIGN CHAIN_CAMPAIGN [CHAIN_CAMPAIGN ...] [--scenes FILE.mcap ...]

PRED_CAMPAIGN: a ``scipctl campaign`` folder with prediction records; CHAIN_CAMPAIGN: folders with chain records
(the same downlinks, matched by their SHA-256; a downlink in several is taken from the first). An approach succeeds when the chain's last hazcam answer is
within ``--success-px`` of the mark (no hazcam answer: a miss). The family is the campaign's, or, with
``--scenes``, the name of the folder holding each downlink file (for downlinks rendered outside the scene
families). Prints the markdown tables of docs/sequence.md.
"""

from __future__ import annotations

import argparse
import collections
import hashlib
import json
from pathlib import Path

import numpy as np


def _records(folder: Path) -> dict:
    out = {}
    for f in sorted((folder / "records").glob("*.jsonl")):
        recs = [json.loads(line) for line in f.read_text().splitlines() if line.strip()]
        head = [r for r in recs if r.get("kind") == "downlink"]
        if head and head[0].get("status") == "ok":
            out[head[0]["downlink_sha256"]] = recs
    return out


def approaches(chain_dirs: list, pred_dir: Path, success_px: float, folder_of: dict) -> list:
    from scipctl.pipeline.prediction_calibration_fit import last_hazcam_error_px

    chains, preds = {}, _records(pred_dir)
    for d in chain_dirs:
        for k, v in _records(d).items():
            chains.setdefault(k, v)
    rows = []
    for sha, recs in preds.items():
        if sha not in chains:
            continue
        ch = {r["record"]["target"]: r["record"] for r in chains[sha] if r.get("kind") == "chain"}
        for r in recs:
            if r.get("kind") != "prediction" or r["record"]["target"] not in ch:
                continue
            p, c = r["record"], ch[r["record"]["target"]]
            err = last_hazcam_error_px(c["steps"])
            rows.append({"family": folder_of.get(sha, r.get("family")), "P": p.get("confidence") or 0.0,
                         "written": bool(p.get("sequence_written")), "success": err is not None and err <= success_px,
                         "last": c["steps"][-1] if c["steps"] else {}})
    return rows


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("preds", type=Path)
    ap.add_argument("chains", type=Path, nargs="+")
    ap.add_argument("--scenes", nargs="*", type=Path, default=[])
    ap.add_argument("--success-px", type=float, default=4.0)
    a = ap.parse_args(argv)
    folder_of = {hashlib.sha256(p.read_bytes()).hexdigest(): p.resolve().parent.name for p in a.scenes}
    rows = approaches(a.chains, a.preds, a.success_px, folder_of)
    print("| family | approaches | chain within 4 px | mean P | Brier | Brier of the base rate | sequences written "
          "| written, chain missed |\n| --- | --- | --- | --- | --- | --- | --- | --- |")
    for fam in sorted({r["family"] for r in rows}) + ["all"]:
        R = [r for r in rows if fam == "all" or r["family"] == fam]
        y = np.array([r["success"] for r in R], float)
        P = np.array([r["P"] for r in R])
        w = [r for r in R if r["written"]]
        print(f"| {fam} | {len(R)} | {100 * y.mean():.0f} % | {P.mean():.2f} | {np.mean((P - y) ** 2):.3f} | "
              f"{np.mean((y.mean() - y) ** 2):.3f} | {len(w)} | {sum(not r['success'] for r in w)} |")
    y = np.array([r["success"] for r in rows], float)
    P = np.array([r["P"] for r in rows])
    print("\n| P bin | n | mean P | chain within 4 px |\n| --- | --- | --- | --- |")
    for lo, hi in ((0, .2), (.2, .5), (.5, .7), (.7, .9), (.9, 1.01)):
        m = (P >= lo) & (P < hi)
        if m.any():
            print(f"| [{lo:.1f}, {min(hi, 1):.1f}) | {m.sum()} | {P[m].mean():.2f} | {100 * y[m].mean():.0f} % |")
    modes = collections.Counter()
    for r in rows:
        if not r["success"]:
            last = r["last"]
            modes[f"{last.get('camera')} {'trusted' if last.get('ok') else 'flagged'} "
                  f"{'>' if (last.get('error_px') or 0) > a.success_px else '<='} {a.success_px:g} px"] += 1
    print("\nmisses by the chain's last step:", dict(modes))
    succ = [r for r in rows if r["success"]]
    print("successes with a written sequence:", sum(r["written"] for r in succ), "of", len(succ))


if __name__ == "__main__":
    main()
