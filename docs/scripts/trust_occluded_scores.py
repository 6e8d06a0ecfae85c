"""How trust models answer the visible and the hidden targets of evidence tables (docs/handoff.md, "Shallow
occluders: the packaged model refitted on four tables").

    python docs/scripts/trust_occluded_scores.py EV_DIR MODEL [MODEL ...]

EV_DIR holds ``scipctl trust-evidence`` tables (``*.jsonl``) of downlinks made by ``docs/scripts/trust_render.py``
with ``--shallow`` and/or ``--occluded``. Per model, at 4 px and the model's own GO threshold: the visible targets'
summary (within 4 px, GO, false GO, Brier), and the hidden targets by kind -- ids ``p..`` (a pebble in front,
``--shallow``) and ``o..`` (a deep occluder, ``--occluded``) -- with how many scip answered GO (every one is
wrong) and the mean and largest p. Each table is its own group (target ids repeat across downlinks).
"""

from __future__ import annotations

import argparse
import dataclasses
import glob
import os

R_PX = 4.0
KINDS = {"p": "pebble", "o": "deep"}


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("ev_dir")
    ap.add_argument("models", nargs="+")
    a = ap.parse_args(argv)
    tables = sorted(glob.glob(os.path.join(a.ev_dir, "*.jsonl")))
    if not tables:
        ap.error(f"no *.jsonl tables in {a.ev_dir}")
    for m in a.models:
        if not os.path.isfile(m):
            ap.error(f"no such model file: {m}")

    from scipctl.commands.trust import read_rows
    from scipctl.errors import InputError
    from scipctl.io.trust_model import load_trust_model
    from scipctl.pipeline import trust_fit as tf

    try:  # a bad model or table: one line and exit 2 (usage error), not a traceback
        rows = []
        for t in tables:
            rows += [dataclasses.replace(r, group=os.path.basename(t)) for r in tf.fit_rows(read_rows([t]))]
        models = [(path, load_trust_model(path)) for path in a.models]
    except InputError as e:
        ap.error(str(e))
    keys = sorted(tf.targets_of(rows))
    for path, model in models:
        go_min = model.go_threshold(R_PX)
        choices = tf.scip_choices(model, rows, R_PX)  # in the order of ``keys``
        s = tf.choice_summary([c for c in choices if not c.occluded], R_PX, go_min)
        print(f"{path}: GO at p >= {go_min}")
        print(f"  visible  n {s['n']:4d} within {s['within'] * 100:5.1f} % GO {s['go']:4d} ({s['go_rate'] * 100:5.1f} %) "
              f"false GO {s['false_go']} Brier {s['brier']:.4f}")
        for k, name in KINDS.items():
            sel = [c for (_, tid), c in zip(keys, choices) if c.occluded and tid.startswith(k)]
            if sel:
                o = tf.occluded_summary(sel, go_min)
                print(f"  {name:8s} n {o['n']:4d} GO (all wrong) {o['go']:3d} mean p {o['mean_p']:.3f} max p {o['max_p']:.3f}")


if __name__ == "__main__":
    main()
