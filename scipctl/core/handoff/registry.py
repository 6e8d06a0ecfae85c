"""The handoff methods by name: one registry line per method (pure numerics).

:data:`METHODS` maps each name to its function (``method(case, nav_uv, params, *, near_hint=None) ->
MethodResult``, see :class:`~scipctl.core.handoff.run.MethodFn`), in run and report order; :class:`Method`
(a ``StrEnum``) is made from it, so a new method is its function in a family module and one line here.
"""

from __future__ import annotations

from enum import StrEnum
from typing import Mapping, Optional

from . import combined, geometric, kinematic, registration, scip
from .case import HandoffCase
from .params import HandoffParams
from .result import MethodResult
from .run import MethodFn, call_method

# name -> (function, a method of the paper); the order is the order methods run and are reported in
_REGISTRY: dict[str, tuple[MethodFn, bool]] = {
    "pure-kinematic": (kinematic.pure_kinematic, True),
    "alt-pure-kinematic": (kinematic.alt_pure_kinematic, True),
    "refined-kinematic": (kinematic.refined_kinematic, True),
    "pure-geometric": (geometric.pure_geometric, True),
    "refined-geometric": (geometric.refined_geometric, True),
    "mesh-registration": (registration.mesh_registration, True),
    "coarse-fine-geometric": (geometric.coarse_fine_geometric, False),
    "consensus": (combined.consensus, False),
    "scip": (scip.scip, False),
}

Method = StrEnum("Method", [(name.upper().replace("-", "_"), name) for name in _REGISTRY])
Method.__doc__ = "The handoff methods' names (``Method.PURE_KINEMATIC == 'pure-kinematic'``), in registry order."
Method.__module__ = __name__

METHODS: dict[Method, MethodFn] = {Method(name): fn for name, (fn, _) in _REGISTRY.items()}

PAPER_METHODS: tuple[str, ...] = tuple(name for name, (_, paper) in _REGISTRY.items() if paper)
EXTRA_METHODS: tuple[str, ...] = tuple(name for name, (_, paper) in _REGISTRY.items() if not paper)
ALL_METHODS: tuple[str, ...] = tuple(_REGISTRY)  # paper methods first


def run_method(case: HandoffCase, method: str, nav_uv, params: Optional[HandoffParams] = None, *,
               near_hint: Optional[MethodResult] = None,
               registry: Mapping[str, MethodFn] = METHODS) -> MethodResult:
    """Run the method named ``method`` (a :class:`Method` or its name) for the navcam-left pixel ``nav_uv`` (2,).

    ``near_hint``: the near-navcam pure-kinematic result for the same
    target; far refined-kinematic centres its search there, as the paper does.
    ``params`` defaults to ``case.params``; ``registry`` to :data:`METHODS`
    (tests pass a copy with more methods). ``ValueError`` for an unknown name.
    """
    fn = registry.get(method)
    if fn is None:
        raise ValueError(f"unknown handoff method {method!r} (known: {', '.join(str(m) for m in registry)})")
    return call_method(fn, str(method), case, nav_uv, params, near_hint=near_hint)
