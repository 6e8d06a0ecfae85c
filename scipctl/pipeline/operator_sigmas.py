"""The operator's pose-error sigmas (``--sigma-position-m``, ``--sigma-yaw-deg``) as prediction parameters."""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Optional

from ..errors import InputError


def uncertainty_params(sigma_position_m: Optional[float] = None, sigma_yaw_deg: Optional[float] = None):
    """:class:`~scipctl.pipeline.predict.PredictParams` (defaults) with the operator's pose-estimate 1-sigma errors
    per stop: ``sigma_position_m`` metres, ``sigma_yaw_deg`` degrees (None: from the downlink).

    :class:`InputError` naming the option if one is not a positive finite number.
    """
    from .predict import PredictParams

    for name, v in (("--sigma-position-m", sigma_position_m), ("--sigma-yaw-deg", sigma_yaw_deg)):
        if v is not None and not (math.isfinite(v) and v > 0):
            raise InputError(name, name.lstrip("-").replace("-", "_"), f"must be a positive number, got {v}")
    p = PredictParams()
    u = replace(p.uncertainty, sigma_position_m=sigma_position_m,
                sigma_yaw_rad=None if sigma_yaw_deg is None else math.radians(sigma_yaw_deg))
    return replace(p, uncertainty=u)
