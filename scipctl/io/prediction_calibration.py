"""Reading and writing the pre-uplink prediction's calibration (JSON <->
:class:`~scipctl.core.prediction_calibration.PredictionCalibration`).

The packaged models are ``scipctl/data/prediction_calibration_plan.json`` and ``..._downlink.json``, one per
predicted route (package data; made by ``docs/scripts/fit_prediction_calibration.py``, docs/sequence.md
"Calibrated against the chain"), read without executing anything, as the trust models are.
"""

from __future__ import annotations

from typing import Optional

from ..core.prediction_calibration import PredictionCalibration
from .trust_model import load_packaged_model, model_from_text, trust_model_json


def packaged_name(route: str) -> str:
    """The package data file of ``route``'s calibration (``plan`` or ``downlink``)."""
    return f"prediction_calibration_{route}.json"


def prediction_calibration_from_text(text: str, source: str) -> PredictionCalibration:
    """Parse a prediction calibration; :class:`InputError` naming ``source`` when it is not one."""
    return model_from_text(PredictionCalibration, text, source, "prediction calibration")


def load_packaged_prediction_calibration(route: str) -> Optional[PredictionCalibration]:
    """The packaged calibration of ``route``, or None when the package has none."""
    return load_packaged_model(packaged_name(route), PredictionCalibration, "prediction calibration")


def prediction_calibration_json(model: PredictionCalibration) -> str:
    """Deterministic JSON text of ``model`` (same model, same bytes)."""
    return trust_model_json(model)
