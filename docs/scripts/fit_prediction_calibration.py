"""The pre-uplink prediction's calibration: its table from campaign records, the fit and the held-out figures
(docs/sequence.md, "Calibrated against the chain").

    # 1. the table: prediction campaigns (either route) and chain campaigns over the same downlinks
    python docs/scripts/fit_prediction_calibration.py table --pred PRED1 PRED2 --chains CH1 CH2 CH3 \
        -o tests/data/prediction_calibration/approaches.jsonl.gz
    # 2. one model per route (scipctl/data/prediction_calibration_{plan,downlink}.json) and the held-out report
    #    (one family out at a time)
    python docs/scripts/fit_prediction_calibration.py fit tests/data/prediction_calibration/approaches.jsonl.gz \
        -o scipctl/data --report r.json [--markdown]
    # 3. another table scored by the packaged (or given) models: nothing refitted
    python docs/scripts/fit_prediction_calibration.py score OTHER.jsonl.gz [--models DIR] [--markdown]
    # 4. the reliability diagram of one route: the simulated P and the calibrated one (each family held out) on
    #    the table, and on another table scored by the packaged model
    python docs/scripts/fit_prediction_calibration.py plot OUT.png TABLE [--new OTHER.jsonl.gz] [--route plan]

The fit needs scikit-learn; the models it writes are evaluated with numpy only. Same table, same bytes.
"""

from __future__ import annotations

import argparse
import gzip
import json
import sys
from pathlib import Path

from scipctl.io.atomic import atomic_write_bytes, atomic_write_text

ROUTES = ("plan", "downlink")


def read_table(path) -> list:
    from scipctl.pipeline.prediction_calibration_fit import PredictionRow

    text = gzip.decompress(Path(path).read_bytes()).decode("utf-8")
    return [PredictionRow.from_dict(json.loads(line)) for line in text.splitlines() if line.strip()]


def cmd_table(args) -> None:
    from scipctl.pipeline.prediction_calibration_fit import approach_rows

    rows = approach_rows(args.pred, args.chains)
    text = "".join(json.dumps(r.to_dict(), sort_keys=True, allow_nan=False) + "\n" for r in rows)
    atomic_write_bytes(args.out, gzip.compress(text.encode("utf-8"), mtime=0))
    print(json.dumps({"approaches": len(rows), "routes": sorted({r.route for r in rows})}), file=sys.stderr)


def _markdown(title: str, per: dict) -> str:
    out = [f"### {title}", "", "| family | approaches | chain within 4 px | mean P | Brier | Brier of the base rate | AUC |",
           "| --- | --- | --- | --- | --- | --- | --- |"]
    for fam, s in per.items():
        if fam == "pooled":
            continue
        out.append(_row(fam, s))
    out.append(_row("**pooled**", per["pooled"]))
    out += ["", "| P bin | approaches | mean P | chain within 4 px |", "| --- | --- | --- | --- |"]
    for b in per["pooled"]["reliability"]:
        if b["n"]:
            out.append(f"| [{b['lo']:.1f}, {b['hi']:.1f}) | {b['n']} | {b['mean_p']:.2f} | {100 * b['observed']:.0f} % |")
    return "\n".join(out) + "\n"


def _row(name: str, s: dict) -> str:
    auc = "-" if s["auc"] is None else f"{s['auc']:.2f}"
    return (f"| {name} | {s['n']} | {s['success']} ({100 * s['success'] / s['n']:.0f} %) | {s['mean_p']:.2f} | "
            f"{s['brier']:.3f} | {s['brier_base_rate']:.3f} | {auc} |")


def _per_family(pairs: list) -> dict:
    from scipctl.pipeline.prediction_calibration_fit import scores

    per = {fam: scores([x for x in pairs if x[0].family == fam]) for fam in sorted({x[0].family for x in pairs})}
    per["pooled"] = scores(pairs)
    return per


def cmd_fit(args) -> None:
    import sklearn

    from scipctl.io.prediction_calibration import packaged_name, prediction_calibration_json
    from scipctl.io.provenance import provenance
    from scipctl.pipeline.prediction_calibration_fit import SUCCESS_PX, fit_calibration, held_out, training_data
    from scipctl.pipeline.trust_fit import C_REG

    rows = read_table(args.table)
    pairs = held_out(rows, SUCCESS_PX)
    report, md = {}, []
    for route in ROUTES:
        R = [r for r in rows if r.route == route]
        if not R:
            continue
        ev, y, fams = training_data(R, SUCCESS_PX)
        out = Path(args.out, packaged_name(route))
        prov = provenance({"table0": str(args.table)}, deterministic=True)
        prov.update({"C": C_REG, "route": route, "n_rows": int(len(y)), "n_success": int(y.sum()),
                     "training_families": sorted(set(fams)), "scikit_learn": sklearn.__version__,
                     "command": f"python docs/scripts/fit_prediction_calibration.py fit {args.table} -o {args.out}"})
        model = fit_calibration(ev, y, SUCCESS_PX, provenance=prov)
        atomic_write_text(out, prediction_calibration_json(model))
        raw = _per_family([(r, r.p_simulated, r.success(SUCCESS_PX)) for r in R])
        cal = _per_family([x for x in pairs if x[0].route == route])
        report[route] = {"held_out": cal, "p_simulated": raw, "coef": dict(zip(model.features, model.coef)),
                         "intercept": model.intercept,
                         "p_at": {str(p): model.p_success(p) for p in (0.0, 0.5, 1.0)}}
        md += [_markdown(f"route {route}: p_simulated as it was", raw),
               _markdown(f"route {route}: calibrated, each family held out", cal)]
        print(json.dumps({"out": str(out), "rows": int(len(y)), "success": int(y.sum())}), file=sys.stderr)
    if args.report:
        atomic_write_text(args.report, json.dumps(report, indent=1, sort_keys=True) + "\n")
    if args.markdown:
        print("\n".join(md))


def cmd_score(args) -> None:
    from scipctl.io.prediction_calibration import (load_packaged_prediction_calibration, packaged_name,
                                                   prediction_calibration_from_text)
    from scipctl.pipeline.prediction_calibration_fit import SUCCESS_PX

    rows = read_table(args.table)
    report, md = {}, []
    for route in ROUTES:
        R = [r for r in rows if r.route == route]
        if not R:
            continue
        if args.models:
            f = Path(args.models, packaged_name(route))
            model = prediction_calibration_from_text(f.read_text(encoding="utf-8"), str(f))
        else:
            model = load_packaged_prediction_calibration(route)
        cal = _per_family([(r, model.p_success(r.p_simulated), r.success(SUCCESS_PX)) for r in R])
        raw = _per_family([(r, r.p_simulated, r.success(SUCCESS_PX)) for r in R])
        report[route] = {"calibrated": cal, "p_simulated": raw}
        md += [_markdown(f"route {route}: p_simulated as it was", raw), _markdown(f"route {route}: calibrated", cal)]
    print("\n".join(md) if args.markdown else json.dumps(report, indent=1, sort_keys=True))


def cmd_plot(args) -> None:
    import numpy as np

    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from prediction_reliability_plot import reliability_axes, reliability_series, save

    from scipctl.io.prediction_calibration import load_packaged_prediction_calibration
    from scipctl.pipeline.prediction_calibration_fit import SUCCESS_PX, held_out

    rows = [r for r in read_table(args.table) if r.route == args.route]
    fig, ax = reliability_axes()
    y = [r.success(SUCCESS_PX) for r in rows]
    reliability_series(ax, "simulated P", [r.p_simulated for r in rows], y)
    pairs = held_out(rows, SUCCESS_PX)
    reliability_series(ax, "calibrated, family held out", [p for _, p, _ in pairs], [s for _, _, s in pairs])
    if args.new:
        new = [r for r in read_table(args.new) if r.route == args.route]
        model = load_packaged_prediction_calibration(args.route)
        yn = [r.success(SUCCESS_PX) for r in new]
        reliability_series(ax, "new scenes: simulated P", [r.p_simulated for r in new], yn)
        reliability_series(ax, "new scenes: calibrated (packaged)", [model.p_success(r.p_simulated) for r in new], yn)
    save(fig, ax, Path(args.out), f"Pre-uplink prediction against the chain ({args.route} route)",
         float(np.mean(y)))
    print(args.out)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    t = sub.add_parser("table")
    t.add_argument("--pred", nargs="+", required=True, help="prediction campaign folders")
    t.add_argument("--chains", nargs="+", required=True, help="chain campaign folders")
    t.add_argument("-o", "--out", required=True)
    f = sub.add_parser("fit")
    f.add_argument("table")
    f.add_argument("-o", "--out", required=True, help="folder for prediction_calibration_<route>.json")
    f.add_argument("--report")
    f.add_argument("--markdown", action="store_true")
    s = sub.add_parser("score")
    s.add_argument("table")
    s.add_argument("--models", help="folder of prediction_calibration_<route>.json (default: the packaged ones)")
    s.add_argument("--markdown", action="store_true")
    g = sub.add_parser("plot")
    g.add_argument("out")
    g.add_argument("table")
    g.add_argument("--new", help="another table, scored by the packaged model")
    g.add_argument("--route", default="plan", choices=ROUTES)
    a = ap.parse_args()
    {"table": cmd_table, "fit": cmd_fit, "score": cmd_score, "plot": cmd_plot}[a.cmd](a)


if __name__ == "__main__":
    main()
