"""The uplink sequence for one target of an opened source: designation record -> prediction -> flight rules ->
sequence document (:mod:`.sequence` builds, checks and formats; this module puts them together)."""

from __future__ import annotations

from ..errors import CommandFailed


def source_designations(source):
    """The :class:`~scipctl.pipeline.designate.Designation` records of ``source``'s ``targets.json`` (an opened
    :class:`~scipctl.io.workspace` source), or None when it has none."""
    from .designate import designations_from_doc

    doc = source.load_json("targets.json")
    return designations_from_doc(doc, str(source.read_from.get("targets.json", "targets.json")))


def make_sequence(source, target: str, params=None, rules=None, pred=None, record=None, rules_used=None,
                  render_views: bool = True, handoff_choice: str = "scip", selfcal_fits=None, designations=...):
    """Everything ``scipctl sequence`` does short of writing, for ``source`` (an opened
    :class:`~scipctl.io.workspace` source, whose ``targets.json`` and ``handoff.json`` are read if there):
    :func:`sequence_for` on its downlink. ``designations``: :func:`source_designations` of ``source`` when the
    caller has read them already (the default reads them, unless ``pred`` and ``record`` are given)."""
    if designations is ...:
        designations = source_designations(source) if pred is None or record is None else None
    from .handoff import table1_rows_from_doc

    handoff_doc = source.load_json("handoff.json")
    rows = table1_rows_from_doc(handoff_doc, str(source.read_from.get("handoff.json", "handoff.json")))
    return sequence_for(source.downlink, target, designations, rows, params=params, rules=rules, pred=pred,
                        record=record, rules_used=rules_used, render_views=render_views, handoff_choice=handoff_choice,
                        selfcal_fits=selfcal_fits)


def sequence_for(dl, target: str, designations=None, table1_rows=None, params=None, rules=None, pred=None,
                 record=None, rules_used=None, render_views: bool = True, handoff_choice: str = "scip",
                 selfcal_fits=None):
    """The prediction and sequence for ``target`` of the downlink ``dl``: returns
    ``(doc or None, checks, prediction, record)`` (``record``: the target's
    :class:`~scipctl.pipeline.designate.Designation`).

    The target is the one designated in ``designations`` (the :class:`Designation` records of ``targets.json``),
    else designated now from its mark in the first left pancam image (:func:`~.predict.resolve_target`).
    ``table1_rows``: the handoff accuracy rows (``handoff.json``'s ``table1``); ``handoff_choice``: how the
    handoff method is chosen (:data:`~.sequence.HANDOFF_CHOICES`: ``scip``, the default, or ``best-single``).
    ``rules_used``: :meth:`scipctl.pipeline.rules.RuleSet.to_dict` of the rule set, recorded in the document.
    ``doc`` is None when a blocking rule is broken. A ready ``pred`` (and its ``record``) is reused.
    ``render_views``: render the prediction's reduced-size expected views (only the report shows them; the
    sequence, its rules and its figures do not depend on them).
    ``selfcal_fits``: the stereo self-calibration ``dl`` carries (``commands.selfcal.self_calibrate``'s records; None:
    none), hashed into the document's provenance.
    :class:`CommandFailed` if the target has no reliable 3-D position; :class:`InputError` for bad products.
    """
    from .predict import predict_target, resolve_target

    if pred is None or record is None:
        record, now = resolve_target(dl, target, designations)
        if not record.has_position:
            raise CommandFailed(f"{target}: no reliable 3-D position for the target "
                                f"({record.reason or 'no stereo match'}); no sequence",
                                payload={"target": target, "designation": record.to_dict()})
        pred = predict_target(dl, record, params, designated_now=now, render_views=render_views)
    doc, checks = document_for(dl, record, pred, table1_rows, rules,
                               chain_params=None if params is None else params.chain, rules_used=rules_used,
                               handoff_choice=handoff_choice, selfcal_fits=selfcal_fits)
    return doc, checks, pred, record


def document_for(dl, record, pred, table1_rows=None, rules=None, chain_params=None, rules_used=None,
                 handoff_choice: str = "scip", selfcal_fits=None):
    """(sequence document or None when a blocking rule is broken, rule checks) for a prediction.

    ``table1_rows``: the handoff accuracy rows (``handoff.json``'s ``table1``); ``handoff_choice``: ``scip`` (the
    recommended handoff, with the packaged trust model's GO threshold at ``ScipParams().success_px``, as the
    prediction's chain runs it) or ``best-single`` (a paper method chosen by those rows);
    ``chain_params``: the windows and bands the uplinked chain commands carry (default ``ChainParams()``; the
    prediction's ``PredictParams.chain``); ``selfcal_fits``: as :func:`sequence_for`.
    """
    from ..io.provenance import provenance
    from .sequence import (broken, build_commands, canonical_hash, check_rules, choose_handoff,
                           sequence_document, _exposures)

    checks = check_rules(pred, dl.rover_config, rules)
    go = getattr(record, "go", None)
    if go is not None:
        # NO-GO: `designate` said "saved, but re-designate before planning on it": no uplink. A designation
        # without a verdict (a targets.json written before designations had one) has no row.
        from .sequence import RuleCheck

        p = getattr(record, "p_ok", None)
        checks.insert(0, RuleCheck(
            "designation-go", bool(go), p, None, "",
            ("the designation is GO" if go else "the designation is NO-GO")
            + ("" if p is None else f" (P(within {record.ok_tolerance_pct:g} % of the range) {p:.2f})")
            + ("" if go else ": re-designate (another pixel or image)")))
    if broken(checks):
        return None, checks
    handoff = choose_handoff(table1_rows, handoff_choice, *_scip_success_and_go() if handoff_choice == "scip" else ())
    inputs = {"downlink": dl.source_sha256, "target_record": canonical_hash(record.to_dict())}
    if table1_rows:
        inputs["handoff_results"] = canonical_hash(table1_rows)
    if rules_used is not None:
        inputs["rules_file"] = rules_used["sha256"]
    if selfcal_fits:
        inputs["stereo_selfcal"] = canonical_hash(selfcal_fits)
    prov = provenance(inputs, deterministic=True)
    cmds = build_commands(pred, record, handoff, _exposures(dl, dl.product(record.product_id).position),
                          chain_params=chain_params)
    return sequence_document(pred, record, checks, cmds, handoff, prov, mission=dl.mission, sol=dl.sol,
                             rules_used=rules_used), checks


def _scip_success_and_go() -> tuple:
    """``(success_px, GO threshold)`` of the chain's ``scip`` (``ScipParams``' defaults and the packaged trust model's
    threshold for that radius; None when the package has no model: never GO)."""
    from ..core.handoff.scip_params import ScipParams
    from ..io.trust_model import load_packaged_trust_model

    sp = ScipParams()
    model = load_packaged_trust_model()
    go = sp.go_min_p if sp.go_min_p is not None else (None if model is None else model.go_threshold(sp.success_px))
    return sp.success_px, go
