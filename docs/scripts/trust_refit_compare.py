"""Compare two fits of scip's trust model: the packaged model against a refit on more evidence.

    python docs/scripts/trust_refit_compare.py OLD_MODEL.json OLD_TABLE BLIND_DIR --new NEW [NEW ...] [--diff]

OLD_MODEL is the model before the refit (fitted on OLD_TABLE alone); the refit is ``fit_trust_model`` on OLD_TABLE
plus every NEW (an evidence table, or a folder of them: every ``NEW/*.jsonl`` in name order), what ``scipctl
fit-trust OLD_TABLE NEW...`` writes. Printed, at 4 px:

* on the new tables: the old model (it never saw them) against the refit held out by family (each family's
  targets answered by a refit on every other family, old and new rows); the occluded targets (every answer
  wrong) apart: how many each model answers GO;
* on BLIND_DIR's tables (``scipctl trust-evidence`` of downlinks neither model saw): both models, overall, per
  run, for the ``t3`` targets and per family; ``--diff``: the targets whose answer or verdict changed.

BLIND_DIR's tables are grouped per table file (``synth --family`` downlinks of different families share the file
name ``paper-<run>.mcap``). Used for docs/handoff.md, "The trust model refitted on 36 more downlinks (session 21;
measured, not adopted)" (``--new tests/data/trust/evidence-36dl-16fam.jsonl.gz``) and "Occluded targets in the
training data (session 22)".
"""

from __future__ import annotations

import argparse
import dataclasses
import glob
import os

from scipctl.commands.trust import read_rows
from scipctl.errors import InputError
from scipctl.io.trust_model import load_trust_model
from scipctl.pipeline import trust_fit as tf

R_PX = 4.0


def line(name: str, choices: list, go_min: float) -> None:
    s = tf.choice_summary(choices, R_PX, go_min)
    mr = "-" if s["miss_recall"] is None else f"{s['miss_recall']:.2f}"
    print(f"{name:44s} n {s['n']:4d} within {s['within'] * 100:5.1f}% median {s['median_px']:.2f} px "
          f"GO {s['go']:4d} ({s['go_rate'] * 100:5.1f}%) false GO {s['false_go']:2d} missed GO {s['missed_go']:3d} "
          f"miss recall {mr} Brier {s['brier']:.4f} log loss {s['log_loss']:.3f}")


def runs_of(rows: list) -> list:
    return [(v[0].meta.get("run", "?"), k[1]) for k, v in sorted(tf.targets_of(rows).items())]


def tables_in(path: str) -> list:
    return sorted(glob.glob(os.path.join(path, "*.jsonl"))) if os.path.isdir(path) else [path]


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("old_model")
    ap.add_argument("old_table")
    ap.add_argument("blind_dir")
    ap.add_argument("--new", nargs="+", required=True, help="evidence tables (or folders of them) the refit adds")
    ap.add_argument("--diff", action="store_true")
    args = ap.parse_args(argv)
    for p in [args.old_model, args.old_table, args.blind_dir] + args.new:
        if not os.path.exists(p):
            ap.error(f"no such file or folder: {p}")
    try:  # a bad model or table: one line and exit 2 (usage error), not a traceback
        old_model = load_trust_model(args.old_model)
        old = tf.fit_rows(read_rows([args.old_table]))
        new = tf.fit_rows(read_rows([t for p in args.new for t in tables_in(p)]))
        blind = []
        for t in sorted(glob.glob(os.path.join(args.blind_dir, "*.jsonl"))):
            blind += [dataclasses.replace(r, group=os.path.basename(t)) for r in tf.fit_rows(read_rows([t]))]
    except InputError as e:
        ap.error(str(e))
    both = old + new
    refit = tf.fit_trust_model(both)
    go_old, go_new = old_model.go_threshold(R_PX), refit.go_threshold(R_PX)
    print(f"GO threshold at {R_PX:g} px: old {go_old}, refit {go_new}")

    held_by_target = {}  # the new tables' targets, each family answered by a refit without it
    for fam in tf.families_of(new):
        test = [r for r in new if r.family == fam]
        m = tf.fit_raw_model([r for r in both if r.family != fam], tf.RADII_PX)
        held_by_target.update(zip(sorted(tf.targets_of(test)), tf.scip_choices(m, test, R_PX)))
    held = [held_by_target[k] for k in sorted(tf.targets_of(new))]  # in scip_choices' order, as old_on_new
    old_on_new = tf.scip_choices(old_model, new, R_PX)
    ro = runs_of(new)
    sels = (("all", lambda c, r: not c.occluded), ("marked", lambda c, r: c.kind not in ("extra", "occluded")),
            ("marked s2-arc", lambda c, r: c.kind not in ("extra", "occluded") and r[0] == "s2-arc"))
    for sel, keep in sels:
        line(f"new tables, {sel}: old model", [c for c, r in zip(old_on_new, ro) if keep(c, r)], go_old)
        line(f"new tables, {sel}: refit, family held out", [c for c, r in zip(held, ro) if keep(c, r)], go_new)
    for name, ch, go in (("old model", old_on_new, go_old), ("refit, family held out", held, go_new)):
        o = tf.occluded_summary([c for c in ch if c.occluded], go)
        if o["n"]:
            print(f"new tables, occluded: {name:31s} n {o['n']:4d} GO (all false) {o['go']:3d} "
                  f"mean p {o['mean_p']:.3f} max p {o['max_p']:.3f} Brier {o['brier']:.4f}")

    a, b, ro = tf.scip_choices(old_model, blind, R_PX), tf.scip_choices(refit, blind, R_PX), runs_of(blind)
    for sel, keep in (("all", lambda r: True), ("s2-arc", lambda r: r[0] == "s2-arc"),
                      ("s1-straight", lambda r: r[0] == "s1-straight"), ("t3", lambda r: r[1] == "t3")):
        line(f"blind {sel}: old model", [c for c, r in zip(a, ro) if keep(r)], go_old)
        line(f"blind {sel}: refit", [c for c, r in zip(b, ro) if keep(r)], go_new)
    for fam in sorted({c.family for c in a}):
        line(f"blind {fam}: old model", [c for c in a if c.family == fam], go_old)
        line(f"blind {fam}: refit", [c for c in b if c.family == fam], go_new)
    if args.diff:
        inf = float("inf")  # an occluded target's answer has no error: every answer is wrong
        for (k, _), x, y in zip(sorted(tf.targets_of(blind).items()), a, b):
            ex, ey = (inf if x.error_px is None else x.error_px), (inf if y.error_px is None else y.error_px)
            if (ex != ey and not abs(ex - ey) <= 0.01) or (x.p >= go_old) != (y.p >= go_new) \
                    or (x.p >= go_old and ex > R_PX) or (y.p >= go_new and ey > R_PX):
                print(f"{k[0]:36s} {k[1]:4s} {x.kind:8s} old: {ex:7.2f} px p {x.p:.3f} | refit: {ey:7.2f} px p {y.p:.3f}")


if __name__ == "__main__":
    main()
