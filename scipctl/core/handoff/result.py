"""What a handoff method returns (:class:`MethodResult`), how it says it has no answer (:class:`NoAnswer`),
and the diagnostics shared by several methods."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Optional

import numpy as np

from ...jsonutil import finite_or_none


@dataclass
class MethodResult:
    """One method's answer for one navcam target.

    ``method`` and ``navcam`` are filled in by :func:`~scipctl.core.handoff.registry.run_method` (a method
    function returns them empty); ``seconds`` is its wall time.
    """

    method: str
    navcam: str  # "near" | "far"
    ok: bool
    uv: Optional[np.ndarray]  # (2,) predicted hazcam-left pixel, None when the method gave no answer
    reason: str = ""
    diagnostics: dict = field(default_factory=dict)
    seconds: float = 0.0

    def copy(self) -> "MethodResult":
        """A copy whose ``uv`` and top-level ``diagnostics`` can be changed without changing this one."""
        return MethodResult(self.method, self.navcam, self.ok, None if self.uv is None else self.uv.copy(),
                            self.reason, dict(self.diagnostics), self.seconds)


def answer(uv, diagnostics: dict, ok: bool = True) -> MethodResult:
    """A method's answer: hazcam-left pixel ``uv`` (2,) (``method`` and ``navcam`` filled in by the caller)."""
    return MethodResult("", "", ok, uv, diagnostics=diagnostics)


class NoAnswer(Exception):
    """Raised by a method (or a step it uses) that has no answer: the message is the reason;
    :func:`~scipctl.core.handoff.registry.run_method` turns it into a failed :class:`MethodResult`."""

    def __init__(self, msg, diagnostics=None):
        super().__init__(msg)
        self.diagnostics = diagnostics or {}


f = finite_or_none


def track_diag(tr) -> dict:
    """Diagnostics of an NCC track (:func:`~scipctl.core.tracking.track` result)."""
    return {"ncc_peak": f(tr.score), "ncc_ratio": f(tr.ratio), "ncc_sharpness": f(tr.sharpness),
            "track_ok": bool(tr.ok), "track_reason": tr.reason}


def reg_diag(reg) -> dict:
    """Diagnostics of a cloud registration (:class:`~scipctl.core.registration.RegistrationResult`)."""
    return {"icp_fitness": reg.fitness, "icp_rmse_m": reg.inlier_rmse_m, "icp_points": reg.n_source,
            "icp_correction_deg": float(np.degrees(reg.correction_rad)), "icp_correction_m": reg.correction_m,
            "icp_kept_seed": reg.kept_seed}
