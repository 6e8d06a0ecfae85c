"""The uplink sequence for one target of an opened source: designation record -> prediction -> flight rules ->
sequence document (:mod:`.sequence` builds, checks and formats; this module puts them together)."""

from __future__ import annotations

from ..errors import CommandFailed, InputError


def make_sequence(source, target: str, params=None, rules=None, pred=None, record=None):
    """Everything ``scipctl sequence`` does short of writing, for ``source`` (an opened
    :class:`~scipctl.io.workspace` source, whose ``targets.json`` and ``handoff.json`` are read if there):
    :func:`sequence_for` on its downlink."""
    targets_doc = None
    if pred is None or record is None:
        targets_doc = source.load_json("targets.json")
        if targets_doc is not None and not isinstance(targets_doc, dict):
            raise InputError(str(source.read_from["targets.json"]), "targets",
                             "expected a JSON object with a 'targets' list")
    handoff_doc = source.load_json("handoff.json")
    rows = handoff_doc.get("table1") if isinstance(handoff_doc, dict) else None
    return sequence_for(source.downlink, target, targets_doc, rows, params=params, rules=rules, pred=pred, record=record)


def sequence_for(dl, target: str, targets_doc=None, table1_rows=None, params=None, rules=None, pred=None, record=None):
    """The prediction and sequence for ``target`` of the downlink ``dl``: returns
    ``(doc or None, checks, prediction, record)``.

    The target is the one designated in ``targets_doc`` (``targets.json``), else designated now from its mark in
    the first left pancam image (:func:`~.predict.resolve_target`). ``table1_rows``: the handoff accuracy rows
    (``handoff.json``'s ``table1``) that choose the handoff method. ``doc`` is None when a blocking rule is
    broken. A ready ``pred`` (and its ``record``) is reused. :class:`CommandFailed` if the target has no reliable
    3-D position; :class:`InputError` for bad products.
    """
    from .predict import predict_target, resolve_target

    if pred is None or record is None:
        record, now = resolve_target(dl, target, targets_doc)
        if not record.get("ok", True) or record.get("xyz_site_m") is None:
            raise CommandFailed(f"{target}: no reliable 3-D position for the target "
                                f"({record.get('reason') or 'no stereo match'}); no sequence",
                                payload={"target": target, "designation": record})
        pred = predict_target(dl, record, params, designated_now=now)
    doc, checks = document_for(dl, record, pred, table1_rows, rules)
    return doc, checks, pred, record


def document_for(dl, record, pred, table1_rows=None, rules=None):
    """(sequence document or None when a blocking rule is broken, rule checks) for a prediction.

    ``table1_rows``: the handoff accuracy rows (``handoff.json``'s ``table1``) that choose the handoff method.
    """
    from ..io.provenance import provenance
    from .sequence import (broken, build_commands, canonical_hash, check_rules, choose_handoff,
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
