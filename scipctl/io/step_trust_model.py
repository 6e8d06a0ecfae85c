"""Reading and writing the chain's step trust model (JSON <-> :class:`~scipctl.core.step_trust.StepTrustModel`).

The packaged model is ``scipctl/data/step_trust_model.json`` (package data; made by
``docs/scripts/fit_step_trust.py``, docs/stereo-and-tracking.md "Trust along the chain"): data with its provenance,
read without executing anything, as ``trust_model.json`` is for ``scip``.
"""

from __future__ import annotations

from typing import Optional

from ..core.step_trust import StepTrustModel
from .trust_model import load_packaged_model, model_from_text, trust_model_json

PACKAGED = "step_trust_model.json"


def step_trust_model_from_text(text: str, source: str) -> StepTrustModel:
    """Parse a step trust model; :class:`InputError` naming ``source`` when it is not one."""
    return model_from_text(StepTrustModel, text, source, "step trust model")


def load_packaged_step_trust_model() -> Optional[StepTrustModel]:
    """The packaged step trust model, or None when the package has none."""
    return load_packaged_model(PACKAGED, StepTrustModel, "step trust model")


def step_trust_model_json(model: StepTrustModel) -> str:
    """Deterministic JSON text of ``model`` (same model, same bytes)."""
    return trust_model_json(model)
