"""The closure's trust model: its table from campaign records, the fit and the held-out figures
(docs/stereo-and-tracking.md, "Closure as the answer").

    # 1. the table: every confirmed closure of campaign folders run with --closure or --chain-answer closure
    python docs/scripts/fit_closure_trust.py table OUT1 OUT2 ... -o closures.jsonl.gz [--family-dir DIR=FAMILY ...] \
        [--step-model scipctl/data/step_trust_model.json] [--add OLD.jsonl.gz]
    # 2. the model (scipctl/data/closure_trust_model.json) and the held-out report (one family out at a time)
    python docs/scripts/fit_closure_trust.py fit closures.jsonl.gz -o scipctl/data/closure_trust_model.json \
        --report r.json
    # 3. a table scored by a fitted model (another population: nothing refitted)
    python docs/scripts/fit_closure_trust.py score closures.jsonl.gz --model scipctl/data/closure_trust_model.json
    # 4. a campaign's whole chains with their adopted closures scored again by each model (the first: the one the
    #    chains ran with, whose recorded p and GO must come back), the verdict taken again; every chain counted
    python docs/scripts/fit_closure_trust.py chains CAMP --model scipctl/data/closure_trust_model.json --model new.json \
        [--closure-go-max-drives N]

A chain's family is its campaign header's ``family``, or the first ``--family-dir DIR=FAMILY`` whose DIR is a
component of the downlink's path (campaigns made before ``campaign`` read the family ``synth --family`` records
called every such downlink ``default``). The fit needs scikit-learn; the model it writes is evaluated
with numpy only. Same table, same bytes.
"""

from __future__ import annotations

import argparse
import gzip
import json
import sys
from pathlib import Path

import numpy as np

from scipctl.io.atomic import atomic_write_bytes, atomic_write_text

sys.path.insert(0, str(Path(__file__).resolve().parent))  # campaign_chains, beside this script


def cmd_table(args) -> None:
    from campaign_chains import campaign_chains, first_per_target
    from scipctl.pipeline.closure_trust_fit import closure_row

    dirs = dict(x.split("=", 1) for x in args.family_dir)
    step_model = None
    if args.step_model:
        from scipctl.io.step_trust_model import step_trust_model_from_text

        step_model = step_trust_model_from_text(Path(args.step_model).read_text(encoding="utf-8"), args.step_model)
    # --add: the rows of an earlier table first (their campaigns need not exist any more), then the campaigns'
    try:
        rows, chains = (read_table(args.add) if args.add else []), 0
    except (OSError, ValueError, TypeError) as e:
        print(f"fit_closure_trust.py table: --add {args.add}: {e}", file=sys.stderr)
        sys.exit(2)
    added = len(rows)
    for fam, name, record in campaign_chains(args.campaigns, dirs):
        chains += 1
        row = closure_row(record, fam, name, step_model)
        if row is not None:
            rows.append(row)
    rows = first_per_target(rows)
    text = "".join(json.dumps(r.to_dict(), sort_keys=True, allow_nan=False) + "\n" for r in rows)
    atomic_write_bytes(args.out, gzip.compress(text.encode("utf-8"), mtime=0))
    print(json.dumps({"chains": chains, "added": added, "confirmed_closures": len(rows)}), file=sys.stderr)


def read_table(path) -> list:
    from scipctl.pipeline.closure_trust_fit import ClosureRow

    text = gzip.decompress(Path(path).read_bytes()).decode("utf-8")
    return [ClosureRow.from_dict(json.loads(line)) for line in text.splitlines() if line.strip()]


def stats(pairs: list, go_min_p: float) -> dict:
    """Brier, base rate, GO figures and reliability of ``[(row, p, within)]``."""
    p = np.array([x[1] for x in pairs], float)
    y = np.array([x[2] for x in pairs], bool)
    go = p >= go_min_p
    out = {"n": int(len(p)), "within": int(y.sum()), "brier": float(np.mean((p - y) ** 2)) if len(p) else None,
           "brier_base_rate": float(np.mean((y.mean() - y) ** 2)) if len(p) else None,
           "go": int(go.sum()), "go_within": int((go & y).sum()), "misses": int((~y).sum()),
           "misses_nogo": int((~go & ~y).sum()), "reliability": []}
    for lo, hi in ((0.0, 0.2), (0.2, 0.5), (0.5, 0.8), (0.8, 0.9), (0.9, 1.0001)):
        m = (p >= lo) & (p < hi)
        out["reliability"].append({"lo": lo, "hi": min(hi, 1.0), "n": int(m.sum()),
                                   "mean_p": float(p[m].mean()) if m.any() else None,
                                   "observed": float(y[m].mean()) if m.any() else None})
    return out


def cmd_fit(args) -> None:
    import sklearn

    from scipctl.io.closure_trust_model import closure_trust_model_json
    from scipctl.io.provenance import provenance
    from scipctl.pipeline.closure_trust_fit import (SUCCESS_PX, choose_go_min_p, fit_closure_model, held_out,
                                                    training_rows)
    from scipctl.pipeline.trust_fit import C_REG

    rows = read_table(args.table)
    pairs = held_out(rows, SUCCESS_PX)
    go_min_p = choose_go_min_p(pairs)
    ev, y, fams = training_rows(rows, SUCCESS_PX)
    prov = provenance({"table0": str(args.table)}, deterministic=True)
    prov.update({"C": C_REG, "n_rows": int(len(y)), "n_within": int(y.sum()),
                 "training_families": sorted(set(fams)), "scikit_learn": sklearn.__version__,
                 "go_rule": "smallest p in 0.90..0.99 whose leave-one-family-out GO answers are right >= 98 % "
                            "of the time; 1.0 (never GO) when none is",
                 "command": f"python docs/scripts/fit_closure_trust.py fit {args.table} -o {args.out}"})
    model = fit_closure_model(ev, y, SUCCESS_PX, go_min_p=go_min_p, provenance=prov)
    atomic_write_text(args.out, closure_trust_model_json(model))
    if args.report:
        per = {}
        for fam in sorted({r.family for r, _, _ in pairs}):
            per[fam] = stats([x for x in pairs if x[0].family == fam], go_min_p)
        per["pooled"] = stats(pairs, go_min_p)
        report = {"go_min_p": go_min_p, "held_out": per, "coef": dict(zip(model.features, model.coef))}
        atomic_write_text(args.report, json.dumps(report, indent=1, sort_keys=True) + "\n")
    print(json.dumps({"out": str(args.out), "go_min_p": go_min_p, "rows": int(len(y)), "within": int(y.sum())}),
          file=sys.stderr)


def cmd_score(args) -> None:
    from scipctl.core.closure_trust import ClosureEvidence
    from scipctl.io.closure_trust_model import closure_trust_model_from_text

    model = closure_trust_model_from_text(Path(args.model).read_text(encoding="utf-8"), args.model)
    rows = [r for r in read_table(args.table) if r.closure_error_px is not None]
    ps = model.probability([ClosureEvidence.from_dict(r.evidence) for r in rows])
    pairs = [(r, float(p), r.closure_error_px <= model.success_px) for r, p in zip(rows, ps)]
    per = {fam: stats([x for x in pairs if x[0].family == fam], model.go_min_p)
           for fam in sorted({r.family for r in rows})}
    per["pooled"] = stats(pairs, model.go_min_p)
    print(json.dumps({"go_min_p": model.go_min_p, "scored": per}, indent=1, sort_keys=True))


def chain_scores(campaigns: list, models: dict, max_drives=None) -> dict:
    """Per model (name -> ClosureTrustModel, the first the one the chains ran with): over every chain of the
    campaigns, the final answer's p (an adopted closure's scored again by the model; otherwise as recorded; no final
    answer: 0) against the final answer within 4 px: Brier, base rate, AUC, the chain GO (``chain_verdict`` with the
    final step's p and GO replaced; as the chain does, never GO when the closure's reference is more than
    ``max_drives`` drives from the designation, None: ``ChainParams().closure_go_max_drives``) and how many GO
    chains are within 4 px, and the chains at p >= 0.9. ValueError when the first model does not give a recorded p
    or GO back, or when ``max_drives`` is not an integer >= 0."""
    from campaign_chains import auc, campaign_chains
    from scipctl.core.closure_trust import ClosureEvidence
    from scipctl.pipeline.chain import ChainParams, ChainStep, closure_go
    from scipctl.pipeline.chain_trust import chain_verdict
    from scipctl.pipeline.closure_trust_fit import SUCCESS_PX, closure_row

    # ChainParams checks the limit (an integer >= 0), so the script refuses what a chain would refuse
    params = ChainParams() if max_drives is None else ChainParams(closure_go_max_drives=max_drives)
    params.check()
    max_drives = params.closure_go_max_drives

    names = list(models)
    res = {n: {"p": [], "go": []} for n in names}
    ys = []
    for fam, name, rec in campaign_chains(campaigns, {}):
        st = rec.get("steps") or []
        fin = st[-1] if st and st[-1]["camera"] == "hazcam" and st[-1]["extra"].get("final") else None
        ys.append(fin is not None and fin["error_px"] is not None and fin["error_px"] <= SUCCESS_PX)
        row = closure_row(rec, fam, name) if fin is not None and fin["extra"].get("answer") == "closure" else None
        if row is not None:  # each model's p and GO go into the same steps before the verdict
            steps = [ChainStep.from_dict(d) for d in st]
            ref_step = fin["extra"]["closure"].get("reference_step")
        for n in names:
            if row is None:
                res[n]["p"].append(0.0 if fin is None or fin["p_success"] is None else float(fin["p_success"]))
                res[n]["go"].append(bool(rec.get("go")))
                continue
            m = models[n]
            p = float(m.probability([ClosureEvidence.from_dict(row.evidence)])[0])
            go = closure_go(bool(fin["ok"]), p, m.go_min_p, steps, ref_step, max_drives)[0]  # as run_chain's
            if n == names[0] and (abs(p - float(fin["p_success"])) > 1e-9 or go != bool(fin["go"])):
                raise ValueError(f"{name} {rec.get('target')}: model {n!r} gives p {p} (GO {go}), the record "
                                 f"{fin['p_success']} (GO {fin['go']}): not the model the chains ran with")
            steps[-1].p_success, steps[-1].go = p, go
            res[n]["p"].append(p)
            res[n]["go"].append(chain_verdict(steps).go)
    y = np.array(ys, bool)
    out = {"chains": int(len(y)), "within": int(y.sum()), "models": {}}
    for n in names:
        p, go = np.array(res[n]["p"], float), np.array(res[n]["go"], bool)
        out["models"][n] = {"brier": float(np.mean((p - y) ** 2)) if len(y) else None,
                            "brier_base_rate": float(np.mean((y.mean() - y) ** 2)) if len(y) else None,
                            "auc": auc(p, y),
                            "chain_go": int(go.sum()), "chain_go_within": int((go & y).sum()),
                            "p_ge_0_9": int((p >= 0.9).sum()), "p_ge_0_9_within": int((y & (p >= 0.9)).sum())}
    return out


def cmd_chains(args) -> None:
    from scipctl.errors import InputError
    from scipctl.io.closure_trust_model import closure_trust_model_from_text

    try:
        for c in args.campaigns:
            if not Path(c, "records").is_dir():
                raise ValueError(f"{c}: no records/ (not a campaign folder)")
        models = {f: closure_trust_model_from_text(Path(f).read_text(encoding="utf-8"), f) for f in args.model}
        out = chain_scores(args.campaigns, models, args.closure_go_max_drives)
    except (OSError, ValueError, InputError) as e:
        print(f"fit_closure_trust.py chains: {e}", file=sys.stderr)
        sys.exit(2)
    print(json.dumps(out, indent=1, sort_keys=True))


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    t = sub.add_parser("table")
    t.add_argument("campaigns", nargs="+")
    t.add_argument("-o", "--out", required=True)
    t.add_argument("--family-dir", action="append", default=[], metavar="DIR=FAMILY")
    t.add_argument("--add", metavar="TABLE", help="keep this earlier table's rows first (its campaigns need not "
                   "exist any more)")
    t.add_argument("--step-model", metavar="FILE", help="score the chains' tracking steps with this step model "
                   "(the reference's ref_p_success as a chain run with it would have it); default: as recorded")
    f = sub.add_parser("fit")
    f.add_argument("table")
    f.add_argument("-o", "--out", required=True)
    f.add_argument("--report")
    s = sub.add_parser("score")
    s.add_argument("table")
    s.add_argument("--model", required=True)
    c = sub.add_parser("chains")
    c.add_argument("campaigns", nargs="+")
    c.add_argument("--model", action="append", required=True, metavar="FILE",
                   help="a closure model (repeat; the first is the one the chains ran with)")
    c.add_argument("--closure-go-max-drives", type=int, metavar="N", help="never GO when the closure's reference is "
                   "more than N drives from the designation (default: ChainParams' default, as the chains ran)")
    a = ap.parse_args()
    {"table": cmd_table, "fit": cmd_fit, "score": cmd_score, "chains": cmd_chains}[a.cmd](a)


if __name__ == "__main__":
    main()
