"""scip's answers per scene family from `simulate-handoff --json` outputs named FAMILY-SEED.json, or from campaign
folders (their handoff records, each with its downlink's family): within 4 px, median, GO rate, GO precision,
misses NO-GO, Brier score (docs/handoff.md, "Families never used in the fit", and the blind populations).

    python docs/scripts/scip_family_summary.py OUT/*.json
    python docs/scripts/scip_family_summary.py CAMPAIGN [CAMPAIGN ...] [--misses]

``--misses`` also lists, on stderr, every answer off by more than 4 px or with no answer, GO or NO-GO (family,
downlink, target, error, p, the verdict, the navcams and methods it came from).
"""

import argparse
import json
import statistics
import sys
from pathlib import Path

SUCCESS_PX = 4.0  # the success radius, hazcam px


def summary(rows, success_px=SUCCESS_PX):
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


def miss_line(family: str, r: dict) -> str:
    """One line for an answer off by more than the success radius (or none), whatever its verdict."""
    e = r["error_px"]
    p = r["p_success"]
    chosen = ",".join((r.get("diagnostics") or {}).get("chosen") or [])
    return (f"{family:16s} {r.get('downlink', '?'):28s} {r.get('target', '?'):4s} "
            f"{'no answer' if e is None else f'{e:8.2f} px'} p {'-' if p is None else f'{p:.3f}'} "
            f"{'GO' if r['go'] else 'NO-GO':5s} {r.get('navcam', '?')} {chosen}")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("paths", nargs="+", help="simulate-handoff --json outputs (FAMILY-SEED.json) or campaign folders")
    ap.add_argument("--misses", action="store_true", help=f"list the answers off by more than {SUCCESS_PX:g} px on stderr")
    args = ap.parse_args(argv)
    by_family, misses = {}, []
    for f in args.paths:
        path = Path(f)
        if not path.exists() or (path.is_dir() and not (path / "records").is_dir()):
            ap.error(f"{f}: neither a simulate-handoff output nor a campaign folder (no records/)")
        try:  # a file or record without the fields read here is a usage error too, not a traceback
            for family, r in scip_results(path):
                if r["method"] == "scip" and r.get("truth_uv") is not None:
                    by_family.setdefault(family, []).append((r["error_px"], r["p_success"], r["go"]))
                    if r["error_px"] is None or r["error_px"] > SUCCESS_PX:
                        misses.append(miss_line(family, r))
        except (OSError, ValueError, KeyError, TypeError) as e:
            ap.error(f"{f}: not a simulate-handoff --json output or a campaign's records ({type(e).__name__}: {e})")
    if not by_family:
        ap.error("no scip answer with a truth pixel in " + ", ".join(args.paths))
    out = {fam: summary(rows) for fam, rows in sorted(by_family.items())}
    out["all"] = summary([x for rows in by_family.values() for x in rows])
    print(json.dumps(out, indent=1))
    if args.misses:
        for line in misses:
            print(line, file=sys.stderr)


if __name__ == "__main__":
    main()
