"""The trust model of the chain's closure answer: P(the closure pixel is within ``success_px`` hazcam pixels of the
target | the closure's own evidence) (pure numerics).

When the chain's final answer is its closure (``ChainParams.answer = "closure"``,
``scipctl/pipeline/chain_closure.py``), the answer no longer comes from ``scip``'s handoff of the navcam pixel,
so ``scip``'s probability does not describe it. The closure is described by a :class:`ClosureEvidence` (its
feature step's diagnostics, the reference it started from and that reference's own step probability, and how far
the independent handoff path landed from it). The model is one logistic regression on standardised features,
evaluated as the step model is (:func:`~scipctl.core.handoff.trust_model.logistic_probability`):

    z = clip((f(evidence) - mean) / scale, +-clip_z)   (f: the named transforms of CLOSURE_FEATURES; NaN -> fill)
    p = 1 / (1 + exp(-(coef . z + intercept)))

The packaged model is ``scipctl/data/closure_trust_model.json`` (read by ``scipctl.io.closure_trust_model``,
refitted by ``docs/scripts/fit_closure_trust.py``; docs/stereo-and-tracking.md, "Closure as the answer").
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from .handoff.trust_model import EvidenceRecord
from .logistic_model import PixelLogistic


@dataclass
class ClosureEvidence(EvidenceRecord):
    """What a closure knows about itself (NaN: unknown). ``from_pancam``: 1 when it started from the 4.5 m pancam
    image (its track, or the navcam handoff's point projected into it), 0 from the navcam handoff's image;
    ``ref_p_success``: the reference step's own probability (step model); ``handoff_px``: distance (hazcam px) from
    the closure pixel to the handoff path's answer (``closure_px``); ``path_p``: the product of the step
    probabilities along the reference's lineage (``pipeline.chain_closure.reference_lineage``), which sees the drift of
    the tracks before the reference that ``ref_p_success`` alone does not."""

    ncc_peak: float = math.nan
    local_inliers: float = math.nan
    confirmed: float = math.nan
    shift_px: float = math.nan
    scale: float = math.nan
    from_pancam: float = 0.0
    ref_p_success: float = math.nan
    handoff_px: float = math.nan
    refine_px: float = math.nan  # |NCC peak - feature position| of the winning candidate (hazcam px)
    pooled: float = math.nan  # candidates whose NCC positions agreed
    path_p: float = math.nan  # product of the step p along the reference's lineage (designation -> reference)


# feature name -> (ClosureEvidence attribute, transform of core.handoff.trust_model.transform)
CLOSURE_FEATURES: dict[str, tuple[str, str]] = {
    "ncc_peak": ("ncc_peak", "x"),
    "log_local_inliers": ("local_inliers", "log1p"),
    "log_confirmed": ("confirmed", "log1p"),
    "log_shift": ("shift_px", "log1p"),
    "log_scale": ("scale", "log"),
    "from_pancam": ("from_pancam", "x"),
    "ref_p_success": ("ref_p_success", "x"),
    "log_handoff_px": ("handoff_px", "log1p"),
    "log_refine": ("refine_px", "log1p"),
    "log_pooled": ("pooled", "log1p"),
    "log_path_p": ("path_p", "log"),
}


@dataclass
class ClosureTrustModel(PixelLogistic):
    """A fitted closure model (see the module docstring). ``features``: name -> [ClosureEvidence attribute,
    transform]; ``fill``/``mean``/``scale``/``coef``: one value per feature; ``go_min_p``: the GO threshold;
    ``success_px``: the radius (final hazcam image pixels) the probability is for. Evaluation and file form:
    :class:`~scipctl.core.logistic_model.SingleLogistic`."""

    WHAT = "closure trust model"
