"""Plain-data helpers shared by the commands and products (import-light: numpy only when needed)."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Optional


def json_default(o):
    """``json.dumps(default=...)`` for numpy arrays/scalars, tuples and paths."""
    import numpy as np

    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, (np.floating, np.integer, np.bool_)):
        return o.item()
    if isinstance(o, tuple):
        return list(o)
    if isinstance(o, Path):
        return str(o)
    raise TypeError(f"not JSON serialisable: {type(o).__name__}")


def finite_or_none(x) -> Optional[float]:
    """``float(x)`` if it is a finite number, else ``None`` (for JSON records)."""
    try:
        x = float(x)
    except (TypeError, ValueError):
        return None
    return x if math.isfinite(x) else None
