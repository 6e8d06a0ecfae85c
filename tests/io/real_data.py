"""Where the real rover products (``shared/real``) are: beside the checkout, never inside the repository.

CI checks the repository out with ``shared/`` beside it (``/work/main`` ->
``/work/shared``); a git worktree one level deeper (``/work/wt/x``) finds the
same folder two levels up; ``SCIPCTL_SHARED_REAL`` overrides both. Tests that
need the files skip with the reason when they are absent.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Optional

import pytest

REPO = Path(__file__).resolve().parents[2]


def real_dir() -> Optional[Path]:
    env = os.environ.get("SCIPCTL_SHARED_REAL")
    cands = [Path(env)] if env else []
    cands += [REPO / ".." / "shared" / "real", REPO / ".." / ".." / "shared" / "real"]
    for c in cands:
        if c.is_dir():
            return c.resolve()
    return None


def real(sub: str = "") -> Path:
    """``shared/real/<sub>`` (a glob prefix such as ``"05_"`` picks that folder), or skip the test."""
    base = real_dir()
    if base is None:
        pytest.skip("real products absent: no shared/real beside the checkout (set SCIPCTL_SHARED_REAL)")
    if not sub:
        return base
    hits = sorted(base.glob(sub + "*"))
    if not hits:
        pytest.skip(f"real products absent: no {sub}* in {base}")
    return hits[0]
