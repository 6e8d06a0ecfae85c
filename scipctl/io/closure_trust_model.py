"""Reading and writing the chain's closure trust model (JSON <-> :class:`~scipctl.core.closure_trust.ClosureTrustModel`).

The packaged model is ``scipctl/data/closure_trust_model.json`` (package data; made by
``docs/scripts/fit_closure_trust.py``, docs/stereo-and-tracking.md "Closure as the answer"), read without executing
anything, as the step and ``scip`` models are.
"""

from __future__ import annotations

from typing import Optional

from ..core.closure_trust import ClosureTrustModel
from .trust_model import load_packaged_model, model_from_text, trust_model_json

PACKAGED = "closure_trust_model.json"


def closure_trust_model_from_text(text: str, source: str) -> ClosureTrustModel:
    """Parse a closure trust model; :class:`InputError` naming ``source`` when it is not one."""
    return model_from_text(ClosureTrustModel, text, source, "closure trust model")


def load_packaged_closure_trust_model() -> Optional[ClosureTrustModel]:
    """The packaged closure trust model, or None when the package has none."""
    return load_packaged_model(PACKAGED, ClosureTrustModel, "closure trust model")


def closure_trust_model_json(model: ClosureTrustModel) -> str:
    """Deterministic JSON text of ``model`` (same model, same bytes)."""
    return trust_model_json(model)
