"""``scip``'s geometry veto (``ScipParams.geometry_veto_px``) on an evidence table, leave one family out.

    python docs/scripts/scip_veto_check.py [TABLE.jsonl[.gz] ...]     (default: tests/data/trust/evidence-20dl-11fam.jsonl.gz)

Per family held out, a model with the packaged feature set is fitted on the other families (as ``fit-trust``'s
held-out tables are); each target's answer is the most probable candidate; GO at the packaged model's 4 px
threshold, then with the veto. Prints GO / false GO with and without it, how many right (<= 4 px) answers
the veto turns NO-GO, and the largest ``geo_best_nav_res_px`` of any candidate within 4 px (the veto's margin).
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from scipctl.core.handoff.evidence import Evidence
from scipctl.core.handoff.scip_params import ScipParams
from scipctl.io.trust_model import load_packaged_trust_model
from scipctl.pipeline import trust_fit as F

R_PX = 4.0


def read(paths):
    from scipctl.commands.trust import read_rows  # the CLI's reader (gzip or not; skips a table's header line)

    return [r for r in read_rows(paths) if r.error_px is not None]


def main(argv):
    paths = argv or [str(Path(__file__).resolve().parents[2] / "tests/data/trust/evidence-20dl-11fam.jsonl.gz")]
    rows = read(paths)
    veto = ScipParams().geometry_veto_px
    go_min = load_packaged_trust_model().go_threshold(R_PX)
    n = go0 = go1 = fgo0 = fgo1 = lost = 0
    for fam in F.families_of(rows):
        m = F.fit_raw_model([r for r in rows if r.family != fam], (R_PX,))
        for _, rs in sorted(F.targets_of([r for r in rows if r.family == fam]).items()):
            ev = [Evidence.from_dict(r.evidence) for r in rs]
            p = m.probability(ev, R_PX)
            i = int(np.argmax(p))
            g0 = p[i] >= go_min
            g1 = g0 and not ev[i].geo_best_nav_res_px > veto
            right = rs[i].error_px <= R_PX
            n += 1
            go0 += g0
            go1 += g1
            fgo0 += g0 and not right
            fgo1 += g1 and not right
            lost += g0 and not g1 and right
    res = [Evidence.from_dict(r.evidence).geo_best_nav_res_px for r in rows if r.error_px <= R_PX]
    res = [v for v in res if np.isfinite(v)]
    print(f"{len(rows)} candidates, {n} targets; GO at {go_min}, veto {veto} px")
    print(f"held out: GO {go0} (false {fgo0}) without the veto, {go1} (false {fgo1}) with it; "
          f"right answers vetoed: {lost}")
    print(f"largest geo_best_nav_res_px of a candidate within {R_PX:g} px: {max(res):.1f} px")


if __name__ == "__main__":
    main(sys.argv[1:])
