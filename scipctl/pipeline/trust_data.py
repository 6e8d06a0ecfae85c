"""The evidence table of ``scip``'s trust model: one row per candidate answer of every marked target of a
downlink, with its evidence and its true error (docs/handoff.md, "Trust: scip").

Any downlink with marks in the hazcam works (the simulator's, or a real one marked by hand): the table is made
by the same code path ``simulate-handoff`` runs (:func:`~scipctl.pipeline.handoff.run_targets` with ``scip``),
so the evidence a model is fitted on is the evidence it is evaluated on.

A target known to be hidden from the hazcam (``occluded``: the simulator's ``occluded_targets``, or a real case
an operator saw) has no right answer: its rows are ``occluded`` with no error, and the fit counts them wrong at
every radius.
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
    when the target has no hazcam mark). ``group``: the downlink (rows of one downlink are split together).
    ``occluded``: the target is hidden from the hazcam, so the answer is wrong whatever its pixel."""

    family: str
    group: str
    target: str
    kind: str
    uv: list
    sources: list  # ["method/navcam", ...]
    evidence: dict  # Evidence.to_dict()
    error_px: Optional[float]
    meta: dict  # seed, run, scenario... as known
    occluded: bool = False

    def to_dict(self) -> dict:
        d = dict(self.__dict__)
        if not self.occluded:  # the tables written before the flag existed stay byte for byte the same
            del d["occluded"]
        return d

    def is_right(self, success_px: float) -> bool:
        """Within ``success_px`` of the truth (an occluded target's answer never is)."""
        return (not self.occluded) and self.error_px is not None and self.error_px <= success_px

    @classmethod
    def from_dict(cls, d: dict) -> "EvidenceRow":
        return cls(str(d["family"]), str(d["group"]), str(d["target"]), str(d.get("kind", "")), list(d["uv"]),
                   [str(s) for s in d["sources"]], dict(d["evidence"]),
                   None if d.get("error_px") is None else float(d["error_px"]), dict(d.get("meta", {})),
                   bool(d.get("occluded", False)))


class OccludedTargetError(ValueError):
    """An id given as an occluded target is not one the downlink can have as such."""


def evidence_rows(dl: Downlink, name: str, family: str, meta: Optional[dict] = None,
                  params: Optional[HandoffParams] = None, progress=None, occluded_ids=()) -> list[EvidenceRow]:
    """Every candidate of every target of ``dl`` marked in its hazcam, near and far navcams together, and of
    every target of ``occluded_ids`` (hidden from the hazcam: rows ``occluded``, ``error_px`` None).

    Raises :class:`OccludedTargetError` when an id of ``occluded_ids`` is not a target of ``dl`` or has a mark in
    the hazcam."""
    from .handoff import build_setup, marked_targets, run_targets

    setup = build_setup(dl, params)
    occluded = set(occluded_ids)
    every = marked_targets(dl, setup)
    known = {t[0]: t for t in every}
    for tid in sorted(occluded):
        if tid not in known:
            raise OccludedTargetError(f"occluded target {tid!r} is not a target of the downlink")
        if known[tid][2] is not None:
            raise OccludedTargetError(f"occluded target {tid!r} has a mark in the hazcam {setup.hazcam.product_id}")
    targets = [t for t in every if t[2] is not None or t[0] in occluded]
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
            err = None if truth is None else float(math.hypot(uv[0] - truth[0], uv[1] - truth[1]))
            rows.append(EvidenceRow(family, name, target_id, kinds.get(target_id, ""), [float(uv[0]), float(uv[1])],
                                    [f"{m}/{nc}" for m, nc in s.candidate.sources], s.evidence.to_dict(), err,
                                    dict(meta or {}), target_id in occluded))
    return rows
