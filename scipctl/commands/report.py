"""`scipctl report`: a self-contained HTML diagnostic report of a downlink (and a short summary)."""

from __future__ import annotations

import math
from pathlib import Path

from ..errors import InputError
from .output import emit_json, stderr_console


def build(source, progress=None, params=None, rule_set=None, selfcal_fits=None):
    """(html text, summary dict, data) for an opened source. No file is written. ``rule_set``: the
    :class:`~scipctl.pipeline.rules.RuleSet` the sequences are checked with (None: the package default);
    ``selfcal_fits``: the stereo self-calibration ``source.downlink`` carries (commands/selfcal.py; None: none),
    recorded in the provenance."""
    from ..io.provenance import provenance
    from ..io.report_html import render_report
    from ..pipeline.designate import designations_from_doc
    from ..pipeline.chain_key import keyed_chains_from_doc
    from ..pipeline.handoff import handoff_records_from_doc, table1_rows_from_doc
    from ..pipeline.report_data import ReportParams, collect
    from ..pipeline.paper_table1 import PAPER_TABLE1
    from ..pipeline.sequence import format_seqn
    from ..pipeline.target_sequence import document_for

    dl = source.downlink
    targets_doc = source.load_json("targets.json")
    designations = designations_from_doc(targets_doc, str(source.read_from.get("targets.json", "targets.json")))
    handoff_doc = source.load_json("handoff.json")
    saved_handoff, saved_chains = None, None
    if isinstance(handoff_doc, dict):
        where = str(source.read_from.get("handoff.json", "handoff.json"))
        saved_handoff = (handoff_records_from_doc(handoff_doc, where), table1_rows_from_doc(handoff_doc, where))
        saved_chains = keyed_chains_from_doc(handoff_doc, where)
    data = collect(dl, designations, saved_handoff, params or ReportParams(), progress, saved_chains=saved_chains)
    data["stereo_selfcal"] = selfcal_fits  # shown beside the calibration health (None: --no-stereo-selfcal)
    rows = data["handoff"]["table1"]
    sequences = {}
    for t in data["targets"]:
        pred, rec = t["prediction"], t["record"]
        if pred is None or rec is None:
            continue
        try:
            doc, checks = document_for(dl, rec, pred, rows, rules=None if rule_set is None else rule_set.flight,
                                       rules_used=None if rule_set is None else rule_set.to_dict())
            sequences[t["id"]] = {"checks": [c.to_dict() for c in checks], "text": format_seqn(doc) if doc else None}
        except (InputError, ValueError) as e:
            sequences[t["id"]] = {"checks": [], "text": None, "error": str(e)}
    # the report depends on the saved products it read and on the rules file, not only on the downlink
    inputs = dict({"downlink": dl.source_sha256}, **{name: path for name, path in source.read_from.items()})
    if rule_set is not None:
        inputs["rules_file"] = rule_set.sha256
    from .selfcal import with_fits

    prov = with_fits(provenance(inputs), selfcal_fits)
    html = render_report(data, sequences, PAPER_TABLE1, prov)
    summary = _summary(data, sequences)
    summary["provenance"] = prov  # the record the HTML embeds
    return html, summary, data


def _summary(data, sequences) -> dict:
    targets = []
    for t in data["targets"]:
        pred = t["prediction"]
        fin = next((s for s in reversed(t["chain"]) if s.error_px is not None), None)
        near = [r for r in t["handoff"] if r.navcam == "near" and r.error_px is not None]
        best = min(near, key=lambda r: r.error_px) if near else None
        scip = next((r for r in t["handoff"] if r.method == "scip"), None)
        seq = sequences.get(t["id"])
        targets.append({
            "id": t["id"], "designated": t["record"] is not None,
            "designation_ok": t["record"] is not None and t["record"].has_position,
            "prediction_check": [{k: r.get(k) for k in ("product_id", "expected_error_px", "expected_error_true_pose_px",
                                                         "render_pose", "ncc", "shift_px")}
                                 for r in t.get("prediction_check", [])],
            "chain_final_error_px": None if fin is None else fin.error_px,
            "chain_source": data["chain_sources"].get(t["id"]),
            "scip": None if scip is None else {"navcam": scip.navcam, "error_px": scip.error_px,
                                               "p_success": scip.p_success, "go": scip.go},
            "best_near_handoff": None if best is None else {"method": best.method, "error_px": best.error_px},
            "predicted_success": None if pred is None else pred.confidence,
            "predicted_p_simulated": None if pred is None else pred.p_simulated,
            "risks": None if pred is None else len(pred.risks),
            "rules_broken": None if not seq else [c["rule"] for c in seq["checks"] if c["blocking"] and not c["ok"]],
        })
    mb = data["calibration"].get("mast_bias")
    return {
        "mission": data["mission"], "sol": data["sol"], "targets": targets,
        "handoff_source": data["handoff"]["source"],
        "mast_bias_deg": None if not mb else {"pan": math.degrees(mb["dpan_rad"]), "tilt": math.degrees(mb["dtilt_rad"]),
                                              "rms_before_px": mb["rms_before_px"], "rms_after_px": mb["rms_after_px"]},
        "flagged_images": sum(1 for s in data["image_stats"] if s["flags"]),
        "notes": data["notes"], "seconds": {k: round(v, 3) for k, v in data["seconds"].items()},
    }


def report(src, out, json_out, sigma_position_m=None, sigma_yaw_deg=None, products_root=None, rules_path=None,
           stereo_selfcal: bool = True):
    """``scipctl report``: write the HTML report (and its annotations MCAP beside it); summary on stderr
    (and stdout with ``--json``). ``stereo_selfcal``: every stereo pair re-aligned first (commands/selfcal.py)."""
    from ..io.atomic import check_not_input, check_output_file, output_group
    from ..io.workspace import open_source

    out = check_output_file(out)  # before the work (the report takes a minute)
    check_not_input(out, src, products_root=products_root)  # -o SRC would replace the downlink with the HTML
    check_not_input(out.with_suffix(".annotations.mcap"), src, products_root=products_root)  # and so would the annotations written beside it
    check_output_file(out.with_suffix(".annotations.mcap"), "-o (its annotations MCAP beside it)")
    from .params import report_params
    from .params import rule_set as load_rule_set

    rule_set = load_rule_set(rules_path, None, sigma_position_m, sigma_yaw_deg)
    source = open_source(src, products_root=products_root)
    if rules_path is None:  # none named: the built-in chosen from the downlink's rover
        rule_set = load_rule_set(None, None, sigma_position_m, sigma_yaw_deg, dl=source.downlink)
    params = report_params(sigma_position_m, sigma_yaw_deg, rule_set)
    from .selfcal import self_calibrate

    selfcal = self_calibrate(source, stereo_selfcal)
    fits = selfcal.records
    con = stderr_console()
    with con.status("report", spinner="dots") as st:
        html, summary, data = build(source, progress=lambda s: st.update(f"report: {s}") if con.is_terminal else None,
                                    params=params, rule_set=rule_set, selfcal_fits=fits)
    from ..io.annotations_mcap import annotations_bytes

    mc = out.with_suffix(".annotations.mcap")  # the same annotations for Foxglove
    mcap = annotations_bytes(source.downlink, data, summary["provenance"])  # the HTML's record: same inputs
    with output_group() as outputs:  # both files or neither (a full disk, a folder made meanwhile: exit 2)
        outputs.add_text(out, html)
        outputs.add_bytes(mc, mcap, "-o (its annotations MCAP beside it)")
    selfcal.keep()
    summary["report"] = str(out)
    summary["products_read"] = {k: str(v) for k, v in source.read_from.items()}
    summary["bytes"] = len(html.encode())
    summary["embedded_images"] = html.count("<img ")
    summary["annotations_mcap"] = str(mc)
    if json_out:
        emit_json(summary)
    _print(con, summary)


def _print(con, s):
    con.print(f"report: {s['report']} ({s['bytes'] / 1e6:.1f} MB, {s['embedded_images']} images)"
              + (f"; annotations: {s['annotations_mcap']}" if s.get("annotations_mcap") else ""))
    for t in s["targets"]:
        parts = [f"target {t['id']}:"]
        if t["chain_final_error_px"] is not None:
            parts.append(f"chain final error {t['chain_final_error_px']:.1f} px")
        if t["best_near_handoff"]:
            parts.append(f"best near handoff {t['best_near_handoff']['method']} {t['best_near_handoff']['error_px']:.1f} px")
        if t["predicted_success"] is not None:
            parts.append(f"predicted P(success) {t['predicted_success']:.2f}, {t['risks']} risk(s)")
        if t["rules_broken"] is not None:
            parts.append("sequence ok" if not t["rules_broken"] else "rules broken: " + ", ".join(t["rules_broken"]))
        if not t["designated"]:
            parts.append("not designated")
        elif not t["designation_ok"]:
            parts.append("designation failed (no reliable stereo match)")
        chk = [c for c in t["prediction_check"] if c["ncc"] is not None]
        if chk:
            parts.append(f"expected views vs {len(chk)} later image(s): NCC "
                         + ", ".join(f"{c['ncc']:.2f}" for c in chk))
        con.print(" ".join(parts))
    if s["mast_bias_deg"]:
        m = s["mast_bias_deg"]
        con.print(f"mast bias estimate: pan {m['pan']:+.3f} deg, tilt {m['tilt']:+.3f} deg "
                  f"(hazcam rms {m['rms_before_px']:.1f} -> {m['rms_after_px'] or float('nan'):.1f} px)")
    if s["flagged_images"]:
        con.print(f"{s['flagged_images']} image(s) flagged for gain/saturation")
    for n in s["notes"]:
        con.print(f"note: {n}")
