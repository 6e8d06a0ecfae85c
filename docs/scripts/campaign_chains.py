"""The chain records of campaign folders, for the measurement scripts beside this one (fit_step_trust.py,
fit_closure_trust.py, chain_answer_compare.py)."""

from __future__ import annotations

import json
from pathlib import Path


def family_of(header: dict, dirs: dict) -> str:
    """The family of a campaign record's downlink: the first ``dirs`` entry (DIR -> FAMILY) naming a component of
    its path, else the header's ``family`` (campaigns made before ``campaign`` read the family that
    ``synth --family`` records called every such downlink ``default``)."""
    path = (header.get("job") or {}).get("path")
    for part in Path(path).parts if path else ():
        if part in dirs:
            return dirs[part]
    return str(header.get("family") or "default")


def downlink_name(header: dict) -> str:
    """A downlink file named by its folder too (``scenes/def1/paper-s1-arc.mcap`` and def2's differ)."""
    path = (header.get("job") or {}).get("path")
    return f"{Path(path).parent.name}/{Path(path).name}" if path else str(header.get("downlink"))


def campaign_chains(campaigns: list, dirs: dict):
    """``(family, downlink name, chain record)`` of every chain of every downlink that ran (header status ``ok``),
    campaign by campaign, its records files in name order."""
    for out in campaigns:
        for f in sorted(Path(out, "records").glob("*.jsonl")):
            lines = [json.loads(line) for line in f.read_text(encoding="utf-8").splitlines() if line.strip()]
            header = lines[0]
            if header.get("status") != "ok":
                continue
            fam, name = family_of(header, dirs), downlink_name(header)
            for rec in lines[1:]:
                if rec.get("kind") == "chain":
                    yield fam, name, rec["record"]
