"""What a campaign runs on each downlink (:class:`CampaignOptions`), and the key that says two runs computed the same."""

from __future__ import annotations

import hashlib
import json
import math
from dataclasses import dataclass

from ..errors import InputError
from ..pipeline.chain import DEFAULT_CHAIN_ANSWER

NAVCAMS = ("near", "far")


@dataclass(frozen=True)
class CampaignOptions:
    """The work done on every downlink of a campaign.

    ``methods``: the handoff methods in run order (names from the handoff registry); ``pairs``: the
    (method, navcam) pairs to run (``--methods`` may name ``METHOD-near`` / ``METHOD-far``); ``fast``: the
    handoff's half-resolution dense stereo (``simulate-handoff --fast``); ``predict_route``: the approach the
    prediction is made for (``PredictParams.route``: ``plan``, what ``sequence`` uplinks, or ``downlink``, the
    downlink's own later stops, which its chain ran over); ``success_px``: a handoff (and a chain's
    final answer) within this many hazcam pixels of the mark is a success; ``closure``: each chain also runs its
    closure check (recorded on its final step); ``chain_answer``: the chain's final answer (``ChainParams.answer``);
    ``stereo_selfcal``: the stereo pairs the stages read (all of them with the chain) re-aligned from their own
    matches before anything runs (pipeline/stereo_selfcal.py); on by default since session 57, as in every command.
    """

    handoff: bool = True
    chain: bool = True
    predict: bool = True
    methods: tuple = ()
    pairs: tuple = ()  # ((method, navcam), ...), sorted
    success_px: float = 4.0
    fast: bool = False
    predict_route: str = "plan"  # PredictParams.route: "plan" (the planner's approach) or "downlink" (its own stops)
    closure: bool = False  # the chain's closure check (ChainParams.closure, pipeline/chain_closure.py) on every chain
    chain_answer: str = DEFAULT_CHAIN_ANSWER  # ChainParams.answer: the chain's final answer, "closure" or "handoff"
    stereo_selfcal: bool = True  # pipeline.stereo_selfcal.self_calibrate_downlink on each downlink first

    def check(self) -> "CampaignOptions":
        if not (self.handoff or self.chain or self.predict):
            raise InputError("campaign", "--no-handoff/--no-chain/--no-predict", "nothing left to run on a downlink")
        if not (isinstance(self.success_px, (int, float)) and math.isfinite(self.success_px) and self.success_px > 0):
            raise InputError("campaign", "--success-px", f"must be a positive finite number, got {self.success_px}")
        if self.closure and not self.chain:
            raise InputError("campaign", "--closure", "is a check of the chain: not with --no-chain")
        from ..pipeline.chain import CHAIN_ANSWERS

        if self.chain_answer not in CHAIN_ANSWERS:
            raise InputError("campaign", "--chain-answer", f"must be one of {', '.join(CHAIN_ANSWERS)}, "
                                                           f"got {self.chain_answer!r}")
        if self.predict_route not in ("plan", "downlink"):
            raise InputError("campaign", "--predict-route", f"must be plan or downlink, got {self.predict_route!r}")
        if self.handoff:
            if not self.methods or not self.pairs:
                raise InputError("campaign", "--methods", "no handoff method to run")
            for m, nc in self.pairs:
                if m not in self.methods or nc not in NAVCAMS:
                    raise InputError("campaign", "--methods", f"pair ({m}, {nc}) is not among the methods and navcams")
        return self

    @property
    def navcams(self) -> list:
        """The navcams in use, near first."""
        return [n for n in NAVCAMS if any(p[1] == n for p in self.pairs)]

    def to_dict(self) -> dict:
        d = {"handoff": self.handoff, "chain": self.chain, "predict": self.predict,
             "methods": list(self.methods), "pairs": [list(p) for p in self.pairs],
             "success_px": float(self.success_px), "fast": self.fast, "predict_route": self.predict_route}
        if self.closure:  # only when on: the keys of campaigns without it stay what they were
            d["closure"] = True
        if self.chain_answer != "handoff":  # likewise: campaigns before the closure answer were "handoff" ones
            d["chain_answer"] = self.chain_answer
        if self.stereo_selfcal:  # only when on: a record without it was made with the downlinked models (before
            d["stereo_selfcal"] = True  # the option, or with it off), and keeps its key
        return d

    @classmethod
    def from_dict(cls, d: dict) -> "CampaignOptions":
        return cls(bool(d["handoff"]), bool(d["chain"]), bool(d["predict"]), tuple(d["methods"]),
                   tuple(tuple(p) for p in d["pairs"]), float(d["success_px"]), bool(d["fast"]),
                   str(d.get("predict_route", "plan")), bool(d.get("closure", False)),
                   str(d.get("chain_answer", "handoff")),  # a record without it was made before the option
                   bool(d.get("stereo_selfcal", False)))  # absent: made without it (off, or before it existed)

    def key(self) -> str:
        """SHA-256 of everything here that changes an answer, and of the tool's version."""
        from .. import __version__

        text = json.dumps({"options": self.to_dict(), "version": __version__}, sort_keys=True)
        return hashlib.sha256(text.encode()).hexdigest()


def job_key(input_sha256: str, options_key: str) -> str:
    """The key of one downlink's records: its input and the options (a re-run with the same key is skipped)."""
    return hashlib.sha256(f"{input_sha256}\n{options_key}".encode()).hexdigest()
