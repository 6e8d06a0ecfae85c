"""Chain campaigns over paired downlinks (the same scenes with one change), compared chain by chain.

    python docs/scripts/chain_pairs.py CONTROL_CAMPAIGN VARIANT_CAMPAIGN [VARIANT_CAMPAIGN ...] [--json]

Chains are paired by (family, downlink file name, target): the campaigns ran over copies of the same scenes in
other folders (e.g. docs/scripts/sun_change_render.py's ``control/`` and ``sun*/``). Per campaign: chains, final
hazcam answers within 4 px, median error, the first pancam track (10 -> 4.5 m) within 4 px and flagged (``ok``
false), chain GO and GO answers more than 4 px off, misses NO-GO, and the Brier score of the final step's
``p_success``; then, per variant, the chains it won and lost against the control.
"""

from __future__ import annotations

import argparse
import glob
import json
import statistics
import sys
from pathlib import Path

SUCCESS_PX = 4.0


def load(campaign: Path) -> dict:
    """(family, file name, target) -> chain record, from a campaign folder's records. ValueError when two downlinks
    of one family share a file name there (e.g. two populations in one campaign): their chains could not be told
    apart, and pairing would silently keep one of them."""
    out, paths = {}, {}
    for f in sorted(glob.glob(str(campaign / "records" / "*.jsonl"))):
        head, chains = None, []
        with open(f) as fh:
            for line in fh:
                d = json.loads(line)
                if d["kind"] == "downlink":
                    head = d
                elif d["kind"] == "chain":
                    chains.append(d["record"])
        if head is None or head.get("status") != "ok":
            continue
        path = head["job"].get("path") or head["downlink"]
        name = Path(path).name
        other = paths.setdefault((head["family"], name), path)
        if other != path:
            raise ValueError(f"{campaign}: two {head['family']} downlinks named {name} ({other}, {path}); chains are "
                             f"paired by family and file name: run one population per campaign")
        for r in chains:
            out[(head["family"], name, r["target"])] = r
    return out


def final_step(r: dict):
    h = [s for s in r.get("steps", []) if s.get("camera") == "hazcam" and (s.get("extra") or {}).get("final")]
    return h[-1] if h else None


def final_error(r: dict):
    f = final_step(r)
    return None if f is None or f.get("tracked_uv") is None else f.get("error_px")


def first_track(r: dict):
    t = [s for s in r.get("steps", []) if s.get("camera") == "pancam" and s.get("kind") == "track"]
    return t[0] if t else None


def within(e) -> bool:
    return e is not None and e <= SUCCESS_PX


def stats(chains: dict, keys: list) -> dict:
    errs, brier = [], []
    w4 = go = go_miss = miss_nogo = miss = t_w4 = t_flag = t_n = 0
    for k in keys:
        r = chains[k]
        e = final_error(r)
        ok = within(e)
        if e is not None:
            errs.append(e)
        w4 += ok
        g = bool(r.get("go"))
        go += g
        go_miss += g and not ok
        miss += not ok
        miss_nogo += (not ok) and not g
        f = final_step(r)
        if f is not None and f.get("p_success") is not None:
            brier.append((float(f["p_success"]) - float(ok)) ** 2)
        t = first_track(r)
        if t is not None:
            t_n += 1
            t_w4 += within(t.get("error_px"))
            t_flag += not t.get("ok", False)
    n = len(keys)
    return {"chains": n, "within_4px": w4, "within_pct": round(100.0 * w4 / n, 1) if n else None,
            "median_px": round(statistics.median(errs), 2) if errs else None, "answered": len(errs),
            "first_pancam_tracks": t_n, "first_track_within_4px": t_w4, "first_track_flagged": t_flag,
            "chain_go": go, "go_misses": go_miss, "misses": miss, "misses_nogo": miss_nogo,
            "final_p_brier": round(sum(brier) / len(brier), 4) if brier else None, "final_p_n": len(brier)}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("control", type=Path)
    ap.add_argument("variants", type=Path, nargs="+")
    ap.add_argument("--json", action="store_true")
    a = ap.parse_args(argv)
    for p in [a.control, *a.variants]:
        if not (p / "records").is_dir():
            ap.error(f"{p}: not a campaign folder (no records/)")
    try:
        ctrl = load(a.control)
        variants = [(v, load(v)) for v in a.variants]
    except ValueError as e:
        print(f"chain_pairs.py: error: {e}", file=sys.stderr)
        return 2
    report = {"control": str(a.control), "variants": []}
    for v, var in variants:
        keys = sorted(set(ctrl) & set(var))
        won = [k for k in keys if within(final_error(var[k])) and not within(final_error(ctrl[k]))]
        lost = [k for k in keys if within(final_error(ctrl[k])) and not within(final_error(var[k]))]
        by_family = {}
        for fam in sorted({k[0] for k in keys}):
            fk = [k for k in keys if k[0] == fam]
            by_family[fam] = {"chains": len(fk), "control_within": sum(within(final_error(ctrl[k])) for k in fk),
                              "variant_within": sum(within(final_error(var[k])) for k in fk)}
        report["variants"].append({
            "variant": str(v), "paired": len(keys), "only_control": len(set(ctrl) - set(var)),
            "only_variant": len(set(var) - set(ctrl)), "control": stats(ctrl, keys), "variant_stats": stats(var, keys),
            "won": ["/".join(k) for k in won], "lost": ["/".join(k) for k in lost], "by_family": by_family})
    if a.json:
        print(json.dumps(report, indent=1))
        return 0
    for rep in report["variants"]:
        print(f"== {rep['variant']} against {a.control} ({rep['paired']} paired chains; unpaired "
              f"{rep['only_control']} / {rep['only_variant']})")
        for label, s in (("control", rep["control"]), ("variant", rep["variant_stats"])):
            print(f"  {label:8s} " + ", ".join(f"{k} {v}" for k, v in s.items()))
        print(f"  won {len(rep['won'])}: {', '.join(rep['won'])}")
        print(f"  lost {len(rep['lost'])}: {', '.join(rep['lost'])}")
        for fam, s in rep["by_family"].items():
            print(f"    {fam:18s} {s['control_within']}/{s['chains']} -> {s['variant_within']}/{s['chains']}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
