"""The designation's trust on recorded chains: what ``scipctl designate`` says of each chain's first pixel, and the
chain's verdict with it on step 0 (docs/stereo-and-tracking.md, "The designation's trust in the chain").

    python docs/scripts/designation_in_chains.py run CAMP OUT.jsonl [--workers N]
    python docs/scripts/designation_in_chains.py score OUT.jsonl [--json]

``run``: for every chain with steps of the campaign folder CAMP (``scipctl campaign ... --chain``), the
designation at its step 0 (product and pixel) as ``scipctl designate`` makes it without the surface normal
(:func:`~scipctl.pipeline.designate.designate` with the packaged designation model: its ``p_ok`` at the model's
default tolerance, GO and veto), and the chain's verdict (:func:`~scipctl.pipeline.chain_trust.chain_verdict`)
before (step 0 as recorded, or taken as given when the record has no designation trust) and after (step 0 with
that p and GO). A record made since session 29 carries the trust on step 0 (``extra["designation"]``): it must be
given back (``reproduced``/``moved`` on stderr, exit 1 if any moved); older records count as neither. One JSON
line per chain: its family, the designation's p, GO and veto, the final answer's error (hazcam px, null: none)
and both verdicts. ``score``: the chains whose designation is NO-GO, how many of them and of the others put the
final answer within 4 px, the chain GO before and after, GO chains within 4 px that turn NO-GO, and the AUC of
the designation's p for the final answer being within 4 px. A folder without ``records/`` is refused with one line
and exit code 2.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))  # campaign_chains, beside this script
from campaign_chains import auc, plain_main, recorded_chains  # noqa: E402

SUCCESS_PX = 4.0  # the final hazcam answer's radius (issue #14)


def run_file(path: str) -> tuple[list, int, int]:
    """The rows of one campaign records file: ``(rows, reproduced, moved)``."""
    import copy

    from scipctl.io.downlink import read_downlink
    from scipctl.io.trust_model import PACKAGED_DESIGNATION, load_packaged_trust_model
    from scipctl.pipeline.chain_trust import advice_for, chain_verdict
    from scipctl.pipeline.designate import designate
    from scipctl.pipeline.designation_trust import VETO_WARNING_PREFIX

    model = load_packaged_trust_model(PACKAGED_DESIGNATION)
    header, chains = recorded_chains(path)
    rows, same, moved = [], 0, 0
    dl = None
    for record, steps in chains:
        s0 = steps[0]
        if s0.kind != "designate":
            continue
        dl = dl or read_downlink(header["job"]["path"])
        d = designate(dl, dl.product(s0.product_id), s0.tracked_uv, record["target"], with_normal=False, trust=model)
        veto = next((w for w in d.warnings if w.startswith(VETO_WARNING_PREFIX)), None)
        recorded = (s0.extra or {}).get("designation")
        if recorded is not None:
            if (recorded.get("p_ok"), bool(recorded.get("go"))) == (d.p_ok, bool(d.go)):
                same += 1
            else:
                moved += 1
        before = chain_verdict(steps)
        after_steps = copy.deepcopy(steps)
        after_steps[0].p_success, after_steps[0].go = d.p_ok, bool(d.go)
        after_steps[0].advice = None if d.go else advice_for(after_steps, 0)
        after = chain_verdict(after_steps)
        fin = steps[-1] if steps[-1].camera == "hazcam" and steps[-1].extra.get("final") else None
        rows.append({"downlink": header["job"]["path"], "family": header.get("family"), "target": record["target"],
                     "p_ok": d.p_ok, "go": bool(d.go), "veto": veto, "recorded": recorded,
                     "final_px": None if fin is None else fin.error_px,
                     "before": {"go": before.go, "step": before.step}, "after": {"go": after.go, "step": after.step}})
    return rows, same, moved


def score(rows: list) -> dict:
    """The figures of ``score`` as a dict (see the module docstring)."""
    right = [r["final_px"] is not None and r["final_px"] <= SUCCESS_PX for r in rows]
    nogo = [not r["go"] for r in rows]
    scored = [(r["p_ok"], w) for r, w in zip(rows, right) if r["p_ok"] is not None]
    return {"chains": len(rows), "within_4px": sum(right),
            "designation_nogo": sum(nogo), "designation_nogo_within_4px": sum(n and w for n, w in zip(nogo, right)),
            "designation_go_within_4px": sum((not n) and w for n, w in zip(nogo, right)),
            "chain_go_before": sum(r["before"]["go"] for r in rows), "chain_go_after": sum(r["after"]["go"] for r in rows),
            "go_within_turned_nogo": sum(r["before"]["go"] and w and not r["after"]["go"] for r, w in zip(rows, right)),
            "nogo_at_step0_after": sum((not r["after"]["go"]) and r["after"]["step"] == 0 for r in rows),
            "auc_p_ok": auc([p for p, _ in scored], [w for _, w in scored])}


def _print(s: dict) -> None:
    auc_text = "-" if s["auc_p_ok"] is None else f"{s['auc_p_ok']:.3f}"
    print(f"chains {s['chains']} ({s['within_4px']} within 4 px); designation NO-GO {s['designation_nogo']} "
          f"({s['designation_nogo_within_4px']} of them within 4 px; the GO designations' chains: "
          f"{s['designation_go_within_4px']}); chain GO {s['chain_go_before']} -> {s['chain_go_after']}, GO and within "
          f"4 px turned NO-GO {s['go_within_turned_nogo']}; NO-GO at step 0 after: {s['nogo_at_step0_after']}; "
          f"AUC of p_ok {auc_text}")


def main(argv=None) -> int:
    return plain_main(__file__, __doc__, run_file, "chains", score, _print, argv)


if __name__ == "__main__":
    sys.exit(main())
