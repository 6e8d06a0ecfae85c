"""Recorded chains scored again with another step trust model (and with ``--closure-model`` another closure model;
by default the packaged one) (docs/stereo-and-tracking.md, "The step model with traverse chains"): every tracking
step's p and GO, each hazcam handoff's p (``scip``'s times
its input navcam step's), an adopted closure's p and GO (its evidence with the new ``ref_p_success``) and the
chain's verdict. The chain's answers do not depend on the step model (the closure's reference is chosen by ``ok``,
not by p), so this is exact.

    python docs/scripts/chain_trust_rescore.py run CAMP [CAMP ...] -o ROWS.jsonl --step-model NEW.json [--recorded-model OLD.json]
        [--closure-model NEWCLOSURE.json]
    python docs/scripts/chain_trust_rescore.py score ROWS.jsonl [ROWS.jsonl ...] [--radius-mm R] [--by family] [--json]

``run``: each chain is first scored with ``--recorded-model`` (the step model its campaign ran with; default the
packaged one) and must give back every recorded step p, GO and the verdict (``reproduced``/``moved`` on stderr,
exit 1 if any moved), then with ``--step-model``. One JSON line per chain: its family, the final answer's error
(hazcam px; null: none), and per arm (``recorded``, ``new``) the final p, the chain's GO and NO-GO step, the step
p and GO. ``score``: per campaign (``--by family``: per scene family) and over all, per arm, the final answer's
Brier score (a chain without a hazcam answer counting p = 0), chain GO (wrong), misses NO-GO at or before their first
tracking step beyond ``R`` mm (default 7.73, the step radius before session 43) and GO tracking steps. Bad input (a
row file that is not JSON lines, or a row without the field a figure needs): one line, exit code 2.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))  # campaign_chains, beside this script
from campaign_chains import recorded_chains  # noqa: E402

SUCCESS_PX = 4.0  # the final hazcam answer's radius (issue #14)


def rescore(steps: list, step_model, closure_model, max_drives: int) -> list:
    """A deep copy of a recorded chain's ``steps`` with its trust scored again by ``step_model`` (and
    ``closure_model`` for an adopted closure), as ``run_chain`` scores a chain it made."""
    import copy

    from scipctl.pipeline.chain import closure_go
    from scipctl.pipeline.chain_closure import closure_evidence
    from scipctl.pipeline.chain_trust import advice_for, score_hazcam_handoffs, score_steps

    steps = copy.deepcopy(steps)
    final = next((i for i, s in enumerate(steps) if s.camera == "hazcam" and s.extra.get("final")), None)
    closure = final is not None and steps[final].extra.get("answer") == "closure"
    for i, s in enumerate(steps):
        if s.camera == "hazcam" and s.kind == "handoff" and "scip_p_success" in s.extra and not (closure and i == final):
            # back to scip's own p and GO, which score_hazcam_handoffs multiplies by the input step's
            s.p_success, s.go = s.extra.pop("scip_p_success"), s.extra.pop("scip_go")
            s.extra.pop("navcam_p_success", None)
    if closure:
        adopted = steps[final]
        h = adopted.extra["handoff"]
        stand_in = copy.deepcopy(adopted)  # the handoff as it was before the closure was adopted
        stand_in.p_success, stand_in.go = h.get("scip_p_success"), h.get("scip_go")
        stand_in.extra = {k: v for k, v in adopted.extra.items() if k not in ("answer", "handoff", "go_min_p")}
        steps[final] = stand_in
    score_steps(steps, step_model)
    score_hazcam_handoffs(steps)
    if closure:
        cl = adopted.extra["closure"]
        p = float(closure_model.probability([closure_evidence(steps, cl)])[0])
        adopted.p_success = p
        adopted.go = closure_go(bool(adopted.ok), p, closure_model.go_min_p, steps, cl.get("reference_step"),
                                max_drives)[0]
        steps[final] = adopted
        adopted.advice = None if adopted.go else advice_for(steps, final)
    return steps


def _arm(steps: list) -> dict:
    from scipctl.pipeline.chain_trust import chain_verdict

    v = chain_verdict(steps)
    fin = next((s for s in steps if s.camera == "hazcam" and s.extra.get("final")), None)
    return {"go": v.go, "nogo_step": v.step, "final_p": None if fin is None else fin.p_success,
            "steps_p": [s.p_success for s in steps], "steps_go": [bool(s.go) for s in steps]}


def _same(a: dict, b: dict) -> bool:
    def eq(x, y):
        return (x is None and y is None) or (x is not None and y is not None and abs(x - y) <= 1e-9)

    return (a["go"] == b["go"] and a["nogo_step"] == b["nogo_step"] and a["steps_go"] == b["steps_go"]
            and all(eq(x, y) for x, y in zip(a["steps_p"], b["steps_p"])) and len(a["steps_p"]) == len(b["steps_p"]))


def run(camps: list, new_model, recorded_model, closure_model, max_drives: int,
        new_closure_model=None) -> tuple[list, int, int]:
    """``(rows, reproduced, moved)`` over every records file of the campaign folders ``camps``; the new arm's closures
    scored by ``new_closure_model`` (None: ``closure_model``, the one the chains ran with)."""
    rows, same, moved = [], 0, 0
    for camp in camps:
        files = sorted(Path(camp, "records").glob("*.jsonl"))
        if not files:
            raise ValueError(f"{camp}: no records/*.jsonl (not a campaign folder)")
        for f in files:
            header, chains = recorded_chains(f)
            for record, steps in chains:
                rec = _arm(steps)
                old = _arm(rescore(steps, recorded_model, closure_model, max_drives))
                if _same(old, rec):
                    same += 1
                else:
                    moved += 1
                new = _arm(rescore(steps, new_model, new_closure_model or closure_model, max_drives))
                fin = next((s for s in steps if s.camera == "hazcam" and s.extra.get("final")), None)
                rows.append({"campaign": str(camp), "downlink": header["job"]["path"], "family": header.get("family"),
                             "target": record["target"], "final_px": None if fin is None else fin.error_px,
                             "kinds": [f"{s.camera} {s.kind}" for s in steps],
                             "steps_mm": [None if s.error_px is None or s.extra.get("px_mm") is None
                                          else s.error_px * s.extra["px_mm"] for s in steps],
                             "steps_answered": [s.tracked_uv is not None for s in steps],
                             "recorded": old, "new": new})
    return rows, same, moved


def _first_bad(row: dict, radius_mm: float):
    """Index of the chain's first tracking step (not the designation, not a hazcam step) that is lost or beyond
    ``radius_mm`` of the target; None: none."""
    for i, (kind, mm, answered) in enumerate(zip(row["kinds"], row["steps_mm"], row["steps_answered"])):
        if kind.startswith("hazcam") or kind.endswith("designate"):
            continue
        if not answered or (mm is not None and mm > radius_mm):
            return i
    return None


def score(rows: list, radius_mm: float = 7.73, by: str = "campaign") -> dict:
    """The figures of ``score`` (see the module docstring): ``{campaign (or family, by="family") or "all": {arm:
    figures}}``."""
    if by not in ("campaign", "family"):
        raise ValueError(f"by: campaign or family, not {by!r}")
    out = {}
    for group in sorted({r[by] for r in rows}) + ["all"]:
        sel = [r for r in rows if group == "all" or r[by] == group]
        y = np.array([r["final_px"] is not None and r["final_px"] <= SUCCESS_PX for r in sel], bool)
        out[group] = {}
        for arm in ("recorded", "new"):
            a = [r[arm] for r in sel]
            p = np.array([x["final_p"] or 0.0 for x in a])
            go = np.array([x["go"] for x in a], bool)
            caught = 0
            for r, x, w in zip(sel, a, y):
                if not w:
                    fb = _first_bad(r, radius_mm)
                    caught += (not x["go"]) and (x["nogo_step"] is None or fb is None or x["nogo_step"] <= fb)
            steps_go = sum(g for r, x in zip(sel, a) for g, k in zip(x["steps_go"], r["kinds"])
                           if not k.startswith("hazcam") and not k.endswith("designate"))
            out[group][arm] = {"chains": len(sel), "within_4px": int(y.sum()),
                              "final_brier": float(np.mean((p - y) ** 2)) if len(sel) else None,
                              "chain_go": int(go.sum()), "chain_go_wrong": int((go & ~y).sum()),
                              "misses": int((~y).sum()), "misses_caught": int(caught), "go_tracking_steps": int(steps_go)}
    return out


def _load_model(path, what, closure: bool = False):
    """The step model (``closure``: the closure model) in the file ``path``, or the packaged one when None; a file
    that cannot be read or is not such a model raises ValueError naming ``what`` and the file (one line)."""
    from scipctl.errors import InputError
    from scipctl.io.closure_trust_model import closure_trust_model_from_text, load_packaged_closure_trust_model
    from scipctl.io.step_trust_model import load_packaged_step_trust_model, step_trust_model_from_text

    packaged, from_text = ((load_packaged_closure_trust_model, closure_trust_model_from_text) if closure
                           else (load_packaged_step_trust_model, step_trust_model_from_text))
    if path is None:
        return packaged()
    try:
        return from_text(Path(path).read_text(encoding="utf-8"), str(path))
    except (OSError, ValueError, InputError) as e:
        raise ValueError(f"{what}: {e}") from None


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="chain_trust_rescore.py", description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("run")
    r.add_argument("campaigns", nargs="+")
    r.add_argument("-o", "--out", required=True)
    r.add_argument("--step-model", required=True)
    r.add_argument("--recorded-model", default=None)
    r.add_argument("--closure-model", default=None, help="the new arm's closure model (default: the packaged one, "
                                                         "which the recorded arm always uses)")
    s = sub.add_parser("score")
    s.add_argument("rows", nargs="+")
    s.add_argument("--radius-mm", type=float, default=7.73)
    s.add_argument("--by", choices=("campaign", "family"), default="campaign")
    s.add_argument("--json", action="store_true")
    a = ap.parse_args(argv)
    if a.cmd == "run":
        from scipctl.io.atomic import atomic_write_text
        from scipctl.pipeline.chain import ChainParams

        try:
            new = _load_model(a.step_model, "--step-model")
            old = _load_model(a.recorded_model, "--recorded-model")
            new_closure = None if a.closure_model is None else _load_model(a.closure_model, "--closure-model",
                                                                           closure=True)
            rows, same, moved = run(a.campaigns, new, old, _load_model(None, "", closure=True),
                                    ChainParams().closure_go_max_drives, new_closure)
        except ValueError as e:
            ap.error(str(e))  # one line, exit code 2
        atomic_write_text(a.out, "".join(json.dumps(x) + "\n" for x in rows))
        print(json.dumps({"chains": len(rows), "reproduced": same, "moved": moved}), file=sys.stderr)
        return 1 if moved else 0
    rows = []
    for f in a.rows:
        try:
            rows += [json.loads(x) for x in Path(f).read_text(encoding="utf-8").splitlines() if x.strip()]
        except (OSError, ValueError) as e:
            ap.error(f"{f}: {e}")
    try:
        s = score(rows, a.radius_mm, a.by)
    except (KeyError, TypeError) as e:
        ap.error(f"{', '.join(a.rows)}: a row without the field {e} (rows as `run` writes them)")
    if a.json:
        print(json.dumps(s, indent=1))
    else:
        for group, arms in s.items():
            for arm, f in arms.items():
                print(f"{Path(group).name:16s} {arm:8s} chains {f['chains']} within 4 px {f['within_4px']} final Brier "
                      f"{f['final_brier']:.4f} chain GO {f['chain_go']} (wrong {f['chain_go_wrong']}) misses caught "
                      f"{f['misses_caught']} of {f['misses']} GO tracking steps {f['go_tracking_steps']}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
