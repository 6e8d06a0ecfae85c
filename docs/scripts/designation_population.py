"""Designation population for the designation trust model (scipctl/pipeline/designation_trust.py).

    python docs/scripts/designation_population.py OUT.jsonl FAMILY=DOWNLINK.mcap [FAMILY=DOWNLINK.mcap ...]

For every marked target of every downlink, designates at its mark in the first two left pancam and navcam images
whose right image is marked too (``scipctl designate`` without the normal), and compares the point with ideal
point stereo: the two marks triangulated with the same downlinked models. One JSON row per designation with a
stereo point: family, downlink, target, product, camera, the match evidence (with the window range gap)
(:class:`~scipctl.pipeline.designation_trust.DesignationEvidence`), range, range sigma and the error in percent
of the ideal range. Rows are appended in the order given (deterministic).
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np


def rows_for(family: str, path: Path):
    from scipctl.core.triangulation import triangulate_rays
    from scipctl.io.downlink import read_downlink
    from scipctl.pipeline.designate import designate
    from scipctl.pipeline.designation_trust import DesignationEvidence

    dl = read_downlink(path)
    for t in dl.targets:
        for cam in ("pancam", "navcam"):
            lefts = sorted((im for im in dl.images if im.camera == cam and im.eye == "left"), key=lambda i: i.time_s)
            for im in lefts[:2]:
                right = dl.stereo_pair(im)
                if right is None:
                    continue
                mL, mR = t.mark_in(im.product_id), t.mark_in(right.product_id)
                if mL is None or mR is None:
                    continue
                rec = designate(dl, im, [mL.u, mL.v], target_id=t.id, with_normal=False)
                if not rec.has_position:
                    continue
                oL, dL = im.camera_model.unproject(np.array([[mL.u, mL.v]]))
                oR, dR = right.camera_model.unproject(np.array([[mR.u, mR.v]]))
                X_ideal_rover = triangulate_rays(oL[0], dL[0], oR[0], dR[0])[0]
                r_ideal = float(np.linalg.norm(X_ideal_rover - im.camera_model.C))
                err = float(np.linalg.norm(np.asarray(rec.xyz_rover_m) - X_ideal_rover))
                yield {"family": family, "downlink": f"{path.parent.name}/{path.name}", "target": t.id, "product_id": im.product_id,
                       "camera": cam, "evidence": DesignationEvidence.of(rec).to_dict(), "range_m": rec.range_m,
                       "range_sigma_m": rec.range_sigma_m, "range_ideal_m": r_ideal, "error_pct": 100.0 * err / r_ideal}


def main(argv):
    out = Path(argv[0])
    with out.open("a") as f:
        for arg in argv[1:]:
            family, _, path = arg.partition("=")
            for row in rows_for(family, Path(path)):
                f.write(json.dumps(row, sort_keys=True) + "\n")


if __name__ == "__main__":
    main(sys.argv[1:])
