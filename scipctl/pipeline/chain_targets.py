"""The tracking chain for every marked target of a downlink, from its first pancam stop: what
``simulate-handoff --chain`` and ``campaign`` run (:func:`run_marked_chains`); :func:`run_chain` follows one."""

from __future__ import annotations

from typing import Optional

from ..errors import InputError
from ..model import Downlink


def run_marked_chains(dl: Downlink, downlink_name: str, only: Optional[str] = None, closure: bool = False,
                      answer: Optional[str] = None, keyed: bool = False) -> list:
    """One entry per target marked in the first left pancam image (or only the target ``only``):
    ``{"downlink", "target", "steps": [ChainStep, ...], "go", "nogo_step", "advice", "why"}`` (the chain's
    verdict, :func:`~scipctl.pipeline.chain_trust.chain_verdict`), or with ``"error"`` (one line), no steps and
    ``go`` False when the chain stops on bad input. Empty when the downlink has no left pancam image. ``closure``:
    each chain also runs its closure check (``ChainParams.closure``); ``answer``: the chain's final answer
    (``ChainParams.answer``: ``closure`` or ``handoff``; None: its default). ``keyed``: each chain's entry also
    has its ``key`` (:func:`~scipctl.pipeline.chain_key.chain_key`: what a report takes it back by; None for a
    downlink without a source SHA-256)."""
    from .chain import ChainParams, run_chain
    from .chain_trust import REDESIGNATE, chain_verdict

    out = []
    starts = sorted((im for im in dl.images if im.camera == "pancam" and im.eye == "left"), key=lambda i: i.time_s)
    if not starts:
        return out
    start = starts[0]
    setups = {}  # the hazcam handoffs' setups, shared by the targets (same products, same answers)
    features = {}  # the feature step's keypoints of each image, likewise
    for t in dl.targets:
        if only and t.id != only:
            continue
        mk = t.mark_in(start.product_id)
        if mk is None:
            continue
        params = ChainParams(closure=closure, **({} if answer is None else {"answer": answer}))
        try:
            steps = run_chain(dl, start, [mk.u, mk.v], target_id=t.id, setups=setups, feature_cache=features,
                              params=params)
            out.append({"downlink": downlink_name, "target": t.id, "steps": steps,
                        **chain_verdict(steps).to_dict()})
            if keyed:
                from .chain_key import chain_key

                out[-1]["key"] = chain_key(dl, start.product_id, [mk.u, mk.v], t.id, params)
        except InputError as e:
            out.append({"downlink": downlink_name, "target": t.id, "error": str(e), "steps": [], "go": False,
                        "nogo_step": 0, "advice": REDESIGNATE, "why": str(e)})
    return out
