"""The chain's step trust model: its data table from campaign records, the fit, and the held-out figures
(docs/stereo-and-tracking.md, "Trust along the chain").

    # 1. the table: every chain record of campaign folders, each with its scene family (--add: an earlier table's
    #    chains kept first, e.g. the committed one, whose campaigns are gone)
    python docs/scripts/fit_step_trust.py table OUT1 OUT2 ... -o chains.jsonl.gz [--family-dir DIR=FAMILY ...] [--add T]
    # 2. the model (scipctl/data/step_trust_model.json) and the report (held out by family)
    python docs/scripts/fit_step_trust.py fit chains.jsonl.gz -o scipctl/data/step_trust_model.json --report report.json

A chain's family is the campaign header's ``family``, or for a downlink file the first ``--family-dir`` whose
DIR is a component of the file's path (``scenes/m2020_4/paper-s1-arc.mcap`` with ``m2020_4=m2020``). The fit
needs scikit-learn; the model it writes is evaluated with numpy only. Same table, same bytes.
"""

from __future__ import annotations

import argparse
import gzip
import json
import sys
from pathlib import Path

import numpy as np

from scipctl.io.atomic import atomic_write_bytes, atomic_write_text


def cmd_table(args) -> None:
    from campaign_chains import campaign_chains, first_per_target
    from scipctl.pipeline.step_trust_fit import chain_row

    dirs = dict(x.split("=", 1) for x in args.family_dir)
    # --add: the rows of an earlier table first (their campaigns need not exist any more), then the campaigns'
    try:
        added = read_table(args.add) if args.add else []
    except (OSError, ValueError, TypeError, KeyError) as e:
        print(f"fit_step_trust.py table: --add {args.add}: {e}", file=sys.stderr)
        sys.exit(2)
    rows = []
    for fam, name, record in campaign_chains(args.campaigns, dirs):
        row = chain_row(record, fam)
        row.downlink = name
        rows.append(row)
    rows.sort(key=lambda c: (c.family, c.downlink, c.target))
    rows = first_per_target(added + rows)
    text = "".join(json.dumps(c.to_dict(), sort_keys=True, allow_nan=False) + "\n" for c in rows)
    atomic_write_bytes(args.out, gzip.compress(text.encode("utf-8"), mtime=0))
    fams = {}
    for c in rows:
        fams[c.family] = fams.get(c.family, 0) + 1
    out = {"chains": len(rows), "per_family": fams}
    if args.add:
        out["added"] = len(added)
    print(json.dumps(out), file=sys.stderr)


def read_table(path) -> list:
    from scipctl.pipeline.step_trust_fit import ChainRow

    text = gzip.decompress(Path(path).read_bytes()).decode("utf-8")
    return [ChainRow.from_dict(json.loads(line)) for line in text.splitlines() if line.strip()]


def _summary(outcomes: list) -> dict:
    n = len(outcomes)
    errs = [o.final_error_px for o in outcomes if o.final_error_px is not None]
    misses = [o for o in outcomes if not o.within]
    go = [o for o in outcomes if o.go]
    return {"chains": n, "final_answers": len(errs), "within_4px": sum(o.within for o in outcomes),
            "within_rate": sum(o.within for o in outcomes) / n if n else None,
            "median_final_px": float(np.median(errs)) if errs else None,
            "go": len(go), "go_within": sum(o.within for o in go),
            "misses": len(misses), "misses_caught": sum(o.caught for o in misses),
            "misses_not_caught": sum(not o.caught for o in misses)}


def _step_stats(pairs: list, t: float) -> dict:
    p = np.array([a for a, _ in pairs], float)
    y = np.array([b for _, b in pairs], bool)
    go = p >= t
    out = {"steps": int(len(p)), "within": int(y.sum()), "go": int(go.sum()), "go_within": int((go & y).sum()),
           "misses": int((~y).sum()), "misses_nogo": int((~go & ~y).sum()),
           "brier": float(np.mean((p - y) ** 2)) if len(p) else None}
    out["go_precision"] = out["go_within"] / out["go"] if out["go"] else None
    out["miss_recall"] = out["misses_nogo"] / out["misses"] if out["misses"] else None
    return out


def cmd_fit(args) -> None:
    from scipctl.io.provenance import provenance
    from scipctl.io.step_trust_model import step_trust_model_json
    from scipctl.pipeline.trust_fit import C_REG
    from scipctl.pipeline.step_trust_fit import (choose_threshold, fit_logistic, held_out, judge_chain,
                                                 step_within, success_mm_of, training_steps)

    chains = read_table(args.table)
    success_mm = success_mm_of(chains)
    ho = held_out(chains, success_mm)
    fam_chains = {f: [c for c in chains if c.family == f] for f in ho}
    # held-out (p, outcome) of every tracking step with a pixel and a mark
    pairs, per_fam_pairs = [], {}
    for fam, (_, probs) in ho.items():
        per_fam_pairs[fam] = []
        for c, pc in zip(fam_chains[fam], probs):
            for s, p in zip(c.steps, pc):
                if s.evidence is None or not s.answered:
                    continue
                w = step_within(s, success_mm)
                if w is not None:
                    per_fam_pairs[fam].append((p, w))
        pairs += per_fam_pairs[fam]
    go_min_p = choose_threshold(chains, ho, success_mm)
    ev, y, fams = training_steps(chains, success_mm)
    counts = {f: sum(1 for x in fams if x == f) for f in sorted(set(fams))}
    prov = provenance({"table0": str(args.table)}, deterministic=True)
    import sklearn

    prov.update({"C": C_REG, "go_rule": "smallest p in 0.50..0.99 at which every held-out missing chain is NO-GO "
                                        "at or before the step where it went wrong", "n_steps": int(len(y)), "n_chains": len(chains),
                 "per_family_steps": counts, "training_families": sorted(counts), "scikit_learn": sklearn.__version__,
                 "success_mm": success_mm, "command": "python docs/scripts/fit_step_trust.py fit " + " ".join(
                     [str(args.table), "-o", str(args.out)])})
    model = fit_logistic(ev, y, success_mm, go_min_p=go_min_p, provenance=prov)
    atomic_write_text(args.out, step_trust_model_json(model))
    if args.report:
        report = {"success_mm": success_mm, "go_min_p": go_min_p, "held_out": {}, "fit": {}}
        all_out, all_fit = [], []
        for fam, (m, probs) in ho.items():
            outs = [judge_chain(c, pc, go_min_p, success_mm) for c, pc in zip(fam_chains[fam], probs)]
            all_out += outs
            report["held_out"][fam] = {"chains": _summary(outs), "steps": _step_stats(per_fam_pairs[fam], go_min_p)}
            from scipctl.pipeline.step_trust_fit import chain_probabilities

            fits = [judge_chain(c, chain_probabilities(c, model), go_min_p, success_mm) for c in fam_chains[fam]]
            all_fit += fits
            report["fit"][fam] = _summary(fits)
        report["held_out"]["pooled"] = {"chains": _summary(all_out), "steps": _step_stats(pairs, go_min_p)}
        # the simple rule the model must beat: GO = the chain's own ok flag and a confirmed feature match (or the
        # same-stop IFOV-scaled handoff); p = 1 / 0
        report["rule"] = {}
        rule_all, rule_pairs_all = [], []
        for fam in ho:
            outs, rp = [], []
            for c in fam_chains[fam]:
                pc = [None if s.evidence is None else float(s.answered and s.evidence.ok == 1.0 and (
                    s.evidence.status_confirmed == 1.0 or s.evidence.same_stop == 1.0)) for s in c.steps]
                pc = [p if s.kind != "hazcam-handoff" else s.p_scip for p, s in zip(pc, c.steps)]
                outs.append(judge_chain(c, pc, 0.5, success_mm))
                rp += [(p, step_within(s, success_mm)) for p, s in zip(pc, c.steps)
                       if s.evidence is not None and s.answered and step_within(s, success_mm) is not None]
            rule_all += outs
            rule_pairs_all += rp
            report["rule"][fam] = {"chains": _summary(outs), "steps": _step_stats(rp, 0.5)}
        report["rule"]["pooled"] = {"chains": _summary(rule_all), "steps": _step_stats(rule_pairs_all, 0.5)}
        report["fit"]["pooled"] = _summary(all_fit)
        report["misses_not_caught"] = [
            {"family": c.family, "downlink": c.downlink, "target": c.target, "final_error_px": o.final_error_px,
             "first_nogo": o.first_nogo, "wrong_at": o.wrong_at}
            for fam, (_, probs) in ho.items() for c, pc in zip(fam_chains[fam], probs)
            for o in [judge_chain(c, pc, go_min_p, success_mm)] if not o.caught]
        p = np.array([a for a, _ in pairs])
        yy = np.array([b for _, b in pairs], bool)
        report["reliability"] = []
        for lo, hi in ((0.0, 0.2), (0.2, 0.5), (0.5, 0.8), (0.8, 0.9), (0.9, 0.95), (0.95, 1.0001)):
            m = (p >= lo) & (p < hi)
            report["reliability"].append({"lo": lo, "hi": min(hi, 1.0), "n": int(m.sum()),
                                          "mean_p": float(p[m].mean()) if m.any() else None,
                                          "observed": float(yy[m].mean()) if m.any() else None})
        report["coef"] = dict(zip(model.features, model.coef))
        atomic_write_text(args.report, json.dumps(report, indent=1, sort_keys=True) + "\n")
        if args.markdown:
            print(markdown(report))
    print(json.dumps({"out": str(args.out), "go_min_p": go_min_p, "success_mm": success_mm, "steps": int(len(y))}),
          file=sys.stderr)


def _pct(a, b) -> str:
    return "-" if not b else f"{a} / {b} ({100.0 * a / b:.0f} %)"


def _rate(x) -> str:
    return "-" if x is None else f"{100.0 * x:.0f} %"


def markdown(report: dict) -> str:
    """The report's held-out and rule tables as markdown (docs/stereo-and-tracking.md)."""
    out = ["| family held out | chains | final hazcam answer | within 4 px | median final px | GO chains (within 4 px) "
           "| misses | misses NO-GO at or before the wrong step | tracking steps | GO steps (within) | GO precision "
           "| miss recall | Brier | rule: GO steps (within), miss recall | rule: misses caught |",
           "|" + "---|" * 15]
    for fam, sec in report["held_out"].items():
        c, st = sec["chains"], sec["steps"]
        rc, rs = report["rule"][fam]["chains"], report["rule"][fam]["steps"]
        med = "-" if c["median_final_px"] is None else f"{c['median_final_px']:.2f}"
        name = f"**{fam}**" if fam == "pooled" else fam
        out.append(
            f"| {name} | {c['chains']} | {c['final_answers']} | {_pct(c['within_4px'], c['chains'])} | {med} "
            f"| {c['go']} ({c['go_within']}) | {c['misses']} | {_pct(c['misses_caught'], c['misses'])} "
            f"| {st['steps']} | {st['go']} ({st['go_within']}) | {_rate(st['go_precision'])} "
            f"| {_rate(st['miss_recall'])} | {st['brier']:.3f} | {rs['go']} ({rs['go_within']}), "
            f"{_rate(rs['miss_recall'])} | {_pct(rc['misses_caught'], rc['misses'])} |")
    return "\n".join(out)


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    t = sub.add_parser("table", help="the chain table from campaign folders")
    t.add_argument("campaigns", nargs="+")
    t.add_argument("-o", "--out", required=True)
    t.add_argument("--family-dir", action="append", default=[], help="DIR=FAMILY for downlink files")
    t.add_argument("--add", metavar="TABLE", help="keep this earlier table's chains first (its campaigns need not "
                   "exist any more)")
    f = sub.add_parser("fit", help="the model (and report) from a chain table")
    f.add_argument("table")
    f.add_argument("-o", "--out", required=True)
    f.add_argument("--report")
    f.add_argument("--markdown", action="store_true", help="with --report: its tables as markdown on stdout")
    args = ap.parse_args(argv)
    {"table": cmd_table, "fit": cmd_fit}[args.cmd](args)


if __name__ == "__main__":
    main()
