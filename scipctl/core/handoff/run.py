"""Running one handoff method function: the common frame around every method (pure numerics)."""

from __future__ import annotations

import time
from typing import Optional, Protocol

import numpy as np

from .case import HandoffCase
from .params import HandoffParams
from .result import MethodResult, NoAnswer


class MethodFn(Protocol):
    """A handoff method: the hazcam-left pixel for the navcam-left pixel ``nav_uv`` (2,) of ``case``.

    Returns a :class:`MethodResult` (``method``/``navcam`` may be left empty) or raises :class:`NoAnswer`.
    ``near_hint``: the near navcams' pure-kinematic result for the same target (used by far refined-kinematic).
    """

    def __call__(self, case: HandoffCase, nav_uv: np.ndarray, params: HandoffParams, *,
                 near_hint: Optional[MethodResult] = None) -> MethodResult: ...


def call_method(fn: MethodFn, name: str, case: HandoffCase, nav_uv, params: Optional[HandoffParams] = None, *,
                near_hint: Optional[MethodResult] = None) -> MethodResult:
    """Run ``fn`` on ``case`` for ``nav_uv`` (2,) and name the result ``name``.

    ``params`` defaults to ``case.params`` (the case's cached products always use ``case.params``). A
    :class:`NoAnswer` becomes a result with ``ok=False``, ``uv=None`` and its message as the reason; the
    result carries ``name``, the case's navcam label and the wall time.
    """
    params = case.params if params is None else params
    t0 = time.perf_counter()
    try:
        res = fn(case, np.asarray(nav_uv, float).reshape(2), params, near_hint=near_hint)
    except NoAnswer as e:
        res = MethodResult(name, case.label, False, None, str(e), e.diagnostics)
    res.method = name
    res.navcam = case.label
    res.seconds = time.perf_counter() - t0
    return res
