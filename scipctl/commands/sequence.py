"""`scipctl sequence`: plan the single-cycle approach to a target, predict it, check the flight rules, and
emit the uplink command sequence (SeqN-style text, SeqJSON, JSON, or plain text). No sequence when a rule is broken."""

from __future__ import annotations

import sys

from ..errors import CommandFailed, InputError
from .output import emit_json, stderr_console

FORMATS = ("seqn", "seqjson", "json", "text")


def sequence(src, target, out, fmt, json_out, sigma_position_m=None, sigma_yaw_deg=None, products_root=None,
             rules_path=None, rule_options=None, handoff_choice: str = "scip", stereo_selfcal: bool = True):
    """``scipctl sequence``: write the sequence (``out`` or stdout) and print the rule checks; CommandFailed
    (exit 1, no sequence) when a flight rule is broken. ``rules_path``: the rules file (None: the package
    default); ``rule_options``: ``{option: value}`` overriding it (``scipctl.pipeline.rules.OPTIONS``)."""
    from ..io.atomic import check_not_input, check_output_file, write_output_text
    from ..io.workspace import open_source
    from ..pipeline.predict.from_downlink import designation_position
    from ..pipeline.sequence import FORMATTERS, HANDOFF_CHOICES, broken
    from ..pipeline.target_sequence import make_sequence, source_designations
    from .params import rule_set as load_rule_set

    fmt = (fmt or "seqn").lower()
    if fmt not in FORMATS:
        raise InputError("--format", "format", f"unknown format {fmt!r} (want one of: {', '.join(FORMATS)})")
    if handoff_choice not in HANDOFF_CHOICES:
        raise InputError("--handoff", "handoff", f"unknown choice {handoff_choice!r} (want one of: "
                                                  f"{', '.join(HANDOFF_CHOICES)})")
    if out is not None:
        out = check_output_file(out)  # before the prediction: a bad path costs nothing
        check_not_input(out, src, products_root=products_root)  # -o SRC would replace the downlink (or a product)
    # a named file or built-in is read (and refused) before the downlink; none named: chosen from the downlink
    rule_set = load_rule_set(rules_path, rule_options, sigma_position_m, sigma_yaw_deg)
    source = open_source(src, products_root=products_root)
    if rules_path is None:
        rule_set = load_rule_set(None, rule_options, sigma_position_m, sigma_yaw_deg, dl=source.downlink)
    from .selfcal import self_calibrate, with_fits

    designations = source_designations(source)
    # the stop whose images make_sequence reads (None: make_sequence says why the target is unknown)
    position = designation_position(source.downlink, target, designations)
    selfcal = self_calibrate(source, stereo_selfcal, only=lambda im: im.position == position)
    fits = selfcal.records
    doc, checks, pred, record = make_sequence(source, target, params=rule_set.predict, rules=rule_set.flight,
                                              rules_used=rule_set.to_dict(), render_views=False,
                                              handoff_choice=handoff_choice, selfcal_fits=fits,
                                              designations=designations)
    summary = {
        "target": target, "designated_now": record.designated_from == "mark",
        "confidence": pred.confidence, "p_simulated": pred.p_simulated, "calibration": pred.calibration,
        "rules": [c.to_dict() for c in checks],
        "risks": [r.to_dict() for r in pred.risks], "path_length_m": pred.plan.path_length_m,
        "stops": len(pred.plan.stops) - 1, "seconds": pred.seconds,
        "products_read": {k: str(v) for k, v in source.read_from.items()},
        "rules_file": rule_set.summary(),
    }
    from ..io.provenance import provenance

    # every --json document carries how it was made, the NO-GO one (exit 1, no sequence) included
    summary["provenance"] = with_fits(provenance(dict({"downlink": source.downlink.source_sha256,
                                                       "rules_file": rule_set.sha256},
                                                      **{name: path for name, path in source.read_from.items()})), fits)
    selfcal.keep()  # the inputs were good (a NO-GO below is an answer): the next command takes these fits
    bad = broken(checks)
    stderr_console().print(f"rules: {rule_set.source}" + (f" ({rule_set.chosen_by})" if rule_set.chosen_by else ""),
                           highlight=False, markup=False)
    _print(checks, pred, target)
    if bad:
        summary["ok"] = False
        raise CommandFailed(f"{target}: {len(bad)} flight rule(s) broken, no sequence written: "
                            + "; ".join(f"{c.rule} ({c.message})" for c in bad), payload=summary)
    text = FORMATTERS[fmt](doc)
    summary["ok"] = True
    summary["commands"] = len(doc["commands"])
    summary["total_duration_s"] = doc["total_duration_s"]
    if out is not None:
        write_output_text(out, text)
        summary["written_to"] = str(out)
    if json_out:
        if out is None:
            summary["sequence"] = text  # stdout carries one JSON document
        emit_json(summary)
    elif out is None:
        sys.stdout.write(text)


def _print(checks, pred, target):
    from rich.table import Table

    con = stderr_console()
    t = Table(title=f"flight rules for target {target} (predicted P(success) {pred.confidence:.2f}; "
                    f"simulated {pred.p_simulated:.2f})")
    for c in ("rule", "ok", "detail"):
        t.add_column(c)
    for c in checks:
        t.add_row(c.rule, ("ok" if c.ok else "BROKEN") if c.blocking else ("ok" if c.ok else "advisory"), c.message)
    con.print(t)
    if pred.risks:
        r = Table(title="stops and handoffs at risk")
        for c in ("stop", "camera", "what", "P", "why"):
            r.add_column(c)
        for k in pred.risks:
            r.add_row(str(k.stop), k.camera, k.what, "-" if k.probability is None else f"{k.probability:.2f}", "; ".join(k.reasons))
        con.print(r)
