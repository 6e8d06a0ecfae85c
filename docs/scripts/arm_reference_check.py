"""Per approach, where the arm check stands: the planned standoff to the designated point, the designation ray's
point on today's terrain (the prediction's truth), and the Monte Carlo's P inside the arm workspace
(docs/sequence.md, "Mars 2020 rules", issue #15).

    PYTHONPATH=CODE python docs/scripts/arm_reference_check.py OUT.jsonl DOWNLINK.mcap [DOWNLINK.mcap ...]

Targets t1-t3 of each downlink, predicted as ``scipctl sequence DOWNLINK --target tN`` does (the rules chosen
from the downlink). One JSON line per approach: ``standoff_m`` (designated point, planned final rover frame),
``surface_point_standoff_m`` (the terrain point, same frame), ``offset_3d_m``, ``p_arm``, ``p_geom``,
``confidence``, ``arm_r_max_m``, ``arm_xy_median`` (median distance of the per-sample arm point, when the
Monte Carlo records it), ``broken`` (blocking rules), ``notes``.
"""

import json
import sys

import numpy as np


def main(argv) -> int:
    from scipctl.commands.params import rule_set as load_rule_set
    from scipctl.io.workspace import open_source
    from scipctl.pipeline.target_sequence import make_sequence

    if len(argv) < 2:
        sys.exit(__doc__)
    with open(argv[0], "w") as out:
        for f in argv[1:]:
            for t in ("t1", "t2", "t3"):
                src = open_source(f)
                rs = load_rule_set(None, None, None, None, dl=src.downlink)
                _, checks, pred, _ = make_sequence(src, t, params=rs.predict, rules=rs.flight,
                                                   rules_used=rs.to_dict(), render_views=False)
                plan = pred.plan
                D = np.asarray(plan.target_site_m)
                Xs = np.asarray(pred.surface_point_site)
                T_rover_site = plan.final.T_site_rover.inverse()
                xy = getattr(pred.mc, "final_xy_rover_m", None)
                row = {"scene": f.split("/")[-1][:-5], "target": t,
                       "standoff_m": float(np.hypot(*T_rover_site.apply(D)[:2])),
                       "surface_point_standoff_m": float(np.hypot(*T_rover_site.apply(Xs)[:2])),
                       "offset_3d_m": float(np.linalg.norm(Xs - D)), "p_arm": pred.mc.p_arm_workspace,
                       "p_geom": pred.mc.p_success_geometry, "confidence": pred.confidence,
                       "arm_r_max_m": plan.params.arm.r_max_m,
                       "arm_xy_median": None if xy is None else [float(np.median(np.hypot(*xy.T)))],
                       "broken": [c.rule for c in checks if not c.ok and c.blocking], "notes": pred.notes}
                print(json.dumps(row), file=out, flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
