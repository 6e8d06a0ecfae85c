"""The chain's final answer two ways, from one campaign run with ``--chain-answer closure`` (or ``--closure``): the
handoff path's pixel (scip's handoff of the chain's navcam pixel) against the answer the chain gave (the closure's
pixel when it was confirmed), per scene family (docs/stereo-and-tracking.md, "Closure as the answer").

    PYTHONPATH=. .venv/bin/python docs/scripts/chain_answer_compare.py CAMPAIGN_DIR [CAMPAIGN_DIR ...] [--markdown]
        [--family-dir DIR=FAMILY ...]

A chain without a final hazcam answer (or without a mark there) counts as a miss for both. ``closure rule``: what
``--chain-answer closure`` answers, computed from the records (for a campaign run with ``--closure`` only, where
the final answer is the handoff's).
"""

from __future__ import annotations

import argparse
import json
import math
from collections import defaultdict


def chain_rows(campaigns: list, dirs: dict) -> list:
    from campaign_chains import campaign_chains

    rows = []
    for fam, _, record in campaign_chains(campaigns, dirs):
        st = record["steps"]
        fin = next((s for s in st if s["camera"] == "hazcam" and s["extra"].get("final")), None)
        row = {"family": fam, "handoff_px": math.inf, "answer_px": math.inf, "reference": None, "closure": None,
               "p": None, "go": bool(record.get("go"))}
        if fin is not None and fin.get("mark_uv") is not None:
            mk = fin["mark_uv"]
            x = fin["extra"]
            cl = x.get("closure") or {}
            h_uv = x["handoff"]["uv"] if isinstance(x.get("handoff"), dict) else fin["tracked_uv"]
            row["handoff_px"] = math.dist(h_uv, mk) if h_uv else math.inf
            row["closure"] = cl.get("status")
            adopt = cl.get("status") == "confirmed" and cl.get("uv") is not None
            row["answer_px"] = math.dist(cl["uv"], mk) if adopt else row["handoff_px"]
            if adopt:
                row["reference"] = st[cl["reference_step"]]["camera"]
                row["p"] = fin.get("p_success") if x.get("answer") == "closure" else None
        rows.append(row)
    return rows


def summary(rows: list, success_px: float = 4.0) -> dict:
    def med(v):
        v = sorted(v)
        return v[len(v) // 2] if len(v) % 2 else 0.5 * (v[len(v) // 2 - 1] + v[len(v) // 2]) if v else None

    out = {"chains": len(rows), "handoff_within": sum(r["handoff_px"] <= success_px for r in rows),
           "answer_within": sum(r["answer_px"] <= success_px for r in rows),
           "median_handoff_px": med([r["handoff_px"] for r in rows]),
           "median_answer_px": med([r["answer_px"] for r in rows]),
           "adopted": sum(r["reference"] is not None for r in rows), "go": sum(r["go"] for r in rows)}
    for ref in ("pancam", "navcam"):
        sub = [r for r in rows if r["reference"] == ref]
        out[f"adopted_from_{ref}"] = len(sub)
        out[f"adopted_from_{ref}_handoff_within"] = sum(r["handoff_px"] <= success_px for r in sub)
        out[f"adopted_from_{ref}_closure_within"] = sum(r["answer_px"] <= success_px for r in sub)
    ps = [(r["p"], r["answer_px"] <= success_px) for r in rows if r["p"] is not None]
    out["adopted_scored"] = len(ps)
    out["brier_adopted"] = sum((p - y) ** 2 for p, y in ps) / len(ps) if ps else None
    rate = sum(y for _, y in ps) / len(ps) if ps else None
    out["brier_base_rate_adopted"] = sum((rate - y) ** 2 for _, y in ps) / len(ps) if ps else None
    out["mean_p_adopted"] = sum(p for p, _ in ps) / len(ps) if ps else None
    return out


def markdown(per: dict) -> str:
    head = ("| family | chains | final within 4 px: handoff | closure answer | median px: handoff | closure answer | "
            "closures adopted (from pancam / navcam) | within 4 px among them: handoff -> closure |")
    lines = [head, "| " + " | ".join(["---"] * 8) + " |"]
    for fam, s in per.items():
        f = lambda v: "-" if v is None else ("inf" if v == math.inf else f"{v:.1f}")  # noqa: E731
        lines.append(f"| {fam} | {s['chains']} | {s['handoff_within']} | {s['answer_within']} | "
                     f"{f(s['median_handoff_px'])} | {f(s['median_answer_px'])} | {s['adopted']} "
                     f"({s['adopted_from_pancam']} / {s['adopted_from_navcam']}) | "
                     f"{s['adopted_from_pancam_handoff_within'] + s['adopted_from_navcam_handoff_within']} -> "
                     f"{s['adopted_from_pancam_closure_within'] + s['adopted_from_navcam_closure_within']} |")
    return "\n".join(lines)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("campaigns", nargs="+")
    ap.add_argument("--markdown", action="store_true")
    ap.add_argument("--family-dir", action="append", default=[], metavar="DIR=FAMILY",
                    help="the family of downlinks below DIR (as fit_closure_trust.py table)")
    a = ap.parse_args()
    rows = chain_rows(a.campaigns, dict(x.split("=", 1) for x in a.family_dir))
    fams = defaultdict(list)
    for r in rows:
        fams[r["family"]].append(r)
    per = {fam: summary(fams[fam]) for fam in sorted(fams)}
    per["pooled"] = summary(rows)
    print(markdown(per) if a.markdown else json.dumps(per, indent=1))


if __name__ == "__main__":
    main()
