"""The trust model of the chain's tracking steps: P(a pancam/navcam step's pixel is within ``success_mm`` of the
target | the step's own diagnostics) (pure numerics).

A tracking step (pancam track, pancam -> navcam handoff, navcam track) is described by a
:class:`StepEvidence` (built from a chain step by ``scipctl.pipeline.chain_trust``). The model is one logistic
regression on standardised features of it:

    z = clip((f(evidence) - mean) / scale, +-clip_z)   (f: the named transforms of STEP_FEATURES; NaN -> fill)
    p = 1 / (1 + exp(-(coef . z + intercept)))

A step is a success when its pixel lies within ``success_mm`` of the target's mark measured across the line of
sight at the step's range (``error_px * px_mm <= success_mm``; ``px_mm``: one pixel's footprint there). The
chain carries each step's pixel to the next stop unchanged, so an error of that size arrives at the hazcam as
the same few mm: ``success_mm`` is the hazcam's success radius (4 px) at the arm's working range
(docs/stereo-and-tracking.md, "Trust along the chain"). The packaged model is
``scipctl/data/step_trust_model.json`` (read by ``scipctl.io.step_trust_model``, refitted by
``docs/scripts/fit_step_trust.py``). Evaluating it needs numpy only.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from .handoff.trust_model import EvidenceRecord
from .logistic_model import SingleLogistic

STEP_KINDS = ("pancam-track", "navcam-handoff", "navcam-track")


@dataclass
class StepEvidence(EvidenceRecord):
    """What one tracking step knows about itself (NaN: unknown). ``kind``: one of :data:`STEP_KINDS` (or another
    string: none of the kind indicators is set)."""

    kind: str = ""
    same_stop: float = 0.0  # 1: the IFOV-scaled pancam -> navcam handoff at one stop (no features)
    status_confirmed: float = 0.0  # feature_status one-hot (all 0: no feature step)
    status_unconfirmed: float = 0.0
    status_failed: float = 0.0
    ncc_peak: float = math.nan
    ncc_ratio: float = math.nan
    local_inliers: float = math.nan  # keypoint matches of the feature model within feature_local_px of the target
    inliers: float = math.nan
    confirmed: float = math.nan  # feature candidates NCC confirmed
    shift_px: float = math.nan  # |feature coarse position - pose prediction| (the pose error the step removed)
    stereo_ok: float = 0.0
    ok: float = 0.0  # the chain's own flag (not weak, not unverified, stereo found)
    follows_unverified: float = 0.0
    zoom: float = math.nan  # template scale: new pixels per previous pixel
    px_mm: float = math.nan  # one pixel's footprint at the step's range, mm
    prior_flagged: float = 0.0  # earlier tracking steps of the chain with ok False
    prior_min_ncc: float = math.nan  # lowest NCC peak of the earlier tracking steps
    prior_steps: float = 0.0  # earlier tracking steps (after the designation)
    refine_px: float = math.nan  # confirmed: |NCC peak - the feature model's position| of the winning candidate
    pooled: float = math.nan  # confirmed: how many candidates' NCC positions agreed and were pooled

    @property
    def is_pancam_track(self) -> float:
        return 1.0 if self.kind == "pancam-track" else 0.0

    @property
    def is_navcam_handoff(self) -> float:
        return 1.0 if self.kind == "navcam-handoff" else 0.0


# feature name -> (StepEvidence attribute, transform of core.handoff.trust_model.transform)
STEP_FEATURES: dict[str, tuple[str, str]] = {
    "pancam_track": ("is_pancam_track", "x"),
    "navcam_handoff": ("is_navcam_handoff", "x"),
    "same_stop": ("same_stop", "x"),
    "status_confirmed": ("status_confirmed", "x"),
    "status_unconfirmed": ("status_unconfirmed", "x"),
    "status_failed": ("status_failed", "x"),
    "ncc_peak": ("ncc_peak", "x"),
    "ncc_known": ("ncc_peak", "known"),
    "log_ncc_ratio": ("ncc_ratio", "log"),
    "log_local_inliers": ("local_inliers", "log1p"),
    "log_inliers": ("inliers", "log1p"),
    "log_confirmed": ("confirmed", "log1p"),
    "log_shift": ("shift_px", "log1p"),
    "stereo_ok": ("stereo_ok", "x"),
    "ok": ("ok", "x"),
    "follows_unverified": ("follows_unverified", "x"),
    "log_zoom": ("zoom", "log"),
    "log_px_mm": ("px_mm", "log"),
    "prior_flagged": ("prior_flagged", "x"),
    "prior_min_ncc": ("prior_min_ncc", "x"),
    "prior_steps": ("prior_steps", "x"),
    "log_refine": ("refine_px", "log1p"),
    "log_pooled": ("pooled", "log1p"),
}


@dataclass
class StepTrustModel(SingleLogistic):
    """A fitted step model (see the module docstring). ``features``: name -> [StepEvidence attribute,
    transform]; ``fill``/``mean``/``scale``/``coef``: one value per feature; ``go_min_p``: the GO threshold chosen
    on held-out families; ``success_mm``: the radius the probability is for. Evaluation and file form:
    :class:`~scipctl.core.logistic_model.SingleLogistic`."""

    RADIUS = "success_mm"
    WHAT = "step trust model"

    features: dict
    fill: list
    mean: list
    scale: list
    coef: list
    intercept: float
    go_min_p: float
    success_mm: float
    provenance: dict = field(default_factory=dict)
    clip_z: float = 5.0
