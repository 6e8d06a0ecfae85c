"""A forward-backward check of the closure's reference, measured and not adopted (docs/stereo-and-tracking.md,
"Closure as the answer"): the reference step (the 4.5 m pancam track, or the navcam handoff) tracked back into the
designation image by the chain's own feature-guided step, and how far it lands from the designated pixel.

    PYTHONPATH=. .venv/bin/python docs/scripts/chain_back_check.py CAMPAIGN_DIR OUT.jsonl   # one line per chain
    PYTHONPATH=. .venv/bin/python docs/scripts/chain_back_check.py --table OUT.jsonl        # the figures

CAMPAIGN_DIR: a campaign run with ``--closure`` or ``--chain-answer closure`` (its downlinks are read again from the
paths in its records).
"""

from __future__ import annotations

import argparse
import glob
import json
import math
import time

import numpy as np


def back_check(dl, steps: list, ref: int, params) -> dict:
    """``steps[ref]`` tracked back into the designation image (``steps[0]``): ``{"status", "uv", "back_px"}``,
    ``back_px`` the distance (designation image pixels) from where it lands to the designated pixel."""
    from scipctl.pipeline.chain_closure import track_from_step

    D, R = steps[0], steps[ref]
    tr, info, _, pred = track_from_step(dl, R, dl.product(D.product_id), params)
    if pred is None:
        return {"status": "failed", "uv": None, "back_px": None}
    out = {"status": info.get("feature_status", "failed"), "uv": None, "back_px": None,
           "ncc_peak": info.get("ncc_score")}
    if tr is not None and np.all(np.isfinite(tr.uv)):
        out["uv"] = [float(x) for x in tr.uv]
        out["back_px"] = float(np.linalg.norm(np.asarray(tr.uv) - np.asarray(D.tracked_uv, float)))
    return out


def run(campaign: str, out_path: str) -> None:
    from scipctl.io.downlink import read_downlink
    from scipctl.pipeline.chain import ChainParams, ChainStep

    params = ChainParams()
    with open(out_path, "w", encoding="utf-8") as out:
        for f in sorted(glob.glob(campaign + "/records/*.jsonl")):
            lines = [json.loads(x) for x in open(f, encoding="utf-8")]
            dl = read_downlink(lines[0]["job"]["path"])
            for r in lines[1:]:
                if r.get("kind") != "chain":
                    continue
                st = [ChainStep.from_dict(s) for s in r["record"]["steps"]]
                fin = st[-1]
                c = fin.extra.get("closure")
                if not c or c.get("reference_step") is None:
                    continue
                R = st[c["reference_step"]]
                t0 = time.process_time()
                b = back_check(dl, st, c["reference_step"], params)
                row = {"family": r["family"], "downlink": lines[0]["job"]["path"], "target": r["record"]["target"],
                       "status": c["status"], "ref": f"{R.camera}-{R.kind}", "ref_err_px": R.error_px,
                       "ref_px_mm": R.extra.get("px_mm"), "des_px_mm": st[0].extra.get("px_mm"), "back": b,
                       "closure_err_px": None if c.get("uv") is None or fin.mark_uv is None
                       else math.dist(c["uv"], fin.mark_uv), "cpu_s": time.process_time() - t0}
                out.write(json.dumps(row) + "\n")
                out.flush()


def table(path: str) -> None:
    from scipy.stats import spearmanr

    rows = [json.loads(x) for x in open(path, encoding="utf-8")]
    a = np.array([(r["back"]["back_px"] * r["des_px_mm"], r["ref_err_px"] * r["ref_px_mm"]) for r in rows
                  if r["back"]["back_px"] is not None and r["ref_err_px"] is not None and r["ref_px_mm"]], float)
    bad = a[:, 1] > 5.0
    print(json.dumps({"chains": len(rows), "with_both": int(len(a)),
                      "spearman_back_mm_vs_ref_error_mm": float(spearmanr(a[:, 0], a[:, 1]).statistic),
                      "ref_error_over_5mm": int(bad.sum()), "of_them_back_over_3mm": int((a[bad, 0] > 3).sum()),
                      "ref_error_within_5mm": int((~bad).sum()), "of_them_back_over_3mm_": int((a[~bad, 0] > 3).sum()),
                      "median_cpu_s": float(np.median([r["cpu_s"] for r in rows]))}, indent=1))


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("campaign", nargs="?")
    ap.add_argument("out", nargs="?")
    ap.add_argument("--table")
    a = ap.parse_args()
    if a.table:
        table(a.table)
    else:
        run(a.campaign, a.out)


if __name__ == "__main__":
    main()
