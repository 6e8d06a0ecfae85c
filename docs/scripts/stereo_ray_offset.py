"""How far the chain's stereo point sits off the tracked pixel's ray (a measurement aid for
docs/stereo-and-tracking.md, simulated downlinks with marks).

    PYTHONPATH=. .venv/bin/python docs/scripts/stereo_ray_offset.py DOWNLINK...

For every left pancam/navcam image and marked target: point stereo at the mark with the chain's settings, and the
stereo point (the midpoint of the left and right rays' closest approach) projected back into the left image;
printed: projection - mark (px) and the range.
"""
import sys

import numpy as np

from scipctl.io.downlink import read_downlink
from scipctl.pipeline.chain import ChainParams, stereo_at


def main():
    params = ChainParams().check()
    for path in sys.argv[1:]:
        dl = read_downlink(path)
        for im in dl.images:
            if im.eye != "left" or im.camera == "hazcam":
                continue
            for t in dl.targets:
                mk = t.mark_in(im.product_id)
                ps = None if mk is None else stereo_at(dl, im, [mk.u, mk.v], params)
                if ps is None or not ps.ok:
                    continue
                uv = im.camera_model.project(np.asarray(ps.xyz, float)[None])[0]
                print("/".join(str(path).split("/")[-2:]), im.camera, im.position, t.id,
                      "projection-mark", np.round(uv - [mk.u, mk.v], 2).tolist(), "range_m", round(ps.range_m, 2))


if __name__ == "__main__":
    main()
