"""Per-step signed errors of the tracking chain for one target (a measurement aid for docs/stereo-and-tracking.md).

    .venv/bin/python docs/scripts/chain_steps.py DOWNLINK TARGET [--truth] [--handoff-at every|last|first]

Runs ``run_chain`` with its defaults from the target's mark in the first left pancam image and prints, per step,
tracked - mark (px), the feature status and the 3-D error (m, true rover frame). ``--truth`` first replaces every
product's downlinked pose and camera model by the simulation truth (so only the tracking method is under test).
"""

import argparse

import numpy as np

from scipctl.io.downlink import read_downlink
from scipctl.pipeline.chain import run_chain


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("downlink")
    ap.add_argument("target")
    ap.add_argument("--truth", action="store_true")
    ap.add_argument("--handoff-at", default="every", choices=("every", "last", "first"))
    a = ap.parse_args()
    dl = read_downlink(a.downlink)
    if a.truth:
        for im in dl.images:
            tr = dl.truth_for(im.product_id)
            im.pose, im.camera_model = tr.pose, tr.camera_model
    start = min((im for im in dl.images if im.camera == "pancam" and im.eye == "left"), key=lambda i: i.time_s)
    mk = dl.target(a.target).mark_in(start.product_id)
    for s in run_chain(dl, start, [mk.u, mk.v], target_id=a.target, handoff_at=a.handoff_at):
        d = None if s.tracked_uv is None or s.mark_uv is None else np.subtract(s.tracked_uv, s.mark_uv).round(2).tolist()
        e3 = None if s.error_3d_m is None else round(s.error_3d_m, 3)
        print(s.camera, s.kind, s.position, "tracked-mark", d, "ok" if s.ok else "FLAG", s.extra.get("feature_status"),
              "3-D err", e3)


if __name__ == "__main__":
    main()
