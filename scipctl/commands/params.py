"""The parameters each command runs with, built in one place from its options.

The defaults live beside their algorithms (``core.point_stereo.PointStereoParams``,
``core.handoff.HandoffParams``, ``pipeline.predict.PredictParams``, ``pipeline.report_data.ReportParams``);
these functions turn the command-line options into those objects, checking the options first
(:class:`InputError` naming the option). Heavy modules are imported inside the functions.
"""

from __future__ import annotations

import math
from typing import Optional

from ..errors import InputError


def _positive(option: str, field: str, v: float, what: str = "a positive finite number") -> None:
    if not (math.isfinite(v) and v > 0):
        raise InputError(option, field, f"must be {what}, got {v}")


def designation_params(band_px: Optional[float] = None):
    """``scipctl designate``: :class:`~scipctl.core.point_stereo.PointStereoParams`, with ``--band-px`` (if given)
    as the band of every camera."""
    from ..core.point_stereo import PointStereoParams

    if band_px is None:
        return PointStereoParams()
    _positive("--band-px", "band_px", band_px)
    return PointStereoParams.with_band(band_px)


def handoff_params(fast: bool = False, success_px: float = 4.0, trust_model=None):
    """``scipctl simulate-handoff``: :class:`~scipctl.core.handoff.HandoffParams` (``--fast``: half-resolution
    shared dense stereo; ``--success-px``: the radius scip's P(success) is for; ``--trust-model FILE``: scip's
    fitted model, None for the packaged one, read by :func:`scipctl.io.trust_model.load_trust_model`)."""
    from ..core.handoff import HandoffParams
    from ..core.handoff.scip_params import ScipParams

    model = None
    if trust_model is not None:  # else the packaged one (pipeline.handoff.build_setup)
        from ..io.trust_model import load_trust_model

        model = load_trust_model(trust_model)
    return HandoffParams(dense_downsample=2 if fast else 1,
                         scip=ScipParams(model=model, success_px=float(success_px))).check()


def success_threshold(success_px: float) -> float:
    """``--success-px``: a handoff within this many hazcam pixels of the truth is a success."""
    _positive("--success-px", "success_px", success_px)
    return float(success_px)


def predict_params(sigma_position_m: Optional[float] = None, sigma_yaw_deg: Optional[float] = None):
    """``scipctl sequence``: :class:`~scipctl.pipeline.predict.PredictParams` with the operator's pose-error sigmas
    (``--sigma-position-m``, ``--sigma-yaw-deg``; None: from the downlink)."""
    from ..pipeline.operator_sigmas import uncertainty_params

    return uncertainty_params(sigma_position_m, sigma_yaw_deg).check()


def rule_set(rules_path=None, rule_options: Optional[dict] = None, sigma_position_m: Optional[float] = None,
             sigma_yaw_deg: Optional[float] = None, dl=None):
    """``scipctl sequence`` / ``report``: the :class:`~scipctl.pipeline.rules.RuleSet` (flight rules and
    :class:`~scipctl.pipeline.predict.PredictParams`) from the rules file ``--rules`` (a file or a built-in name;
    None: the built-in chosen for the downlink ``dl`` by :func:`~scipctl.pipeline.rules.rules_for_downlink`, or
    the package default without ``dl``), overridden by the options ``rule_options`` (``{option: value}``,
    :data:`scipctl.pipeline.rules.OPTIONS`) and the operator's pose-error sigmas (``--sigma-position-m``,
    ``--sigma-yaw-deg``; None: from the downlink)."""
    from ..pipeline.rules import load_rules, rules_for_downlink

    predict_params(sigma_position_m, sigma_yaw_deg)  # the options' own checks (positive numbers)
    chosen_by = ""
    if rules_path is None and dl is not None:
        rules_path, reason = rules_for_downlink(dl)
        chosen_by = f"not given; {reason}"
    return load_rules(rules_path, {**(rule_options or {}), "--sigma-position-m": sigma_position_m,
                                   "--sigma-yaw-deg": sigma_yaw_deg}, chosen_by=chosen_by)


def report_params(sigma_position_m: Optional[float] = None, sigma_yaw_deg: Optional[float] = None, rules=None):
    """``scipctl report``: :class:`~scipctl.pipeline.report_data.ReportParams` with the operator's pose-error
    sigmas for its predictions and, given ``rules`` (a :class:`~scipctl.pipeline.rules.RuleSet`, :func:`rule_set`),
    its prediction parameters."""
    from ..pipeline.report_data import ReportParams

    unc = predict_params(sigma_position_m, sigma_yaw_deg).uncertainty
    return ReportParams(sigma_position_m=unc.sigma_position_m, sigma_yaw_rad=unc.sigma_yaw_rad,
                        predict=None if rules is None else rules.predict).check()
