"""scip's answers over a folder of evidence tables, scored with a trust model (the packaged one by default).

    python docs/scripts/scip_evidence_summary.py EV_DIR [--model MODEL.json] [--success-px 4] [--misses]

EV_DIR holds ``scipctl trust-evidence`` tables (``*.jsonl``, one per downlink, e.g. of ``trust_render.py``
downlinks). Each target's answer is the candidate with the highest p, as ``scip`` chooses at run time, and GO is
p >= the model's GO threshold at ``--success-px``. Printed: the visible targets, the runs' marked targets and the
extra ones, pooled, per run (``meta.run``) and per family; the hidden targets (every answer wrong) apart; with
``--misses``, every visible target answered more than ``--success-px`` off or answered GO wrongly.
Used for docs/handoff.md, "Blind: the other five runs (session 37)".
"""

from __future__ import annotations

import argparse
import dataclasses
import glob
import os
from collections import defaultdict

from scipctl.commands.trust import read_rows
from scipctl.errors import InputError
from scipctl.io.trust_model import load_trust_model
from scipctl.pipeline import trust_fit as tf

PACKAGED = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "scipctl", "data", "trust_model.json")


def fmt(s: dict) -> str:
    mr = "-" if s["miss_recall"] is None else f"{s['miss_recall']:.2f}"
    misses = round(s["n"] * (1 - s["within"]))
    return (f"n {s['n']:4d} within {s['within'] * 100:5.1f}% median {s['median_px']:.2f} px GO {s['go']:4d} "
            f"({s['go_rate'] * 100:5.1f}%) false GO {s['false_go']:2d} misses {misses:3d} miss recall {mr} "
            f"Brier {s['brier']:.4f}")


def choices_by_table(ev_dir: str, model, success_px: float) -> list:
    """``(table name, run, target, ScipChoice)`` for every target of every table in ``ev_dir``."""
    out = []
    for t in sorted(glob.glob(os.path.join(ev_dir, "*.jsonl"))):
        name = os.path.basename(t)
        rows = [dataclasses.replace(r, group=name) for r in tf.fit_rows(read_rows([t]))]
        targets = tf.targets_of(rows)
        for (key, trows), c in zip(sorted(targets.items()), tf.scip_choices(model, rows, success_px)):
            out.append((name, trows[0].meta.get("run", "?"), key[1], c))
    return out


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("ev_dir")
    ap.add_argument("--model", default=PACKAGED)
    ap.add_argument("--success-px", type=float, default=4.0)
    ap.add_argument("--misses", action="store_true")
    args = ap.parse_args(argv)
    if not os.path.isdir(args.ev_dir):
        ap.error(f"no such folder: {args.ev_dir}")
    try:
        model = load_trust_model(args.model)
        got = choices_by_table(args.ev_dir, model, args.success_px)
    except InputError as e:
        ap.error(str(e))
    if not got:
        ap.error(f"no evidence tables in {args.ev_dir}")
    r_px, go = args.success_px, model.go_threshold(args.success_px)
    visible = [g for g in got if not g[3].occluded]
    sets = {"visible": visible, "marked": [g for g in visible if g[3].kind != "extra"],
            "extra": [g for g in visible if g[3].kind == "extra"]}
    for name, sel in sets.items():
        if sel:
            print(f"{name:24s} {fmt(tf.choice_summary([g[3] for g in sel], r_px, go))}")
    for label, key in (("run", lambda g: g[1]), ("family", lambda g: g[3].family)):
        groups = defaultdict(list)
        for g in sets["marked"]:
            groups[key(g)].append(g[3])
        for k in sorted(groups):
            print(f"marked, {label} {k:17s} {fmt(tf.choice_summary(groups[k], r_px, go))}")
    hidden = tf.occluded_summary([g[3] for g in got if g[3].occluded], go)
    if hidden["n"]:
        print(f"hidden                   n {hidden['n']} GO {hidden['go']} mean p {hidden['mean_p']:.3f} "
              f"max p {hidden['max_p']:.3f}")
    if args.misses:
        for name, run, target, c in visible:
            if c.error_px > r_px:
                print(f"  {name:40s} {target:4s} {c.kind:8s} {c.error_px:8.2f} px p {c.p:.3f} "
                      f"{'GO (wrong)' if c.p >= go else 'NO-GO'}")


if __name__ == "__main__":
    main()
