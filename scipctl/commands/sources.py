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


def source_names(srcs) -> list:
    """The name each downlink's results are reported under: its file or folder name, or the path as given when
    another source has the same name (``sol42/ws sol43/ws``), so that no two downlinks share one (their targets
    would be counted, and grouped, as one)."""
    names = [Path(s).name for s in srcs]
    return [str(s) if names.count(n) > 1 else n for s, n in zip(srcs, names)]
