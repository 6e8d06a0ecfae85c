"""Combined handoff methods: answers of several methods put together (pure numerics).

``method(case, nav_uv, params, *, near_hint=None) -> MethodResult``; ``nav_uv`` (2,) is the navcam-left
pixel, the answer the hazcam-left pixel (2,).
"""

from __future__ import annotations

from typing import Optional

import numpy as np

from .case import HandoffCase
from .geometric import coarse_fine_geometric, pure_geometric, refined_geometric
from .kinematic import refined_kinematic
from .params import HandoffParams
from .result import MethodResult, answer
from .run import call_method

# consensus candidates, in the order they run
CONSENSUS_CANDIDATES = (
    ("coarse-fine-geometric", coarse_fine_geometric),
    ("refined-geometric", refined_geometric),
    ("refined-kinematic", refined_kinematic),
)


def consensus(case: HandoffCase, nav_uv, params: HandoffParams, *,
              near_hint: Optional[MethodResult] = None) -> MethodResult:
    """Beyond the paper: failure detection from expected images built in different ways.

    Of :data:`CONSENSUS_CANDIDATES` (run with ``near_hint``), those with NCC
    peak above ``consensus_min_score`` that agree within ``consensus_agree_px``
    (two or more; the largest group, the first found on ties): their mean,
    flagged confident; otherwise the pure-geometric answer, flagged not
    confident.
    """
    p = params
    cands = {}
    for m, fn in CONSENSUS_CANDIDATES:
        r = call_method(fn, m, case, nav_uv, p, near_hint=near_hint)
        if r.ok and r.uv is not None and np.all(np.isfinite(r.uv)):
            score = r.diagnostics.get("ncc_peak") or r.diagnostics.get("coarse_ncc_peak") or 0.0
            if score >= p.consensus_min_score:
                cands[m] = np.asarray(r.uv, float)
    diag = {"candidates": {k: v.tolist() for k, v in cands.items()}}
    best = None
    names = list(cands)
    for i in range(len(names)):
        group = [n for n in names if np.linalg.norm(cands[n] - cands[names[i]]) <= p.consensus_agree_px]
        if len(group) >= 2 and (best is None or len(group) > len(best)):
            best = group
    if best:
        diag["agreeing"] = best
        diag["confident"] = True
        return answer(np.mean([cands[n] for n in best], axis=0), diag)
    pg = pure_geometric(case, nav_uv, p)
    diag["confident"] = False
    diag["fallback"] = "refined answers disagree or are weak: pure-geometric"
    return answer(pg.uv, diag)
