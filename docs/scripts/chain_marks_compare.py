"""Compare two outputs of docs/scripts/chain_from_marks.py (the same chains, two versions of the code).

    python docs/scripts/chain_marks_compare.py BEFORE.jsonl AFTER.jsonl

Per scene family (the downlink's parent folder) and start camera: chains, final hazcam answers within 4 px,
the final answers' median error, and the first tracking step's median error and count within 2 px (before -> after).
"""
import json
import sys

import numpy as np


def load(f):
    out = {}
    for line in open(f):
        r = json.loads(line)
        out[(r["dl"], r["t"], r["start"], tuple(r["start_pos"]))] = r
    return out


def final(r):
    h = [s for s in r.get("steps", []) if s[0] == "hazcam"]
    return h[-1][3] if h and h[-1][3] is not None else None


def first_track(r):
    for s in r.get("steps", [])[1:]:
        if s[1] == "track":
            return s[3]
    return None


def median(xs):
    xs = [x for x in xs if x is not None]
    return round(float(np.median(xs)), 2) if xs else None


def main():
    a, b = load(sys.argv[1]), load(sys.argv[2])
    keys = [k for k in a if k in b]
    fams = sorted({k[0].split("/")[0] for k in keys})
    print("| family | start | chains | final within 4 px | final median, px | first track median, px | first track within 2 px |")
    print("| --- | --- | --- | --- | --- | --- | --- |")
    for fam in fams + ["all"]:
        for start in ("pancam", "navcam"):
            ks = [k for k in keys if (fam == "all" or k[0].split("/")[0] == fam) and k[2] == start]
            if not ks:
                continue
            fa, fb = [final(a[k]) for k in ks], [final(b[k]) for k in ks]
            ta, tb = [first_track(a[k]) for k in ks], [first_track(b[k]) for k in ks]
            w4 = lambda xs: sum(1 for x in xs if x is not None and x <= 4.0)
            w2 = lambda xs: sum(1 for x in xs if x is not None and x <= 2.0)
            print(f"| {fam} | {start} | {len(ks)} | {w4(fa)} -> {w4(fb)} | {median(fa)} -> {median(fb)} | "
                  f"{median(ta)} -> {median(tb)} | {w2(ta)} -> {w2(tb)} |")


if __name__ == "__main__":
    main()
