"""The chain's closure run again from each step it could start from, and the final answer under other choices of
that step (docs/stereo-and-tracking.md, "The closure's reference (session 28; measured, not adopted)").

    python docs/scripts/closure_references.py run CAMP OUT.jsonl [--workers N]
    python docs/scripts/closure_references.py score OUT.jsonl [--json]

``run``: for every chain of the campaign folder CAMP (``scipctl campaign ... --chain``) whose final hazcam step has
a closure record, the closure (:func:`~scipctl.pipeline.chain_closure.track_from_step`, the chain's own feature
step into the final hazcam image) from each kind of reference that the chain has trusted: its last pancam track,
its navcam handoff at the approach's imaging stop, and the designation itself
(:func:`~scipctl.pipeline.chain_closure.closure_reference` with one kind each). One JSON line per chain: the
chain's recorded answer, and per reference its step, the closure's status, pixel and error against the final
step's mark. The closure from the reference the chain used must come out as recorded (the chain is deterministic;
``reproduced``/``moved`` on stderr, exit 1 if any moved). ``score``: the final answer under each order of
preference (a confirmed closure from the first reference found, else the handoff path's answer, as the chain
answers), against the chain's own; each closure alone; how often two closures that agree are right.

A campaign folder without ``records/`` or an unreadable OUT is refused with one line and exit code 2.
"""

from __future__ import annotations

import sys
from collections import Counter
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))  # campaign_chains, beside this script
from campaign_chains import plain_main, recorded_chains  # noqa: E402

# reference name -> closure_reference order (one kind each)
REFERENCES = {"pancam": (("pancam", "track"),), "navcam": (("navcam", "handoff"),),
              "designation": (("pancam", "designate"),)}
# the orders of preference scored (today's first: scipctl.pipeline.chain_closure.CLOSURE_REFERENCES)
RULES = (("pancam", "navcam"), ("navcam", "pancam"), ("designation", "pancam", "navcam"),
         ("pancam", "designation", "navcam"))
SUCCESS_PX = 4.0


def run_file(path: str) -> tuple[list, int, int]:
    """The rows of one campaign records file: ``(rows, reproduced, moved)``."""
    from scipctl.io.downlink import read_downlink
    from scipctl.pipeline.chain import ChainParams
    from scipctl.pipeline.chain_closure import closure_reference, track_from_step

    header, chains = recorded_chains(path)
    rows, same, moved = [], 0, 0
    dl, params, feats = None, ChainParams(), {}  # one keypoint cache per downlink, as the chain shares it
    for record, steps in chains:
        fi = next((i for i, s in enumerate(steps) if s.camera == "hazcam" and s.extra.get("final")), None)
        if fi is None or "closure" not in steps[fi].extra:
            continue
        H = steps[fi]
        answer = H.extra.get("answer")
        handoff_uv = (H.extra.get("handoff") or {}).get("uv") if answer == "closure" else H.tracked_uv
        row = {"downlink": header["job"]["path"], "family": header.get("family"), "target": record["target"],
               "final_px": H.error_px, "answer": answer, "mark": H.mark_uv, "handoff_uv": handoff_uv,
               "chain_go": record.get("go"), "used_step": H.extra["closure"].get("reference_step")}
        dl = dl or read_downlink(header["job"]["path"])
        prod = dl.product(H.product_id)
        for name, order in REFERENCES.items():
            i = closure_reference(steps, fi, order)
            r = {"step": i}
            if i is not None:
                tr, info, scale, pred = track_from_step(dl, steps[i], prod, params, feats)
                r.update(status=info.get("feature_status", "failed") if pred is not None else "failed",
                         scale=float(scale))
                if tr is not None and np.all(np.isfinite(tr.uv)):
                    r["uv"] = [float(x) for x in tr.uv]
                    if H.mark_uv is not None:
                        r["err_px"] = float(np.linalg.norm(np.subtract(tr.uv, H.mark_uv)))
                if i == row["used_step"]:
                    old = H.extra["closure"]
                    ok = old.get("status") == r["status"] and (old.get("uv") is None) == (r.get("uv") is None) and (
                        old.get("uv") is None or float(np.max(np.abs(np.subtract(old["uv"], r["uv"])))) <= 1e-9)
                    same, moved = same + ok, moved + (not ok)
            row[name] = r
        rows.append(row)
    return rows, same, moved


def _within(e) -> bool:
    return e is not None and e <= SUCCESS_PX


def handoff_error(row: dict):
    """The handoff path's error against the mark (hazcam px), None when there is none."""
    if row.get("handoff_uv") is None or row.get("mark") is None:
        return None
    return float(np.linalg.norm(np.subtract(row["handoff_uv"], row["mark"])))


def rule_error(row: dict, order: tuple):
    """The final answer's error under an order of preference: the closure from the first reference the chain
    has, when confirmed, else the handoff path's answer (as the chain answers). ``(error or None, source)``."""
    for name in order:
        r = row.get(name) or {}
        if r.get("step") is None:
            continue
        if r.get("status") == "confirmed" and r.get("uv") is not None:
            return r.get("err_px"), name
        break
    return handoff_error(row), "handoff"


def score(rows: list) -> dict:
    """The tables of ``score`` as a dict (see the module docstring)."""
    own = [r.get("final_px") for r in rows]
    out = {"chains": len(rows), "own_within": sum(map(_within, own)), "rules": [], "closures": {}, "agreement": []}
    for order in RULES:
        res = [rule_error(r, order) for r in rows]
        out["rules"].append({
            "order": list(order), "within": sum(_within(e) for e, _ in res),
            "won": sum(_within(e) and not _within(o) for (e, _), o in zip(res, own)),
            "lost": sum(_within(o) and not _within(e) for (e, _), o in zip(res, own)),
            "median_px": float(np.median([np.inf if e is None else e for e, _ in res])) if res else None,
            "source": dict(Counter(s for _, s in res))})
    for name in REFERENCES:
        ran = [r[name] for r in rows if (r.get(name) or {}).get("step") is not None]
        conf = [c for c in ran if c.get("status") == "confirmed" and c.get("err_px") is not None]
        out["closures"][name] = {"ran": len(ran), "status": dict(Counter(c.get("status") for c in ran)),
                                 "confirmed_within": sum(_within(c["err_px"]) for c in conf), "confirmed": len(conf),
                                 "confirmed_median_px": float(np.median([c["err_px"] for c in conf])) if conf else None}
    both = [r for r in rows if all((r.get(k) or {}).get("status") == "confirmed" and (r.get(k) or {}).get("err_px")
                                   is not None for k in ("pancam", "navcam"))]
    for lim in (1.0, 2.0, 4.0):
        agree = [r for r in both if np.linalg.norm(np.subtract(r["pancam"]["uv"], r["navcam"]["uv"])) <= lim]
        out["agreement"].append({"within_px": lim, "chains": len(agree),
                                 "pancam_right": sum(_within(r["pancam"]["err_px"]) for r in agree),
                                 "navcam_right": sum(_within(r["navcam"]["err_px"]) for r in agree)})
    return out


def _print(s: dict) -> None:
    print(f"chains {s['chains']}; the chain's own final answer within {SUCCESS_PX:g} px: {s['own_within']}")
    for r in s["rules"]:
        print(f"  {' > '.join(r['order'])}: within {r['within']} (won {r['won']}, lost {r['lost']}), "
              f"median {r['median_px']:.2f} px, answers from {r['source']}")
    for name, c in s["closures"].items():
        med = "-" if c["confirmed_median_px"] is None else f"{c['confirmed_median_px']:.2f}"
        print(f"  closure from the {name}: ran {c['ran']} {c['status']}; confirmed and within {SUCCESS_PX:g} px "
              f"{c['confirmed_within']} of {c['confirmed']} (median {med} px)")
    for a in s["agreement"]:
        print(f"  both confirmed, within {a['within_px']:g} px of each other: {a['chains']} (from the pancam right "
              f"{a['pancam_right']}, from the navcam right {a['navcam_right']})")


def main(argv=None) -> int:
    return plain_main(__file__, __doc__, run_file, "chains", score, _print, argv)


if __name__ == "__main__":
    sys.exit(main())
