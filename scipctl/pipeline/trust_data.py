"""The evidence table of ``scip``'s trust model: one row per candidate answer of every marked target of a
downlink, with its evidence and its true error (docs/handoff.md, "Trust: scip").

Any downlink with marks in the hazcam works (the simulator's, or a real one marked by hand): the table is made
by the same code path ``simulate-handoff`` runs (:func:`~scipctl.pipeline.handoff.run_targets` with ``scip``),
so the evidence a model is fitted on is the evidence it is evaluated on.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Optional

from ..core.handoff import HandoffParams
from ..model import Downlink


@dataclass
class EvidenceRow:
    """One candidate answer of one target: where it came from, its evidence and its true error (hazcam px; None
    when the target has no hazcam mark). ``group``: the downlink (rows of one downlink are split together)."""

    family: str
    group: str
    target: str
    kind: str
    uv: list
    sources: list  # ["method/navcam", ...]
    evidence: dict  # Evidence.to_dict()
    error_px: Optional[float]
    meta: dict  # seed, run, scenario... as known

    def to_dict(self) -> dict:
        return dict(self.__dict__)

    @classmethod
    def from_dict(cls, d: dict) -> "EvidenceRow":
        return cls(str(d["family"]), str(d["group"]), str(d["target"]), str(d.get("kind", "")), list(d["uv"]),
                   [str(s) for s in d["sources"]], dict(d["evidence"]),
                   None if d.get("error_px") is None else float(d["error_px"]), dict(d.get("meta", {})))


def evidence_rows(dl: Downlink, name: str, family: str, meta: Optional[dict] = None,
                  params: Optional[HandoffParams] = None, progress=None) -> list[EvidenceRow]:
    """Every candidate of every target of ``dl`` marked in its hazcam, near and far navcams together."""
    from .handoff import build_setup, marked_targets, run_targets

    setup = build_setup(dl, params)
    targets = [t for t in marked_targets(dl, setup) if t[2] is not None]
    outs: dict = {}
    run_targets(dl, setup, targets, methods=["scip"], navcams=[n for n in ("near", "far") if n in setup.cases],
                downlink_name=name, scip_outcomes=outs, progress=progress)
    kinds = {t.id: t.kind for t in dl.targets}
    rows = []
    for target_id, _, truth in targets:
        out = outs.get(target_id)
        if out is None:
            continue
        for s in out.scored:
            uv = s.candidate.uv
            err = float(math.hypot(uv[0] - truth[0], uv[1] - truth[1]))
            rows.append(EvidenceRow(family, name, target_id, kinds.get(target_id, ""), [float(uv[0]), float(uv[1])],
                                    [f"{m}/{nc}" for m, nc in s.candidate.sources], s.evidence.to_dict(), err,
                                    dict(meta or {})))
    return rows
