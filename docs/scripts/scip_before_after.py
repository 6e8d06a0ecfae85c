"""scip's answers of two trees on the same downlinks: per family and overall (within 4 px, median, GO, GO right,
Brier) and the paired change per target. Inputs: two folders of ``simulate-handoff DL --methods scip --json``
outputs named FAMILY-RUN.json (the family is the name before the last '-').

    python docs/scripts/scip_before_after.py BEFORE_DIR AFTER_DIR
"""

import glob
import json
import os
import statistics
import sys


def load(d):
    out = {}
    for f in sorted(glob.glob(os.path.join(d, "*.json"))):
        doc = json.load(open(f))
        fam = os.path.basename(f).rsplit("-", 1)[0]
        for r in doc["results"]:
            if r["method"] == "scip" and r.get("truth_uv") is not None:
                out[(os.path.basename(f), r["target"])] = (fam, r["error_px"], r["p_success"], r["go"])
    return out


def summary(rows, px=4.0):
    e = [x[1] for x in rows if x[1] is not None]
    ok = [x[1] is not None and x[1] <= px for x in rows]
    go = [bool(x[3]) for x in rows]
    brier = sum(((x[2] or 0.0) - w) ** 2 for x, w in zip(rows, ok)) / len(rows)
    return (f"{sum(ok)} of {len(rows)}, median {statistics.median(e):.2f} px, GO {sum(go)} "
            f"(right {sum(g and w for g, w in zip(go, ok))}), Brier {brier:.3f}")


def main():
    B, A = load(sys.argv[1]), load(sys.argv[2])
    keys = [k for k in B if k in A]
    print("| family | before | after |\n| --- | --- | --- |")
    for fam in sorted({B[k][0] for k in keys}) + ["all"]:
        ks = [k for k in keys if fam == "all" or B[k][0] == fam]
        print(f"| {fam} | {summary([B[k] for k in ks])} | {summary([A[k] for k in ks])} |")
    d = [A[k][1] - B[k][1] for k in keys if A[k][1] is not None and B[k][1] is not None]
    print(f"\npaired (after - before, px): better by > 0.05 px {sum(x < -0.05 for x in d)}, worse by > 0.05 px "
          f"{sum(x > 0.05 for x in d)}, within 0.05 px {sum(abs(x) <= 0.05 for x in d)}; median {statistics.median(d):+.3f}")


if __name__ == "__main__":
    main()
