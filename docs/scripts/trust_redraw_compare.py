"""The packaged scip trust model against a refit on its tables with some draws' rows made again.

    python docs/scripts/trust_redraw_compare.py REDRAWN_DIR BLIND_DIR [--tables-out DIR]

REDRAWN_DIR holds ``scipctl trust-evidence`` tables named ``<group without .mcap>.jsonl`` (``m2020-401-s1-straight
.jsonl``...): each replaces the rows of that group (downlink) in whichever of ``tests/data/trust``'s tables
holds it, in place (the tables stay in group order). Printed, at 4 px, GO threshold as the fit chooses:

* held out by family, on the tables as they are and with the rows replaced: pooled, marked targets, hidden
  targets, and per family;
* on BLIND_DIR's tables (downlinks neither model saw): the packaged model and the refit on the new tables, for the
  visible targets, those of groups whose name starts ``m2020`` and the others, the hidden targets; then every target
  whose answer or verdict differs, or that either answers GO wrongly.

``--tables-out DIR`` writes the new tables there (``gzip -n -9`` bytes, as tests/data/README.md makes them).
Used for docs/handoff.md, "The Mars 2020 draws made again upright (session 37; measured, not adopted)".
"""

from __future__ import annotations

import argparse
import dataclasses
import glob
import gzip
import itertools
import json
import os
import sys
import tempfile

from scipctl.commands.trust import read_rows
from scipctl.errors import InputError
from scipctl.io.trust_model import load_trust_model
from scipctl.pipeline import trust_fit as tf

R_PX = 4.0
HERE = os.path.dirname(os.path.abspath(__file__))
TABLES = os.path.join(HERE, "..", "..", "tests", "data", "trust")
PACKAGED = os.path.join(HERE, "..", "..", "scipctl", "data", "trust_model.json")


def fmt(s: dict) -> str:
    mr = "-" if s["miss_recall"] is None else f"{s['miss_recall']:.2f}"
    return (f"n {s['n']:4d} within {s['within'] * 100:5.1f}% median {s['median_px']:.2f} px GO {s['go']:4d} "
            f"({s['go_rate'] * 100:5.1f}%) false GO {s['false_go']:2d} missed GO {s['missed_go']:3d} miss recall {mr} "
            f"Brier {s['brier']:.4f}")


def packaged_tables() -> list:
    """The paths of the packaged model's tables (``tests/data/trust/*.jsonl.gz``), sorted."""
    return sorted(glob.glob(os.path.join(TABLES, "*.jsonl.gz")))


def replaced_tables(redrawn: str, out_dir: str) -> list:
    """The tables of :func:`packaged_tables` with every group that has a table in ``redrawn`` replaced by it; their
    paths in ``out_dir``."""
    paths, used = [], set()
    for src in packaged_tables():
        lines = gzip.decompress(open(src, "rb").read()).decode("utf-8").splitlines()
        out = []
        for group, chunk in itertools.groupby(lines, key=lambda s: json.loads(s)["group"]):
            new = os.path.join(redrawn, group[: -len(".mcap")] + ".jsonl")
            if os.path.isfile(new):
                out += open(new, encoding="utf-8").read().splitlines()  # its provenance header too
                used.add(new)
                print(f"{os.path.basename(src)}: {group}: {len(list(chunk))} rows replaced", file=sys.stderr)
            else:
                out += list(chunk)
        dst = os.path.join(out_dir, os.path.basename(src))
        with open(dst, "wb") as f:
            f.write(gzip.compress(("\n".join(out) + "\n").encode("utf-8"), 9, mtime=0))
        paths.append(dst)
    unused = sorted(set(glob.glob(os.path.join(redrawn, "*.jsonl"))) - used)
    if unused:
        raise InputError(unused[0], "redrawn table", "its group is in none of the tables")
    return paths


def held_out(name: str, tables: list) -> None:
    rep = tf.evaluate(read_rows(tables), R_PX)
    o = rep["held_out_occluded"]
    print(f"{name}: held out by family (GO threshold {rep['go_min_p']})")
    print(f"  pooled           {fmt(rep['held_out_pooled'])}")
    print(f"  marked targets   {fmt(rep['held_out_pooled_marked'])}")
    print(f"  hidden targets   n {o['n']} GO {o['go']} mean p {o['mean_p']:.3f} max p {o['max_p']:.3f}")
    for fam, s in rep["held_out"].items():
        print(f"  {fam:16s} {fmt(s)} hidden {s['occluded']['n']} GO {s['occluded']['go']}")


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("redrawn_dir")
    ap.add_argument("blind_dir")
    ap.add_argument("--tables-out", help="write the new tables here")
    args = ap.parse_args(argv)
    for p in (args.redrawn_dir, args.blind_dir):
        if not os.path.isdir(p):
            ap.error(f"no such folder: {p}")
    try:  # a bad table: one line and exit 2 (usage error), not a traceback
        with tempfile.TemporaryDirectory() as tmp:
            out_dir = args.tables_out or tmp
            os.makedirs(out_dir, exist_ok=True)
            new_tables = replaced_tables(args.redrawn_dir, out_dir)
            old_tables = packaged_tables()
            held_out("the tables as they are", old_tables)
            held_out("with the rows replaced", new_tables)
            refit = tf.fit_trust_model(tf.fit_rows(read_rows(new_tables)))
        packaged = load_trust_model(PACKAGED)
        blind = []
        for t in sorted(glob.glob(os.path.join(args.blind_dir, "*.jsonl"))):
            blind += [dataclasses.replace(r, group=os.path.basename(t)) for r in tf.fit_rows(read_rows([t]))]
    except InputError as e:
        ap.error(str(e))
    if not blind:
        ap.error(f"no evidence tables in {args.blind_dir}")
    go_a, go_b = packaged.go_threshold(R_PX), refit.go_threshold(R_PX)
    keys = sorted(tf.targets_of(blind))
    a, b = tf.scip_choices(packaged, blind, R_PX), tf.scip_choices(refit, blind, R_PX)
    print(f"blind: GO threshold packaged {go_a}, refit {go_b}")
    sels = (("visible", lambda c, k: not c.occluded),
            ("m2020 visible", lambda c, k: not c.occluded and k[0].startswith("m2020")),
            ("other visible", lambda c, k: not c.occluded and not k[0].startswith("m2020")),
            ("marked", lambda c, k: c.kind not in ("extra", "occluded")))
    for sel, keep in sels:
        for name, ch, go in (("packaged", a, go_a), ("refit", b, go_b)):
            print(f"  {sel:14s} {name:9s} {fmt(tf.choice_summary([c for c, k in zip(ch, keys) if keep(c, k)], R_PX, go))}")
    for name, ch, go in (("packaged", a, go_a), ("refit", b, go_b)):
        o = tf.occluded_summary([c for c in ch if c.occluded], go)
        if o["n"]:
            print(f"  hidden         {name:9s} n {o['n']} GO {o['go']} mean p {o['mean_p']:.3f} max p {o['max_p']:.3f}")
    inf = float("inf")  # a hidden target's answer has no error: every answer is wrong
    for k, x, y in zip(keys, a, b):
        ex = inf if x.error_px is None else x.error_px
        ey = inf if y.error_px is None else y.error_px
        if (x.p >= go_a) != (y.p >= go_b) or (x.p >= go_a and ex > R_PX) or (y.p >= go_b and ey > R_PX) \
                or (ex != ey and not abs(ex - ey) <= 0.01):
            print(f"  {k[0]:36s} {k[1]:4s} {x.kind:8s} packaged {ex:8.2f} px p {x.p:.3f} | refit {ey:8.2f} px p {y.p:.3f}")


if __name__ == "__main__":
    main()
