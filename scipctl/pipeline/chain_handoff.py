"""The chain's last step: the navcam -> hazcam handoff at a hazcam stop, from the chain's own navcam pixels
(:func:`hazcam_handoff`; ``scip`` by default, its ``p_success``/``go`` carried onto the step)."""

from __future__ import annotations

from typing import Optional

import numpy as np


def far_reference(steps: list, pos) -> Optional[tuple]:
    """``(navcam product id, pixel)`` of the chain's last verified navcam step before stop ``pos`` (None: none)."""
    for s in reversed(steps):
        if s.camera == "navcam" and s.position != pos and s.ok and s.tracked_uv is not None:
            return s.product_id, s.tracked_uv
    return None


def hazcam_handoff(dl, nav, nav_uv, haz, method, step, stereo, far=None, target_id=None,
                   setups: Optional[dict] = None):
    """The navcam -> hazcam step by ``method`` from the chain's navcam pixel ``nav_uv`` (left navcam ``nav``) into
    the left hazcam ``haz`` at the same stop; ``step``: run_chain's step builder; ``stereo(uv)``: point stereo
    in ``haz`` at a pixel (the chain's band and window).

    ``scip`` weighs the near navcam view and, when given, ``far`` = ``(navcam product, pixel)``, the chain's
    last verified navcam track at an earlier stop (as ``simulate-handoff`` weighs the near and far marks); its
    ``p_success`` and ``go`` become the step's. ``nav_uv`` None (this stop's navcam track was not verified):
    ``scip`` answers from ``far`` alone (``extra["navcam"]`` says which view it used); the chain asks only
    ``scip`` for that. Other methods answer from the near view alone (unscored).
    """
    from ..core.handoff import run_method
    from ..core.handoff.scip import SCIP
    from .handoff import build_setup, run_targets

    extra = {"method": method, "navcam": "near" if nav_uv is not None else "far",
             "reference": nav.product_id if nav_uv is not None or far is None else far[0]}
    setups = {} if setups is None else setups
    if method == SCIP:
        key = (haz.product_id, nav.product_id, None if far is None else far[0])
        if key not in setups:
            setups[key] = build_setup(dl, hazcam=key[0], near=key[1], far=key[2], shared=True)
        setup = setups[key]
        src = {"near": None if nav_uv is None else [float(x) for x in nav_uv],
               "far": None if far is None else [float(x) for x in far[1]]}
        tid = target_id or "target"
        outcomes = {}
        run_targets(dl, setup, [(tid, src, None)], methods=[SCIP], navcams=tuple(setup.cases), only=set(),
                    scip_outcomes=outcomes)
        out = outcomes.get(tid)
        res = out.result if out is not None else None
        if res is None:
            return step(haz, "handoff", None, None, None, ok=False, reason="scip: no navcam view", extra=extra)
        extra.update({"navcam": res.navcam, "far_reference": None if far is None else far[0],
                      "scip_chosen": res.diagnostics.get("chosen"), "go_min_p": res.diagnostics.get("go_min_p")})
        p_success, go = out.p_success, bool(out.go)
    else:
        if nav_uv is None:
            raise ValueError(f"hazcam_handoff: {method} needs the near navcam pixel (only scip answers from far alone)")
        key = (haz.product_id, nav.product_id, None)
        if key not in setups:
            setups[key] = build_setup(dl, hazcam=key[0], near=key[1], shared=True)
        res = run_method(setups[key].cases["near"], method, nav_uv)
        p_success, go = None, False
    uv = res.uv if res.uv is not None and np.all(np.isfinite(res.uv)) else None
    ps = stereo(uv) if uv is not None else None
    s = step(haz, "handoff", None, uv, ps, res.diagnostics.get("ncc_peak"), ok=uv is not None,
             reason=res.reason, extra=extra)
    s.p_success, s.go = p_success, go and uv is not None
    return s
