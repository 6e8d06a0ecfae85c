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


def strict_json(o):
    """``o`` with every non-finite float (NaN, +-inf) replaced by ``None``, recursively through dicts, lists and
    tuples (numpy arrays and scalars via :func:`json_default`): what ``json.dumps(..., allow_nan=False)`` accepts, so
    a document is RFC 8259 JSON that any parser reads (Python's default writes ``NaN``/``Infinity``, which strict
    parsers and JavaScript's ``JSON.parse`` reject)."""
    if isinstance(o, float):
        return o if math.isfinite(o) else None
    if isinstance(o, dict):
        return {k: strict_json(v) for k, v in o.items()}
    if isinstance(o, (list, tuple)):
        return [strict_json(v) for v in o]
    if o is None or isinstance(o, (str, int, bool)):
        return o
    try:
        return strict_json(json_default(o))
    except TypeError:
        return o  # json.dumps says what it cannot serialise


def finite_or_none(x) -> Optional[float]:
    """``float(x)`` if it is a finite number, else ``None`` (for JSON records)."""
    try:
        x = float(x)
    except (TypeError, ValueError):
        return None
    return x if math.isfinite(x) else None


class RecordReader:
    """Typed reads from one JSON record (a dict read back from a product such as ``targets.json``), raising
    :class:`~scipctl.errors.InputError` that names the product and the field (``where`` + key, e.g.
    ``targets[2].pixel_uv``) on a missing or ill-typed value. Values are returned as read (no conversion), so
    a record written by scipctl reads back to what was written."""

    def __init__(self, d, product: str, where: str = "", what: str = "record"):
        from .errors import InputError

        if not isinstance(d, dict):
            raise InputError(product, where.rstrip(".") or "record",
                             f"expected a {what} (JSON object), got {type(d).__name__}")
        self.d, self.product, self.where, self.about = d, product, where, ""

    def bad(self, key: str, why: str):
        from .errors import InputError

        raise InputError(self.product, f"{self.where}{key}", self.about + why)

    def _present(self, key: str, required: bool, nullable: bool) -> bool:
        """True when the key holds a value; ``required``: the key must be there; ``nullable``: null is allowed."""
        if key not in self.d:
            if required:
                self.bad(key, "missing")
            return False
        if self.d[key] is None:
            if not nullable:
                self.bad(key, "missing (null)")
            return False
        return True

    def text(self, key: str, required: bool = False, nullable: bool = True) -> Optional[str]:
        """A string, or None (absent or null)."""
        if not self._present(key, required, nullable):
            return None
        v = self.d[key]
        if not isinstance(v, str):
            self.bad(key, f"expected a string, got {v!r}")
        return v

    def number(self, key: str, required: bool = False, nullable: bool = True) -> Optional[float]:
        """A finite number, or None."""
        if not self._present(key, required, nullable):
            return None
        v = self.d[key]
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            self.bad(key, f"expected a finite number or null, got {v!r}")
        return v

    def integer(self, key: str, required: bool = False, nullable: bool = True, minimum: int = 0) -> Optional[int]:
        """A whole number ``>= minimum``, or None."""
        if not self._present(key, required, nullable):
            return None
        v = self.d[key]
        if isinstance(v, bool) or not isinstance(v, int) or v < minimum:
            self.bad(key, f"expected a whole number >= {minimum}, got {v!r}")
        return v

    def flag(self, key: str, required: bool = False, nullable: bool = True,
             default: Optional[bool] = None) -> Optional[bool]:
        """true/false; ``default`` if absent, None if null."""
        if key not in self.d and not required:
            return default
        if not self._present(key, required, nullable):
            return None
        v = self.d[key]
        if not isinstance(v, bool):
            self.bad(key, f"expected true or false, got {v!r}")
        return v

    def vector(self, key: str, n: int, required: bool = False, nullable: bool = True, kind=tuple):
        """``n`` finite numbers (as ``kind``: tuple or list), or None."""
        if not self._present(key, required, nullable):
            return None
        v = self.d[key]
        if not (isinstance(v, list) and len(v) == n and all(
                isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x) for x in v)):
            self.bad(key, f"expected {n} finite numbers or null, got {v!r}")
        return kind(v)

    def mapping(self, key: str, required: bool = False, nullable: bool = True) -> Optional[dict]:
        """A JSON object, or None."""
        if not self._present(key, required, nullable):
            return None
        v = self.d[key]
        if not isinstance(v, dict):
            self.bad(key, f"expected a JSON object, got {type(v).__name__}")
        return v

    def strings(self, key: str, required: bool = False, nullable: bool = True) -> Optional[list]:
        """A list of strings, or None."""
        if not self._present(key, required, nullable):
            return None
        v = self.d[key]
        if not (isinstance(v, list) and all(isinstance(x, str) for x in v)):
            self.bad(key, "expected a list of strings")
        return v
