"""Where the prediction's terrain hides a target from the last (hazcam) stop of the downlink's route: the range of
the nominal left-hazcam line of sight to the target's surface point, and how far in front of it the terrain is hit
(docs/sequence.md, "The prediction scored on the route that was driven").

    python docs/scripts/prediction_occlusion_check.py DOWNLINK.mcap:TARGET [DOWNLINK.mcap:TARGET ...]
"""

from __future__ import annotations

import sys
from dataclasses import replace

import numpy as np


def main(argv=None) -> None:
    from scipctl.io.downlink import read_downlink
    from scipctl.pipeline.predict import resolve_target
    from scipctl.pipeline.predict.params import PredictParams
    from scipctl.pipeline.predict.prediction import predict_target

    for spec in (argv if argv is not None else sys.argv[1:]):
        path, tid = spec.rsplit(":", 1)
        dl = read_downlink(path)
        rec, now = resolve_target(dl, tid, None)
        pred = predict_target(dl, rec, replace(PredictParams(), route="downlink"), designated_now=now,
                              render_views=False)
        Xs = pred.surface_point_site
        st = pred.plan.stops[-1]
        m = dl.rover_config.camera_model("hazcam", "left", 0.0, 0.0).transformed(st.T_site_rover)
        v = Xs - m.C
        d = float(np.linalg.norm(v))
        h = pred.terrain.cast(m.C[None], (v / d)[None])
        short = d - float(h.t_m[0]) if h.hit[0] else None
        print(f"{spec}: range {d:.2f} m, terrain hit {'none' if short is None else f'{100 * short:.1f} cm in front of the target'}, "
              f"designation incidence {rec.incidence_deg:.0f} deg")


if __name__ == "__main__":
    main()
