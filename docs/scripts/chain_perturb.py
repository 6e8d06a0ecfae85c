"""The bundled sols' chains (run_chain defaults) as they are and under the perturbations of
tests/pipeline/chain_expected.py (designation +0.01 px and (-0.007, +0.007) px, +-1 DN seeded noise): every
step's error and the hazcam step's p_success/go, printed and written to OUT.json.

    PYTHONPATH=. .venv/bin/python docs/scripts/chain_perturb.py OUT.json [closure|handoff]

The second argument is ChainParams.answer (default: the chain's default, closure); EXPECTED_ERROR_PX is measured
with ``handoff`` (every step of the tracking chain), EXPECTED_FINAL_PX with the default.
"""
import json, sys
from pathlib import Path
import numpy as np
from scipctl.io.downlink import read_downlink
from scipctl.pipeline.chain import ChainParams, run_chain
ROOT = Path(__file__).resolve().parents[2]
CASES = {"paper-s1-straight": ["t1", "t2"], "paper-s1-arc": ["t1"]}
out = {}
params = ChainParams(answer=sys.argv[2]) if len(sys.argv) > 2 else ChainParams()
for sol, tids in CASES.items():
    for label in ("base", "d+0.01", "d-0.007+0.007", "1dn"):
        dl = read_downlink(ROOT / "sample_sols/mcap" / f"{sol}.mcap")
        off = {"d+0.01": (0.01, 0.0), "d-0.007+0.007": (-0.007, 0.007)}.get(label, (0.0, 0.0))
        if label == "1dn":
            rng = np.random.default_rng(1)
            for im in dl.images:
                px = im.pixels
                top = np.iinfo(px.dtype).max
                im._pixels = np.clip(px.astype(np.int64) + rng.integers(-1, 2, px.shape), 0, top).astype(px.dtype)
        start = min((im for im in dl.images if im.camera == "pancam" and im.eye == "left"), key=lambda i: i.time_s)
        for tid in tids:
            mk = dl.target(tid).mark_in(start.product_id)
            steps = run_chain(dl, start, np.array([mk.u, mk.v]) + np.asarray(off), target_id=tid, params=params)
            row = [None if s.error_px is None else round(s.error_px, 3) for s in steps[1:]]
            out.setdefault(f"{sol}/{tid}", {})[label] = {"errors": row, "haz_p": steps[-1].p_success, "haz_go": steps[-1].go,
                                                         "kinds": [f"{s.camera}-{s.kind}" for s in steps[1:]]}
            print(sol, tid, label, row, steps[-1].p_success, steps[-1].go, flush=True)
json.dump(out, open(sys.argv[1], "w"), indent=1)
