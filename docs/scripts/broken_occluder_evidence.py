"""The evidence table of the 5 cm occluder case of ``tests/pipeline/test_handoff_broken.py``.

    python docs/scripts/broken_occluder_evidence.py OUT.jsonl

The bundled ``paper-s1-straight`` sample with a textured disk on the left hazcam's line of sight to each target,
at the test's ``NEAR_OCCLUDER`` (range fraction, radius) and seed, broken in memory the way the test breaks it
(``tests/pipeline/broken_downlinks.py``), then ``evidence_rows`` as ``scipctl trust-evidence`` writes them (family
``broken``). Every answer for these targets is wrong (the hazcams see the disk); the table's ``error_px`` is the
distance to the hidden mark. Read by ``docs/scripts/trust_feature_variants.py`` and
``docs/scripts/trust_refit_compare.py``-style scoring (docs/handoff.md, "Occluded targets in the training data").
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # the repository root: tests.pipeline's helpers

from scipctl.io.downlink import read_downlink
from scipctl.pipeline.handoff import build_setup
from scipctl.pipeline.trust_data import evidence_rows
from tests.pipeline import broken_downlinks as B
from tests.pipeline import test_handoff_broken as T


def main(argv: list) -> None:
    if len(argv) != 1:
        sys.exit("usage: python docs/scripts/broken_occluder_evidence.py OUT.jsonl")
    dl = read_downlink(T.SAMPLE)
    base = build_setup(dl)
    range_frac, radius_m = T.NEAR_OCCLUDER
    broken = B.occluded_copy(dl, base.hazcam, [t.id for t in dl.targets], radius_m, range_frac, seed=7)
    rows = evidence_rows(broken, "occl5", "broken")
    with open(argv[0], "w", encoding="utf-8") as f:
        f.writelines(json.dumps(r.to_dict(), sort_keys=True) + "\n" for r in rows)


if __name__ == "__main__":
    main(sys.argv[1:])
