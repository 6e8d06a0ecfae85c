"""The aggregate of a campaign folder (:func:`summarize`): Table 1 per scene family and overall, the chains'
final answers, the predictions, GO/NO-GO and reliability (when records carry ``p_success`` / ``go``), the failed
and the slowest downlinks, and worker CPU time per downlink.

It covers every downlink of the manifest whose records were made under the manifest's current options.
"""

from __future__ import annotations

import math
from typing import Optional

import numpy as np

from .options import CampaignOptions, job_key
from .store import CampaignStore

FORMAT = "scipctl-campaign-summary/1"
OVERALL = "overall"
RELIABILITY_BINS = 10
ERROR_EDGES_PX = (0.0, 0.5, 1.0, 2.0, 4.0, 8.0, 16.0, 32.0, 64.0, 128.0, 256.0, 512.0, math.inf)
SLOWEST = 10


def _handoff_record(d: dict):
    """A :class:`~scipctl.pipeline.handoff.HandoffRecord` from its ``to_dict()`` output (its ``from_dict`` when it
    has one; else the dataclass's own fields, so that records with fields added later still load)."""
    from dataclasses import fields

    from ..pipeline.handoff import HandoffRecord

    from_dict = getattr(HandoffRecord, "from_dict", None)
    if from_dict is not None:
        return from_dict(d)
    return HandoffRecord(**{f.name: d[f.name] for f in fields(HandoffRecord)})


def _stats(vals) -> Optional[dict]:
    a = np.asarray([v for v in vals if v is not None and math.isfinite(v)], float)
    if a.size == 0:
        return None
    return {"n": int(a.size), "mean": float(a.mean()), "median": float(np.median(a)), "std": float(a.std()),
            "min": float(a.min()), "max": float(a.max())}


def final_step(steps: list) -> Optional[dict]:
    """The chain's answer: the step marked ``extra.final`` (the handoff the arm would use), else the last step."""
    if not steps:
        return None
    return next((s for s in steps if (s.get("extra") or {}).get("final")), steps[-1])


def step_success(step: Optional[dict], success_px: float) -> Optional[bool]:
    """A chain step's answer within ``success_px`` of its mark; None when the step has no mark to score against;
    False for no step (the chain stopped before any answer) or no answer."""
    if step is None:
        return False
    if step.get("mark_uv") is None:
        return None
    return step.get("error_px") is not None and bool(step["error_px"] <= success_px)


def reliability(pairs: list) -> Optional[dict]:
    """(predicted probability, outcome bool) pairs -> bins of width 1/RELIABILITY_BINS (count, mean predicted,
    observed frequency), the Brier score and the base rate; None without pairs."""
    pairs = [(float(p), bool(y)) for p, y in pairs if p is not None and y is not None and math.isfinite(p)]
    if not pairs:
        return None
    p = np.clip(np.array([x[0] for x in pairs]), 0.0, 1.0)
    y = np.array([x[1] for x in pairs], float)
    idx = np.minimum((p * RELIABILITY_BINS).astype(int), RELIABILITY_BINS - 1)
    bins = []
    for b in range(RELIABILITY_BINS):
        m = idx == b
        bins.append({"lo": b / RELIABILITY_BINS, "hi": (b + 1) / RELIABILITY_BINS, "n": int(m.sum()),
                     "mean_p": float(p[m].mean()) if m.any() else None,
                     "observed": float(y[m].mean()) if m.any() else None})
    return {"n": len(pairs), "brier": float(np.mean((p - y) ** 2)), "base_rate": float(y.mean()),
            "mean_p": float(p.mean()), "bins": bins}


def go_table(items: list) -> Optional[dict]:
    """(go bool, success bool or None, error px or None) triples (those with no truth to score against left
    out) -> the GO/NO-GO counts and rates, and the error
    histograms of GO and NO-GO answers (edges ``ERROR_EDGES_PX``; unanswered counted apart)."""
    items = [(bool(g), bool(s), e) for g, s, e in items if g is not None and s is not None]  # scored answers only
    if not items:
        return None
    c = {"go_success": 0, "go_miss": 0, "nogo_success": 0, "nogo_miss": 0}
    hist = {"go": [0] * (len(ERROR_EDGES_PX) - 1), "nogo": [0] * (len(ERROR_EDGES_PX) - 1)}
    unanswered = {"go": 0, "nogo": 0}
    for g, s, e in items:
        c[("go_" if g else "nogo_") + ("success" if s else "miss")] += 1
        side = "go" if g else "nogo"
        if e is None or not math.isfinite(e):
            unanswered[side] += 1
        else:
            hist[side][int(np.searchsorted(ERROR_EDGES_PX, e, side="right")) - 1] += 1
    n = len(items)
    go = c["go_success"] + c["go_miss"]
    misses = c["go_miss"] + c["nogo_miss"]
    return {"n": n, **c, "go_rate": go / n, "go_precision": c["go_success"] / go if go else None,
            "miss_recall": c["nogo_miss"] / misses if misses else None,
            "error_edges_px": list(ERROR_EDGES_PX), "error_hist": hist, "unanswered": unanswered}


def _section(results: list, success_px: float) -> dict:
    """Table 1, chains, predictions, GO/NO-GO and reliability over ``results`` (DownlinkResults)."""
    from ..pipeline.handoff import table1

    recs = [r for res in results for r in res.handoff]
    out = {"downlinks": len(results), "handoff_records": len(recs),
           "table1": table1([_handoff_record(r) for r in recs])}
    # chains: the final answer of each
    finals, chain_errors, go_chain, rel_steps = {}, 0, [], []
    for res in results:
        for ch in res.chains:
            if ch.get("error"):
                chain_errors += 1
            fs = final_step(ch.get("steps") or [])
            finals[(res.job.job_id, ch["target"])] = fs
            for s in ch.get("steps") or []:
                # the hazcam handoffs' p_success is for success_px (scip's x its input navcam step's, or the closure
                # model's); the tracking steps' is for the step
                # model's success_mm (pipeline/chain_trust.py), not comparable with success_px
                if s.get("p_success") is not None and s.get("camera") == "hazcam":
                    rel_steps.append((s["p_success"], step_success(s, success_px)))
            if ch.get("go") is not None:  # the chain's verdict: every step up to the final hazcam answer GO
                go_chain.append((ch["go"], step_success(fs, success_px), None if fs is None else fs.get("error_px")))
            elif fs is not None and fs.get("go") is not None:
                go_chain.append((fs["go"], step_success(fs, success_px), fs.get("error_px")))
    scored = {k: step_success(f, success_px) for k, f in finals.items()}
    scored = {k: v for k, v in scored.items() if v is not None}
    answered = [f for f in finals.values() if f is not None and f.get("error_px") is not None]
    misses = [finals[k] for k, v in scored.items() if not v]
    out["chain"] = None if not finals else {
        "chains": len(finals), "errors": chain_errors, "scored": len(scored), "answered": len(answered),
        "within_success_px": sum(scored.values()),
        "success_rate": sum(scored.values()) / len(scored) if scored else None,
        "final_error_px": _stats([f["error_px"] for f in answered]),
        "misses": len(misses), "misses_reported_ok": sum(1 for f in misses if f is not None and f.get("ok"))}
    # predictions, and P(success) against what the chain then did
    preds = [(res.job.job_id, p) for res in results for p in res.predictions]
    rel_pred = []
    for jid, p in preds:
        if p.get("confidence") is not None and (jid, p["target"]) in scored:
            rel_pred.append((p["confidence"], scored.get((jid, p["target"]))))
    out["prediction"] = None if not preds else {
        "targets": len(preds), "errors": sum(1 for _, p in preds if p.get("error")),
        "sequences_written": sum(1 for _, p in preds if p.get("sequence_written")),
        "confidence": _stats([p.get("confidence") for _, p in preds])}
    # GO/NO-GO and reliability, from whatever the records carry
    go_handoff = {}
    for r in recs:
        if r.get("go") is not None:
            go_handoff.setdefault(r["method"], []).append((r["go"], r.get("success"), r.get("error_px")))
    out["go"] = {"handoff": {m: go_table(v) for m, v in go_handoff.items()}, "chain_final": go_table(go_chain)}
    rel_handoff = {}
    for r in recs:
        if r.get("p_success") is not None:
            rel_handoff.setdefault(r["method"], []).append((r["p_success"], r.get("success")))
    out["reliability"] = {"handoff": {m: reliability(v) for m, v in rel_handoff.items()},
                          "chain_steps": reliability(rel_steps), "prediction_vs_chain": reliability(rel_pred)}
    return out


def summarize(store: CampaignStore, run: Optional[dict] = None) -> dict:
    """The summary of the folder (JSON-able). ``run``: what this invocation did (:class:`RunStats`), if any."""
    from ..io.provenance import provenance

    manifest = store.load_manifest()
    if manifest is None:
        from ..errors import InputError

        raise InputError(str(store.manifest_path), "manifest", "no campaign manifest in this folder")
    options = CampaignOptions.from_dict(manifest["options"])
    okey = options.key()
    results, failed, pending = [], [], []
    for job_id, e in sorted(manifest["downlinks"].items()):
        if e.get("key") != job_key(e.get("input_sha256", ""), okey):
            continue  # made under other options
        res = store.read(job_id)
        if res is None or res.key != e["key"]:
            pending.append({"downlink": e["name"], "family": e["family"], "job_id": job_id})
            continue
        results.append(res)
        if res.status != "ok":
            failed.append({"downlink": res.job.name, "family": res.job.family, "job_id": job_id, "error": res.error})
    families = sorted({r.job.family for r in results})
    timed = [r for r in results if r.cpu_s is not None and r.status == "ok"]
    cpu = sum(r.cpu_s for r in timed)
    slow = sorted((r for r in results if r.seconds.get("total") is not None), key=lambda r: -r.seconds["total"])
    prov = provenance(None)
    # the inputs the aggregate covers, by job id: every downlink it counts (also those run by earlier invocations)
    covered = {r.job.job_id for r in results} | {x["job_id"] for x in pending}
    prov["inputs"] = {job_id: {**({"path": e["job"]["path"]} if (e.get("job") or {}).get("path") else {}),
                               "sha256": e.get("input_sha256")}
                      for job_id, e in sorted(manifest["downlinks"].items()) if job_id in covered}
    return {
        "format": FORMAT, "provenance": prov, "out": str(store.out), "options": options.to_dict(),
        "run": run,
        "counts": {"downlinks": len(results) + len(pending), "ok": len(results) - len(failed), "failed": len(failed),
                   "pending": len(pending), "handoff_records": sum(len(r.handoff) for r in results),
                   "chains": sum(len(r.chains) for r in results),
                   "predictions": sum(len(r.predictions) for r in results)},
        "failed": failed, "pending": pending,
        "families": {f: _section([r for r in results if r.job.family == f], options.success_px) for f in families},
        OVERALL: _section(results, options.success_px),
        "slowest": [{"downlink": r.job.name, "family": r.job.family, "status": r.status, "seconds": r.seconds,
                     "cpu_s": r.cpu_s, "cpu_s_by_stage": r.cpu_s_by_stage,
                     "worker": r.worker.get("address") or r.worker.get("host")} for r in slow[:SLOWEST]],
        "cpu": {"downlinks": len(timed), "worker_cpu_s": cpu,
                "by_stage": {k: sum(r.cpu_s_by_stage.get(k, 0.0) for r in timed)
                             for k in sorted({k for r in timed for k in r.cpu_s_by_stage})},
                "cpu_s_per_downlink": cpu / len(timed) if timed else None,
                "downlinks_per_core_hour": 3600.0 * len(timed) / cpu if cpu > 0 else None},
    }


def write_summary(store: CampaignStore, summary: dict) -> tuple:
    """``OUT/summary.json`` and ``OUT/summary.html`` (self-contained), each written atomically; their paths."""
    import json

    from ..errors import InputError
    from ..io.atomic import atomic_write_text
    from ..io.campaign_html import render_campaign_html
    from ..jsonutil import strict_json
    from ..pipeline.paper_table1 import PAPER_TABLE1

    js, page = store.out / "summary.json", store.out / "summary.html"
    try:
        atomic_write_text(js, json.dumps(strict_json(summary), indent=1, sort_keys=True, allow_nan=False) + "\n")
        atomic_write_text(page, render_campaign_html(summary, PAPER_TABLE1))
    except OSError as e:
        raise InputError(str(store.out), "summary", f"cannot write the summary: {e.strerror or e}") from None
    return js, page
