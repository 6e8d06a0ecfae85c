"""`scipctl sequence`: plan the single-cycle approach to a target, predict it, check the flight rules, and
emit the uplink command sequence (SeqN-style text, JSON, or plain text). No sequence when a rule is broken."""

from __future__ import annotations

import sys

from ..cli import CommandFailed, emit_json, stderr_console
from ..model import InputError

FORMATS = ("seqn", "json", "text")


def make_sequence(source, target: str, params=None, rules=None, pred=None, record=None):
    """Everything the command does short of writing: returns ``(doc or None, checks, prediction, record)``.

    ``doc`` is None when a blocking rule is broken. A ready ``pred`` (and its ``record``) is reused.
    """
    from ..pipeline.predict import predict_target, resolve_target

    dl = source.downlink
    if pred is None or record is None:
        targets_doc = source.load_json("targets.json")
        if targets_doc is not None and not isinstance(targets_doc, dict):
            raise InputError(str(source.read_from["targets.json"]), "targets",
                             "expected a JSON object with a 'targets' list")
        record, now = resolve_target(dl, target, targets_doc)
        if not record.get("ok", True) or record.get("xyz_site_m") is None:
            raise CommandFailed(f"{target}: no reliable 3-D position for the target "
                                f"({record.get('reason') or 'no stereo match'}); no sequence",
                                payload={"target": target, "designation": record})
        pred = predict_target(dl, record, params, designated_now=now)
    handoff_doc = source.load_json("handoff.json")
    rows = handoff_doc.get("table1") if isinstance(handoff_doc, dict) else None
    doc, checks = document_for(dl, record, pred, rows, rules)
    return doc, checks, pred, record


def document_for(dl, record, pred, table1_rows=None, rules=None):
    """(sequence document or None when a blocking rule is broken, rule checks) for a prediction."""
    from ..io.provenance import provenance
    from ..pipeline.sequence import (broken, build_commands, canonical_hash, check_rules, choose_handoff,
                                     sequence_document, _exposures)

    checks = check_rules(pred, dl.rover_config, rules)
    if broken(checks):
        return None, checks
    handoff = choose_handoff(table1_rows)
    inputs = {"downlink": dl.source_sha256, "target_record": canonical_hash(record)}
    if table1_rows:
        inputs["handoff_results"] = canonical_hash(table1_rows)
    prov = provenance(inputs, deterministic=True)
    cmds = build_commands(pred, record, handoff, _exposures(dl, dl.product(record["product_id"]).position))
    return sequence_document(pred, record, checks, cmds, handoff, prov, mission=dl.mission, sol=dl.sol), checks


def uncertainty_params(sigma_position_m=None, sigma_yaw_deg=None):
    """PredictParams with the operator's pose-error sigmas (None: from the downlink); InputError if not > 0."""
    import math
    from dataclasses import replace

    from ..pipeline.predict import PredictParams

    for name, v in (("--sigma-position-m", sigma_position_m), ("--sigma-yaw-deg", sigma_yaw_deg)):
        if v is not None and not (math.isfinite(v) and v > 0):
            raise InputError(name, name.lstrip("-").replace("-", "_"), f"must be a positive number, got {v}")
    p = PredictParams()
    u = replace(p.uncertainty, sigma_position_m=sigma_position_m,
                sigma_yaw_rad=None if sigma_yaw_deg is None else math.radians(sigma_yaw_deg))
    return replace(p, uncertainty=u)


def run(src, target, out, fmt, json_out, sigma_position_m=None, sigma_yaw_deg=None, products_root=None):
    from ..io.atomic import atomic_write_text
    from ..io.workspace import open_source
    from ..pipeline.sequence import FORMATTERS, broken

    fmt = (fmt or "seqn").lower()
    if fmt not in FORMATS:
        raise InputError("--format", "format", f"unknown format {fmt!r} (want one of: {', '.join(FORMATS)})")
    params = uncertainty_params(sigma_position_m, sigma_yaw_deg)
    source = open_source(src, products_root=products_root)
    doc, checks, pred, record = make_sequence(source, target, params=params)
    summary = {
        "target": target, "designated_now": bool(record.get("designated_from") == "mark"),
        "confidence": pred.confidence, "rules": [c.to_dict() for c in checks],
        "risks": [r.to_dict() for r in pred.risks], "path_length_m": pred.plan.path_length_m,
        "stops": len(pred.plan.stops) - 1, "seconds": pred.seconds,
        "products_read": {k: str(v) for k, v in source.read_from.items()},
    }
    bad = broken(checks)
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
        try:
            atomic_write_text(out, text)
        except OSError as e:
            raise InputError(str(out), "-o", f"cannot write: {e.strerror or e}") from None
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
    t = Table(title=f"flight rules for target {target} (predicted P(success) {pred.confidence:.2f})")
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
