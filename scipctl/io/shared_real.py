"""Where the real rover products (``shared/real``) are at run time: ``$SCIPCTL_SHARED_REAL``, else ``shared/real``
beside the checkout (or two levels up, for a worktree). The repository keeps no copy of them."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Optional

ENV = "SCIPCTL_SHARED_REAL"


def shared_real_dir() -> Optional[Path]:
    """The ``shared/real`` folder (resolved), or None if there is none."""
    repo = Path(__file__).resolve().parents[2]
    env = os.environ.get(ENV)
    cands = ([Path(env)] if env else []) + [repo / ".." / "shared" / "real", repo / ".." / ".." / "shared" / "real"]
    for c in cands:
        if c.is_dir():
            return c.resolve()
    return None


def shared_real_sub(prefix: str) -> Optional[Path]:
    """The first folder of ``shared/real`` whose name starts with ``prefix`` (e.g. ``"12_"``), or None."""
    root = shared_real_dir()
    if root is None:
        return None
    hits = sorted(p for p in root.glob(prefix + "*") if p.is_dir())
    return hits[0].resolve() if hits else None
