"""Keep only the near stop's navcam and hazcam pairs of a downlink (their marks and truth images too).

    python tests/data/handoff/near_only.py IN.mcap OUT.mcap

Made tests/data/handoff/m2020-1002-s3-straight-near.mcap (tests/data/README.md).
"""

import sys
from dataclasses import replace
from pathlib import Path

from scipctl.io.downlink import read_downlink, write_downlink


def main(src: str, out: str) -> None:
    dl = read_downlink(src)
    keep = {im.product_id for im in dl.images if "-near-" in im.product_id}
    targets = [replace(t, marks=[m for m in t.marks if m.product_id in keep]) for t in dl.targets]
    dl = replace(dl, images=[im for im in dl.images if im.product_id in keep], targets=targets,
                 truth_images=[ti for ti in dl.truth_images if ti.product_id in keep])
    write_downlink(dl, Path(out), "mcap")


if __name__ == "__main__":
    main(*sys.argv[1:3])
