"""Open3D imported without loading its plotly/dash viewer (``open3d.visualization.draw_plotly``).

``import open3d`` imports ``open3d.visualization``, whose ``draw_plotly`` module imports plotly and dash (and
with them IPython, requests, pydantic...): about half of Open3D's import time, for a viewer scipctl never
uses (measured with ``python -X importtime``: 0.22 of 0.46 s on the 2-core build machine, docs/sequence.md
"Speed"). :func:`open3d` puts a stand-in for that one module in ``sys.modules`` while Open3D imports; its three
functions load the real module the first time one of them is called, so nothing is lost.

Every scipctl module that needs Open3D imports it through :func:`open3d` (inside the function that needs it).
"""

from __future__ import annotations

import importlib
import sys
import types

_DRAW_PLOTLY = "open3d.visualization.draw_plotly"
_NAMES = ("get_plotly_fig", "draw_plotly", "draw_plotly_server")


def open3d():
    """The ``open3d`` module (imported on the first call, without plotly and dash)."""
    mod = sys.modules.get("open3d")
    if mod is not None:
        return mod
    if _DRAW_PLOTLY not in sys.modules:
        sys.modules[_DRAW_PLOTLY] = _stand_in()
    import open3d as o3d

    return o3d


def _stand_in() -> types.ModuleType:
    stub = types.ModuleType(_DRAW_PLOTLY, "stand-in: the real module is imported when one of its functions is called")

    def real():
        if sys.modules.get(_DRAW_PLOTLY) is stub:
            del sys.modules[_DRAW_PLOTLY]
        mod = importlib.import_module(_DRAW_PLOTLY)
        parent = sys.modules.get("open3d.visualization")
        if parent is not None:  # importing the submodule rebinds the parent's ``draw_plotly`` to the module
            for n in _NAMES:
                setattr(parent, n, getattr(mod, n))
        return mod

    def forward(name):
        def call(*args, **kwargs):
            return getattr(real(), name)(*args, **kwargs)

        call.__name__ = call.__qualname__ = name
        return call

    for n in _NAMES:
        setattr(stub, n, forward(n))
    return stub
