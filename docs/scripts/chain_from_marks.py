"""Chains from each target's exact mark (a measurement aid for docs/stereo-and-tracking.md, simulated downlinks).

    PYTHONPATH=. .venv/bin/python docs/scripts/chain_from_marks.py [--pancam-only] DOWNLINK... > OUT.jsonl

For every downlink with hazcam images: the whole chain from each target's mark in the first left pancam image,
and a short chain from its mark in each left navcam image before the last hazcam stop (``run_chain`` defaults,
``handoff_at="last"``); ``--pancam-only``: the whole chains alone. One JSON row per chain: ``dl`` (parent folder/file), ``t``, ``start`` (camera),
``start_pos``, ``steps`` = per step ``[camera, kind, position, error_px, ok, go]`` (or ``error``). Compare two
such files with ``docs/scripts/chain_marks_compare.py``.
"""
import json
import sys

from scipctl.io.downlink import read_downlink
from scipctl.pipeline.chain import run_chain


def main():
    pancam_only = "--pancam-only" in sys.argv[1:]
    for path in [a for a in sys.argv[1:] if a != "--pancam-only"]:
        dl = read_downlink(path)
        lefts = sorted((im for im in dl.images if im.eye == "left"), key=lambda i: i.time_s)
        haz = [im for im in lefts if im.camera == "hazcam"]
        if not haz:
            continue
        starts = [im for im in lefts if im.camera == "pancam"][:1]
        if not pancam_only:
            starts += [im for im in lefts if im.camera == "navcam" and im.position != haz[-1].position]
        setups = {}
        for st in starts:
            for t in dl.targets:
                mk = t.mark_in(st.product_id)
                if mk is None:
                    continue
                row = {"dl": "/".join(str(path).split("/")[-2:]), "t": t.id, "start": st.camera,
                       "start_pos": list(st.position)}
                try:
                    steps = run_chain(dl, st, [mk.u, mk.v], target_id=t.id, handoff_at="last", setups=setups)
                    row["steps"] = [[s.camera, s.kind, list(s.position), s.error_px, s.ok, s.go] for s in steps]
                except Exception as e:  # a measurement aid: record and go on
                    row["error"] = repr(e)
                print(json.dumps(row), flush=True)


if __name__ == "__main__":
    main()
