"""A small, seeded evidence table for the trust-model tests (tests/pipeline/test_trust_fit.py,
tests/commands/test_trust_cli.py): made-up candidates whose true error depends on their evidence, in three
families, not a measurement of anything."""

from __future__ import annotations

import numpy as np

from scipctl.core.handoff.evidence import Evidence
from scipctl.pipeline.trust_data import EvidenceRow

FAMILIES = ("fa", "fb", "fc")


def small_table(n_targets_per_family: int = 30, seed: int = 7) -> list[EvidenceRow]:
    """Rows of ``3 * n_targets_per_family`` targets, 4 candidates each: the candidate's error (px) is
    exponential with a scale set by its appearance offset and forward-backward error, plus noise."""
    rng = np.random.default_rng(seed)
    rows = []
    for fam in FAMILIES:
        for t in range(n_targets_per_family):
            for k, (m, nc) in enumerate((("refined-kinematic", "near"), ("mesh-registration", "near"),
                                         ("refined-geometric", "far"), ("pure-kinematic", "far"))):
                off = float(rng.exponential(3.0 if k < 3 else 12.0))
                fb = float(abs(off + rng.normal(0, 1.0)))
                score = float(np.clip(0.9 - 0.05 * off + rng.normal(0, 0.1), -1, 1))
                err = float(abs(off + rng.normal(0, 0.8)))
                ev = Evidence(m, nc, app_near_score_at=score, app_near_offset_px=off, fb_near_error_px=fb,
                              support_groups=float(rng.integers(0, 4)),
                              app_far_score_at=float("nan") if t % 5 == 0 else score + float(rng.normal(0, 0.1)))
                rows.append(EvidenceRow(fam, f"{fam}-dl{t // 10}", f"t{t}", "extra", [0.0, 0.0], [f"{m}/{nc}"],
                                        ev.to_dict(), err, {"seed": t}))
    return rows


def write_table(path, rows) -> None:
    import json

    path.write_text("".join(json.dumps(r.to_dict(), sort_keys=True) + "\n" for r in rows))
