"""Registration handoff method: the navcam cloud registered onto the hazcam cloud (pure numerics).

``method(case, nav_uv, params, *, near_hint=None) -> MethodResult`` (``near_hint`` unused); ``nav_uv`` (2,)
is the navcam-left pixel, the answer the hazcam-left pixel (2,).
"""

from __future__ import annotations

from typing import Optional

import numpy as np

from .case import HandoffCase
from .params import HandoffParams
from .result import MethodResult, NoAnswer, answer, f, reg_diag
from .steps import nav_point, project_haz


def mesh_registration(case: HandoffCase, nav_uv, params: HandoffParams, *,
                      near_hint: Optional[MethodResult] = None) -> MethodResult:
    """ICP between the navcam and hazcam clouds (the case's :meth:`~HandoffCase.whole_registration`, seeded with
    the mast kinematics for near, the pose estimate for far), then kinematic handoff of the navcam point stereo
    through the recovered transform."""
    ps = nav_point(case, nav_uv)
    reg = case.whole_registration()
    if isinstance(reg, Exception):
        raise NoAnswer(f"registration failed: {reg}")
    X = reg.T_target_source.apply(ps.xyz)
    uv = project_haz(case, X)
    diag = reg_diag(reg)
    diag["registration_seconds"] = f(case.registration_seconds)  # shared by the targets; maybe run meanwhile
    return answer(uv, diag, ok=bool(np.all(np.isfinite(uv))))
