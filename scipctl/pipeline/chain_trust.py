"""Trust along the tracking chain: each step's ``p_success`` and ``go``, what to do at a NO-GO step, and the
chain's own GO (docs/stereo-and-tracking.md, "Trust along the chain").

- tracking steps (pancam track, pancam -> navcam handoff, navcam track): ``p_success`` from the step model
  (:class:`~scipctl.core.step_trust.StepTrustModel`, packaged ``scipctl/data/step_trust_model.json``) over the
  step's own diagnostics (:func:`step_evidence`), ``go`` = ``p_success >= go_min_p``; a lost step
  (no pixel) has ``p_success`` 0;
- the navcam -> hazcam handoff: ``scip``'s probability is for a handoff of the target's own navcam pixel (it was
  fitted on handoffs from the marks); the chain hands off its own navcam pixel, which may be off. So the step's
  ``p_success`` is ``scip``'s times the step model's for the navcam step whose pixel it handed off, and its ``go``
  needs both GO (:func:`score_hazcam_handoffs`; ``scip``'s own are kept in ``extra``). When the chain answers
  with its closure (``ChainParams.answer``), the final step's are the closure model's
  (:mod:`scipctl.core.closure_trust`);
- the designation: the designation trust model's, as ``scipctl designate`` gives it (``extra["designation"]``,
  set by :func:`~scipctl.pipeline.chain.run_chain`: ``p_success`` = P(the 3-D point within 1 % of the range of
  ideal point stereo), GO at that model's threshold; NO-GO advises ``re-designate``). Without it (no model, or a
  record made before it) ``p_success`` None and GO: the chain starts from what the operator designated;
- the chain is GO when every step up to the final hazcam handoff is GO and there is a final hazcam answer, or when
  its answer is an adopted closure that is GO (the closure model's p is for the answer itself and weighs its
  reference step's own p) (:func:`chain_verdict`); each NO-GO step carries ``advice`` (:data:`ADVICE`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Optional

from ..core.step_trust import StepEvidence, StepTrustModel
from .feature_track import confirmed_consistency

REDESIGNATE = "re-designate"
NEW_IMAGE = "new image at this stop"
FALL_BACK = "fall back to near navcams"
ADVICE = (REDESIGNATE, NEW_IMAGE, FALL_BACK)


def _num(v) -> float:
    return math.nan if v is None else float(v)


def step_kind(step) -> Optional[str]:
    """``pancam-track`` | ``navcam-handoff`` | ``navcam-track`` for a tracking step (None: any other step)."""
    if step.kind == "track" and step.camera in ("pancam", "navcam"):
        return f"{step.camera}-track"
    if step.kind == "handoff" and step.camera == "navcam":
        return "navcam-handoff"
    return None


def step_evidence(steps: list, i: int) -> StepEvidence:
    """The :class:`StepEvidence` of ``steps[i]`` (a :class:`~scipctl.pipeline.chain.ChainStep`), from its own
    record and the chain's earlier tracking steps."""
    s = steps[i]
    x = s.extra or {}
    status = x.get("feature_status")
    prior = [p for p in steps[:i] if step_kind(p) is not None]
    nccs = [p.ncc_peak for p in prior if p.ncc_peak is not None]
    pooled, refine_px = confirmed_consistency(x)
    return StepEvidence(
        kind=step_kind(s) or "", same_stop=1.0 if x.get("template") == "scale" else 0.0,
        status_confirmed=float(status == "confirmed"), status_unconfirmed=float(status == "unconfirmed"),
        status_failed=float(status == "failed"), ncc_peak=_num(s.ncc_peak), ncc_ratio=_num(x.get("ncc_ratio")),
        local_inliers=_num(x.get("feature_local_inliers")) if status in ("confirmed", "unconfirmed") else math.nan,
        inliers=_num(x.get("feature_inliers")) if status in ("confirmed", "unconfirmed") else math.nan,
        confirmed=_num(x.get("feature_confirmed")), shift_px=_num(x.get("feature_shift_px")),
        stereo_ok=float(s.range_m is not None), ok=float(bool(s.ok)),
        follows_unverified=float(bool(x.get("follows_unverified"))), zoom=_num(x.get("scale")),
        px_mm=_num(x.get("px_mm")), prior_flagged=float(sum(1 for p in prior if not p.ok)),
        prior_min_ncc=min(nccs) if nccs else math.nan, prior_steps=float(len(prior)),
        pooled=pooled, refine_px=refine_px)


def score_steps(steps: list, model: Optional[StepTrustModel]) -> None:
    """Set ``p_success``/``go`` of every tracking step of ``steps`` in place (None/False without a model); the
    designation's from its ``extra["designation"]`` (the designation trust model's ``p_ok`` and GO), or None and GO
    when it has none; the hazcam handoff keeps what ``scip`` gave it."""
    idx = [i for i, s in enumerate(steps) if step_kind(s) is not None]
    for s in steps:
        if s.kind == "designate":
            d = (s.extra or {}).get("designation") or {}
            s.p_success, s.go = (None, True) if d.get("p_ok") is None else (float(d["p_ok"]), bool(d.get("go")))
    if model is None:
        for i in idx:
            steps[i].p_success, steps[i].go = None, False
        for i, s in enumerate(steps):
            if s.kind == "designate":
                s.advice = None if s.go else advice_for(steps, i)
        return
    p = model.probability([step_evidence(steps, i) for i in idx])
    for i, pi in zip(idx, p):
        s = steps[i]
        if s.tracked_uv is None:
            s.p_success, s.go = 0.0, False
        else:
            s.p_success = float(pi)
            s.go = bool(pi >= model.go_min_p)
    for i, s in enumerate(steps):
        s.advice = None if s.go else advice_for(steps, i)


def handoff_input(steps: list, i: int):
    """The navcam step whose pixel the hazcam handoff ``steps[i]`` handed off (None: none found): by
    ``extra["navcam"]``, the near view's (``extra["reference"]``) or the far view's (``extra["far_reference"]``); when
    ``scip`` weighed both, the one with the higher ``p_success``. The latest earlier navcam step of that product
    with a pixel."""
    x = steps[i].extra or {}
    ids = {"near": [x.get("reference")], "far": [x.get("far_reference")],
           "both": [x.get("reference"), x.get("far_reference")]}.get(x.get("navcam"), [])
    found = []
    for pid in ids:
        s = next((s for s in reversed(steps[:i]) if s.camera == "navcam" and s.product_id == pid
                  and s.tracked_uv is not None), None)
        if s is not None:
            found.append(s)
    if not found:
        return None
    return max(found, key=lambda s: -1.0 if s.p_success is None else s.p_success)


def score_hazcam_handoffs(steps: list) -> None:
    """In place, after :func:`score_steps`: each hazcam handoff that ``scip`` scored gets ``p_success`` =
    ``scip``'s x the ``p_success`` of its input navcam step (:func:`handoff_input`), and ``go`` = ``scip``'s GO
    and that step's GO; ``scip``'s own are kept as ``extra["scip_p_success"]`` / ``extra["scip_go"]``, the input's
    as ``extra["navcam_p_success"]``. No scored input (no step model, or none found): ``p_success`` None, NO-GO.

    ``scip`` answers P(within ``success_px`` | the navcam pixel is the target's); the step model answers P(the
    navcam step within the hazcam's success radius). Their product is P(both), a lower bound of P(the answer is
    right): a handoff from a wrong navcam pixel lands on the wrong place. Measured on 74 held-out chains whose
    answer was the handoff's (docs/stereo-and-tracking.md, "The hazcam handoff's p_success is the chain's"):
    Brier 0.261 with ``scip``'s p alone, 0.174 with the product, 0.219 for the base rate."""
    for i, s in enumerate(steps):
        x = s.extra or {}
        if s.camera != "hazcam" or s.kind != "handoff" or s.p_success is None or "scip_p_success" in x:
            continue
        src = handoff_input(steps, i)
        p_nav = None if src is None else src.p_success
        x["scip_p_success"], x["scip_go"], x["navcam_p_success"] = s.p_success, bool(s.go), p_nav
        s.extra = x
        if p_nav is None:
            s.p_success, s.go = None, False
        else:
            s.p_success = float(s.p_success) * float(p_nav)
            s.go = bool(s.go and src.go)
        s.advice = None if s.go else advice_for(steps, i)


def advice_for(steps: list, i: int) -> str:
    """What the operator should do when ``steps[i]`` is NO-GO (one of :data:`ADVICE`):

    - the designation (its point stereo not trusted): ``re-designate``;
    - the hazcam handoff, or a navcam step at the hazcam's stop: the chain's pixel there cannot be trusted, but
      the near navcams see the target at arm's range: designate it there and hand off from them
      (``fall back to near navcams``);
    - the first track after the designation lost it or found no feature match the NCC confirmed: the designated
      place cannot be found again from the designation image (textureless, or not the feature the operator
      meant): ``re-designate``;
    - any other tracking step (stereo failed, a weak or unconfirmed match, a low probability): the next stop
      would inherit its error; take ``new image at this stop`` (or hand on from the last GO step's image).
    """
    s = steps[i]
    if s.kind == "designate":
        return REDESIGNATE  # its 3-D point is not trusted: the chain's predictions and planes start from it
    haz_positions = {p.position for p in steps if p.camera == "hazcam"}
    if s.camera == "hazcam" or (s.camera == "navcam" and s.position in haz_positions):
        return FALL_BACK
    first_track = next((j for j, p in enumerate(steps) if step_kind(p) is not None), None)
    status = (s.extra or {}).get("feature_status")
    if i == first_track and (s.tracked_uv is None or status in ("failed", "unconfirmed")):
        return REDESIGNATE
    return NEW_IMAGE


@dataclass
class ChainVerdict:
    """The chain's GO/NO-GO: GO when every step up to the final hazcam handoff is GO and there is one.
    ``step``: index of the first NO-GO step (None: GO, or no step NO-GO but no final answer); ``advice`` and
    ``why`` for the operator."""

    go: bool
    step: Optional[int]
    advice: Optional[str]
    why: str

    def to_dict(self) -> dict:
        return {"go": self.go, "nogo_step": self.step, "advice": self.advice, "why": self.why}


def chain_verdict(steps: list) -> ChainVerdict:
    """The :class:`ChainVerdict` of a scored chain (steps after the final hazcam handoff are not part of it; when
    the final answer is the chain's closure, ``extra["answer"] == "closure"``, neither are the steps between the
    closure's reference and the final one: the answer does not depend on them).

    A chain whose answer is an adopted closure that is GO is GO: the closure model answers P(the final pixel is
    within 4 px) from the closure's own evidence and its reference step's ``p_success``, so a reference below the
    step model's GO threshold is already weighed there (session 15: held out, the 13 closures at p >= 0.9 were all
    within 4 px; docs/stereo-and-tracking.md, "The chain's verdict follows a GO closure"). Otherwise the first
    NO-GO step decides, as for every NO-GO chain."""
    final = next((i for i, s in enumerate(steps) if s.camera == "hazcam" and s.extra.get("final")), None)
    if final is not None and steps[final].extra.get("answer") == "closure" and steps[final].go:
        return ChainVerdict(True, None, None, "")
    upto = steps if final is None else steps[: final + 1]
    skip = set()
    if final is not None and steps[final].extra.get("answer") == "closure":
        # the answer is the closure's: found from its reference step, past the navcam steps after it
        ref = (steps[final].extra.get("closure") or {}).get("reference_step")
        if isinstance(ref, int):
            skip = set(range(ref + 1, final))
    for i, s in enumerate(upto):
        if s.camera == "hazcam" and i != final:
            continue  # a handoff at an earlier hazcam stop is a side answer: the chain goes on by navcam
        if i in skip:
            continue
        if not s.go:
            p = "-" if s.p_success is None else f"{s.p_success:.2f}"
            return ChainVerdict(False, i, s.advice or advice_for(steps, i),
                                f"step {i} ({s.camera} {s.kind} at {s.position[0]}/{s.position[1]}) is NO-GO "
                                f"(p_success {p}{'; ' + s.reason if s.reason else ''})")
    if final is None:
        return ChainVerdict(False, None, FALL_BACK, "the chain has no hazcam answer (no hazcam stop reached from a "
                                                    "verified navcam reference)")
    return ChainVerdict(True, None, None, "")
