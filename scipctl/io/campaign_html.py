"""The campaign summary as one self-contained HTML page (``OUT/summary.html``): Table 1 per scene family and
overall (beside the paper's), the chains, the predictions, GO/NO-GO tables and error histograms, reliability
diagrams, failed and slowest downlinks. Plots by matplotlib (Agg canvas), embedded as PNG data URIs."""

from __future__ import annotations

import math
from typing import Optional

from .report_html import CSS, _e, _f, _fig_png, _figure, _img, _table, plot_methods


def _pct(x) -> str:
    return "-" if x is None else f"{100 * x:.0f}%"


def _stats(s) -> str:
    """The summary's statistics (``{n, mean, median, std, min, max}``, campaign/summary.py)."""
    if not s:
        return "-"
    med = f", median {s['median']:.2f}" if "median" in s else ""
    return f"{s['mean']:.2f}±{s['std']:.2f} ({s['min']:.2f}-{s['max']:.2f}{med})"


def _px_stats(s) -> str:
    """A Table-1 row's error statistics (``{n, mean_px, std_px, min_px, max_px}``, pipeline/handoff.table1)."""
    if not s:
        return "-"
    return f"{s['mean_px']:.2f}±{s['std_px']:.2f} ({s['min_px']:.2f}-{s['max_px']:.2f})"


def plot_reliability(rels: dict, title: str) -> Optional[bytes]:
    """Reliability diagram: observed frequency against mean predicted probability per bin, one line per set."""
    rels = {k: v for k, v in rels.items() if v}
    if not rels:
        return None
    fig = _figure(4.6, 4.2)
    ax = fig.add_subplot(111)
    ax.plot([0, 1], [0, 1], color="#888", lw=0.8, ls=":")
    for label, rel in sorted(rels.items()):
        pts = [(b["mean_p"], b["observed"], b["n"]) for b in rel["bins"] if b["n"]]
        if pts:
            x, y, n = zip(*pts)
            ax.plot(x, y, "o-", label=f"{label} (n={rel['n']}, Brier {rel['brier']:.3f})")
    ax.set_xlim(0, 1)
    ax.set_ylim(-0.02, 1.02)
    ax.set_xlabel("predicted P(success)")
    ax.set_ylabel("observed frequency of success")
    ax.legend(fontsize=7)
    ax.set_title(title, fontsize=9)
    return _fig_png(fig)


def plot_go_errors(go: dict, title: str) -> Optional[bytes]:
    """Histogram of the error of GO and NO-GO answers (log-spaced bins, ``ERROR_EDGES_PX``)."""
    if not go:
        return None
    import numpy as np

    edges = go["error_edges_px"]
    labels = [f"{edges[i]:g}-{edges[i + 1]:g}" if math.isfinite(edges[i + 1]) else f">{edges[i]:g}"
              for i in range(len(edges) - 1)]
    x = np.arange(len(labels))
    fig = _figure(7.0, 3.0)
    ax = fig.add_subplot(111)
    ax.bar(x - 0.2, go["error_hist"]["go"], 0.4, label="GO", color="#2a9d4a")
    ax.bar(x + 0.2, go["error_hist"]["nogo"], 0.4, label="NO-GO", color="#c0392b")
    ax.set_xticks(x)
    ax.set_xticklabels(labels, rotation=30, ha="right", fontsize=7)
    ax.set_xlabel("error against the mark (px)")
    ax.set_ylabel("answers")
    ax.legend(fontsize=8)
    ax.set_title(title, fontsize=9)
    return _fig_png(fig)


def _table1_html(rows: list, paper: Optional[dict]) -> str:
    head = ["method", "navcam", "success", "answered", "mean±std (range) px", "successes / failures px"]
    if paper is not None:
        head.append("paper")
    body = []
    for r in rows:
        split = f"{_px_stats(r['successes'])} / {_px_stats(r['failures'])}" if r.get("refined") else "-"
        row = [_e(r["method"]), _e(r["navcam"]), _pct(r["success_rate"]), f"{r['answered']}/{r['cases']}",
               _px_stats(r["all"]), split]
        if paper is not None:
            row.append(_e(paper.get((r["method"], r["navcam"]), "(not in paper)")))
        body.append(row)
    return _table(head, body) if body else "<p>no handoff records</p>"


def _go_rows(go: dict) -> list:
    rows = []
    for label, g in sorted((go.get("handoff") or {}).items()) + [("chain (final)", go.get("chain_final"))]:
        if g:
            rows.append([_e(label), str(g["n"]), _pct(g["go_rate"]), _pct(g["go_precision"]), _pct(g["miss_recall"]),
                         f"{g['go_success']} / {g['go_miss']} / {g['nogo_success']} / {g['nogo_miss']}"])
    return rows


def _section_html(name: str, sec: dict, paper: Optional[dict]) -> str:
    out = [f"<h2>{_e(name)}: {sec['downlinks']} downlinks, {sec['handoff_records']} handoff records</h2>",
           "<h3>Table 1 (handoff accuracy per method and navcam)</h3>", _table1_html(sec["table1"], paper)]
    png = plot_methods(sec["table1"])
    if png:
        out.append(_img(png, f"handoff error per method, {name}"))
    ch = sec.get("chain")
    if ch:
        out += ["<h3>Chains (pancam designation to the final hazcam answer)</h3>", _table(
            ["chains", "within success px / scored", "answered", "final error px", "misses", "misses reported ok", "errors"],
            [[str(ch["chains"]), f"{ch['within_success_px']} / {ch['scored']} ({_pct(ch['success_rate'])})", str(ch["answered"]),
              _stats(ch["final_error_px"]), str(ch["misses"]), str(ch["misses_reported_ok"]), str(ch["errors"])]])]
    pr = sec.get("prediction")
    if pr:
        out += ["<h3>Pre-uplink predictions (from the first stop)</h3>", _table(
            ["targets", "sequences written", "P(success)", "errors"],
            [[str(pr["targets"]), str(pr["sequences_written"]), _stats(pr["confidence"]), str(pr["errors"])]])]
    go = sec.get("go") or {}
    rows = _go_rows(go)
    if rows:
        out += ["<h3>GO / NO-GO</h3>", _table(
            ["answers", "n", "GO rate", "GO precision", "miss recall", "GO ok / GO miss / NO-GO ok / NO-GO miss"], rows)]
        for label, g in sorted((go.get("handoff") or {}).items()) + [("chain (final)", go.get("chain_final"))]:
            png = plot_go_errors(g, f"{name}: {label}, error of GO and NO-GO answers")
            if png:
                out.append(_img(png, f"GO/NO-GO errors {label}"))
    rel = sec.get("reliability") or {}
    sets = {f"handoff {m}": v for m, v in (rel.get("handoff") or {}).items()}
    sets.update({"chain steps": rel.get("chain_steps"), "prediction vs chain": rel.get("prediction_vs_chain")})
    png = plot_reliability(sets, f"{name}: reliability")
    if png:
        out += ["<h3>Reliability</h3>", _img(png, f"reliability {name}"), _table(
            ["set", "n", "Brier", "base rate", "mean P"],
            [[_e(k), str(v["n"]), _f(v["brier"], 3), _f(v["base_rate"], 3), _f(v["mean_p"], 3)]
             for k, v in sorted(sets.items()) if v])]
    return "\n".join(out)


def render_campaign_html(summary: dict, paper_table1: dict) -> str:
    """The page for a campaign summary (:func:`scipctl.campaign.summary.summarize`)."""
    import json

    c = summary["counts"]
    shown = dict(summary["options"])
    shown.pop("pairs", None)  # the methods x navcams run; listed in Table 1
    out = ["<!DOCTYPE html><html><head><meta charset='utf-8'><title>scipctl campaign</title>",
           f"<style>{CSS}</style></head><body>", f"<h1>Campaign {_e(summary['out'])}</h1>",
           f"<p>{c['downlinks']} downlinks: {c['ok']} ok, {c['failed']} failed, {c['pending']} not run yet; "
           f"{c['handoff_records']} handoff records, {c['chains']} chains, {c['predictions']} predictions. "
           f"Options: <code>{_e(json.dumps(shown, sort_keys=True))}</code></p>"]
    cpu = summary.get("cpu") or {}
    if cpu.get("cpu_s_per_downlink"):
        out.append(f"<p>Worker CPU: {cpu['worker_cpu_s']:.0f} s over {cpu['downlinks']} downlinks, "
                   f"{cpu['cpu_s_per_downlink']:.1f} s each ({cpu['downlinks_per_core_hour']:.0f} downlinks per core-hour)</p>")
    out.append(_section_html("Overall", summary["overall"], paper_table1))
    for fam, sec in sorted(summary["families"].items()):
        out.append(_section_html(f"Family {fam}", sec, None))
    if summary["failed"]:
        out += ["<h2>Failed downlinks</h2>", _table(["downlink", "family", "error"],
                                                  [[_e(f["downlink"]), _e(f["family"]), _e(f["error"])] for f in summary["failed"]])]
    if summary["slowest"]:
        out += ["<h2>Slowest downlinks</h2>", _table(
            ["downlink", "family", "status", "total s", "stages s", "CPU s", "worker"],
            [[_e(s["downlink"]), _e(s["family"]), _e(s["status"]), _f(s["seconds"].get("total"), 1),
              _e(", ".join(f"{k} {v:.1f}" for k, v in s["seconds"].items() if k != "total")), _f(s["cpu_s"], 1),
              _e(s["worker"])] for s in summary["slowest"]])]
    out.append(f"<p class='small'>{_e(json.dumps(summary['provenance'], sort_keys=True))}</p></body></html>\n")
    return "\n".join(out)
