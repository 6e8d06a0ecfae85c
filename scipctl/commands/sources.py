"""The SRC arguments of the commands that take several downlinks (``simulate-handoff``, ``trust-evidence``)."""

from __future__ import annotations

from pathlib import Path

from .output import note


def distinct_sources(srcs) -> list:
    """``srcs`` in order, each downlink once: one named twice (``a.mcap ./a.mcap``, a glob's expansion and a name)
    would count its targets twice (Table 1's statistics, an evidence table's rows), as ``campaign`` does not
    (``campaign.jobs.expand_sources``). Says on stderr which arguments were dropped."""
    out, seen = [], {}
    for s in srcs:
        key = Path(s).resolve()
        if key in seen:
            note(f"{s}: the same downlink as {seen[key]}, given again: used once")
            continue
        seen[key] = s
        out.append(s)
    return out
