"""Record-by-record comparison of JSON records (test helper): equal values, except timings (keys ``seconds`` and
``*_seconds``, which measure the run, not the answer), and, where a relative tolerance is given, numbers within it."""

from __future__ import annotations

import math

TIMING_KEYS = ("seconds",)


def _is_timing(key: str) -> bool:
    return key in TIMING_KEYS or key.endswith("_seconds")


def assert_same(a, b, rel_tol: float = 0.0, where: str = "") -> None:
    """``a == b`` as JSON values (NaN equals NaN); numbers within ``rel_tol`` relative when it is not 0."""
    if isinstance(a, dict):
        assert isinstance(b, dict), f"{where}: {type(b).__name__} instead of a dict"
        ka = {k for k in a if not _is_timing(k)}
        kb = {k for k in b if not _is_timing(k)}
        assert ka == kb, f"{where}: keys differ: {sorted(ka ^ kb)}"
        for k in sorted(ka):
            assert_same(a[k], b[k], rel_tol, f"{where}.{k}")
    elif isinstance(a, list):
        assert isinstance(b, list) and len(a) == len(b), f"{where}: lists differ in length or type"
        for i, (x, y) in enumerate(zip(a, b)):
            assert_same(x, y, rel_tol, f"{where}[{i}]")
    elif isinstance(a, float) or isinstance(b, float):
        assert isinstance(a, (int, float)) and isinstance(b, (int, float)) and not isinstance(b, bool), f"{where}: {a!r} vs {b!r}"
        if math.isnan(a) or math.isnan(b):
            assert math.isnan(a) and math.isnan(b), f"{where}: {a!r} vs {b!r}"
        elif rel_tol:
            assert math.isclose(a, b, rel_tol=rel_tol, abs_tol=0.0), f"{where}: {a!r} vs {b!r} (relative {rel_tol:g})"
        else:
            assert a == b, f"{where}: {a!r} vs {b!r}"
    else:
        assert a == b, f"{where}: {a!r} vs {b!r}"
