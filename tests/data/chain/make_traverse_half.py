"""Regenerate traverse-s1-straight-half.mcap (see tests/data/README.md): the simulator's traverse s1-straight run,
seed 1, default errors, every camera at half size (512 x 512), no supersampling.

    .venv/bin/python tests/data/chain/make_traverse_half.py tests/data/chain/traverse-s1-straight-half.mcap
"""

import sys

from scipctl.io.downlink import write_downlink
from scipctl.sim.build import build_run

if __name__ == "__main__":
    sim = build_run("traverse", "s1-straight", 1, image_scale=0.5, supersample=1)
    write_downlink(sim.downlink, sys.argv[1])
