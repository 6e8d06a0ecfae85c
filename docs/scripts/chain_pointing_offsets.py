"""Chain steps of campaign folders: pointing offset (mark - pose-estimate prediction, max(|du|,|dv|)) against the step
being within 4 px, split at the chain's NCC search radius (pancam 300, navcam 100 px). docs/sequence.md.

    python docs/scripts/chain_pointing_offsets.py CAMPAIGN [CAMPAIGN ...]
"""
import json, glob, collections, sys
import numpy as np
from scipctl.pipeline.chain import ChainParams

R = ChainParams().search_radius_px
acc = collections.defaultdict(list)
for d in sys.argv[1:]:
    for f in glob.glob(d + "/records/*.jsonl"):
        for l in open(f):
            r = json.loads(l)
            if r["kind"] != "chain": continue
            for s in r["record"]["steps"]:
                if s.get("predicted_uv") is None or s.get("mark_uv") is None: continue
                off = float(np.abs(np.subtract(s["mark_uv"], s["predicted_uv"])).max())
                acc[(s["kind"], s["camera"])].append((off, s["error_px"] is not None and s["error_px"] <= 4))
print("| step | n | offset p50 / p90 px | within 4 px, offset <= radius | within 4 px, offset > radius |")
print("| --- | --- | --- | --- | --- |")
for k, v in sorted(acc.items()):
    o = np.array([a for a, _ in v]); ok = np.array([b for _, b in v]); rad = ChainParams().search_radius(k[1])
    a, b = o <= rad, o > rad
    print(f"| {k[0]} {k[1]} (radius {rad:g} px) | {len(v)} | {np.median(o):.0f} / {np.percentile(o, 90):.0f} | "
          f"{ok[a].sum()} of {a.sum()} ({100 * ok[a].mean():.0f} %) | "
          + (f"{ok[b].sum()} of {b.sum()} ({100 * ok[b].mean():.0f} %) |" if b.any() else "- |"))
