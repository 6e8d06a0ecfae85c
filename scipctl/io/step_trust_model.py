"""Reading and writing the chain's step trust model (JSON <-> :class:`~scipctl.core.step_trust.StepTrustModel`).

The packaged model is ``scipctl/data/step_trust_model.json`` (package data; made by
``scripts/fit_step_trust.py``, docs/stereo-and-tracking.md "Trust along the chain"): data with its provenance,
read without executing anything, as ``trust_model.json`` is for ``scip``.
"""

from __future__ import annotations

import json
from importlib import resources
from typing import Optional

from ..core.step_trust import StepTrustModel
from ..errors import InputError

PACKAGED = "step_trust_model.json"


def step_trust_model_from_text(text: str, source: str) -> StepTrustModel:
    """Parse a step trust model; :class:`InputError` naming ``source`` when it is not one."""
    try:
        return StepTrustModel.from_dict(json.loads(text))
    except (ValueError, AttributeError) as e:
        raise InputError(source, "step trust model", str(e)) from None


def load_packaged_step_trust_model() -> Optional[StepTrustModel]:
    """The packaged step trust model, or None when the package has none."""
    ref = resources.files("scipctl.data").joinpath(PACKAGED)
    if not ref.is_file():
        return None
    return step_trust_model_from_text(ref.read_text(encoding="utf-8"), f"scipctl/data/{PACKAGED}")


def step_trust_model_json(model: StepTrustModel) -> str:
    """Deterministic JSON text of ``model`` (same model, same bytes)."""
    return json.dumps(model.to_dict(), indent=1, sort_keys=True, allow_nan=False) + "\n"
