"""scip's answers per scene family from `simulate-handoff --json` outputs named FAMILY-SEED.json, or from campaign
folders (their handoff records, each with its downlink's family): within 4 px, median, GO rate, GO precision,
misses NO-GO, Brier score (docs/handoff.md, "Families never used in the fit", and the blind populations).

    python docs/scripts/scip_family_summary.py OUT/*.json
    python docs/scripts/scip_family_summary.py CAMPAIGN [CAMPAIGN ...]
"""

import json
import statistics
import sys
from pathlib import Path


def summary(rows, success_px=4.0):
    n = len(rows)
    within = [e is not None and e <= success_px for e, _, _ in rows]
    go = [g for _, _, g in rows]
    errs = [e for e, _, _ in rows if e is not None]
    misses = n - sum(within)
    return {"targets": n, "within": sum(within), "within_pct": round(100 * sum(within) / n, 1),
            "median_px": round(statistics.median(errs), 2) if errs else None,
            "go": sum(go), "go_right": sum(1 for w, g in zip(within, go) if g and w),
            "misses": misses, "misses_nogo": sum(1 for w, g in zip(within, go) if not w and not g),
            "brier": round(sum(((p or 0.0) - w) ** 2 for (_, p, _), w in zip(rows, within)) / n, 4)}


def scip_results(path: Path):
    """(family, scip result record) for every scip answer with truth in a simulate-handoff output or a campaign."""
    if path.is_dir():
        for f in sorted((path / "records").glob("*.jsonl")):
            for line in f.read_text().splitlines():
                d = json.loads(line)
                if d.get("kind") == "handoff":
                    yield d["family"], d["record"]
    else:
        family = path.stem.rsplit("-", 1)[0]
        for r in json.loads(path.read_text())["results"]:
            yield family, r


def main():
    by_family = {}
    for f in sys.argv[1:]:
        for family, r in scip_results(Path(f)):
            if r["method"] == "scip" and r.get("truth_uv") is not None:
                by_family.setdefault(family, []).append((r["error_px"], r["p_success"], r["go"]))
    out = {fam: summary(rows) for fam, rows in sorted(by_family.items())}
    out["all"] = summary([x for rows in by_family.values() for x in rows])
    print(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
