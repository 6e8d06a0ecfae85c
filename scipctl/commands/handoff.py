"""`scipctl simulate-handoff`: run the handoff methods offline on downlinks and score them against marks."""

from __future__ import annotations

from ..errors import InputError
from .output import emit_json, note, stderr_console

def _parse_methods(methods):
    """``--methods`` -> (method names in order, navcams in use, the (method, navcam) pairs to run).

    Each item is a method name (both navcams) or ``NAME-near`` / ``NAME-far``.
    """
    from ..core.handoff import ALL_METHODS

    if not methods or methods.strip() == "scip":  # the default: the recommended handoff alone
        return ["scip"], ["near", "far"], {("scip", n) for n in ("near", "far")}
    if methods.strip() == "all":  # scip first, then every other method
        names = ["scip"] + [m for m in ALL_METHODS if m != "scip"]
        return names, ["near", "far"], {(m, n) for m in names for n in ("near", "far")}
    names, pairs = [], set()
    for item in methods.split(","):
        item = item.strip()
        if not item:
            continue
        base, ncs = item, ("near", "far")
        for suffix in ("-near", "-far", ":near", ":far"):
            if item.endswith(suffix):
                base, ncs = item[: -len(suffix)], (suffix[1:],)
        if base not in ALL_METHODS:
            raise InputError("--methods", "methods", f"unknown method {item!r} (known: {', '.join(ALL_METHODS)}, optionally -near/-far)")
        if base not in names:
            names.append(base)
        pairs.update((base, n) for n in ncs)
    if not pairs:
        raise InputError("--methods", "methods", "no method named")
    return names, [n for n in ("near", "far") if any(p[1] == n for p in pairs)], pairs


def _fmt_stats(s):
    if s is None:
        return "-"
    return f"{s['mean_px']:.1f}±{s['std_px']:.1f} ({s['min_px']:.1f}-{s['max_px']:.1f})"


def _inputs(inputs: dict, trust_model) -> dict:
    """Provenance inputs: the downlinks, and a --trust-model file (p_success and go depend on it)."""
    return dict(inputs, trust_model=str(trust_model)) if trust_model is not None else inputs


def _note_replaced(source, recs) -> None:
    """Say when this run's handoff.json replaces one that held results this run does not (other targets or
    methods): ``sequence`` and ``report`` read the latest only."""
    try:
        old = source.load_json("handoff.json", default=None)
    except InputError:
        return  # unreadable: replaced without a word (the new one is what the other commands will read)
    if not isinstance(old, dict) or not isinstance(old.get("results"), list):
        return

    def key(r: dict) -> tuple:
        return r.get("target"), r.get("method"), r.get("navcam")

    new = {key(r.to_dict()) for r in recs}
    lost = [r for r in old["results"] if isinstance(r, dict) and key(r) not in new]
    if lost:
        methods = sorted({str(r.get("method")) for r in lost})
        targets = sorted({str(r.get("target")) for r in lost})
        note(f"handoff.json replaced: {len(lost)} earlier results not in this run (methods "
             f"{', '.join(methods)}; targets {', '.join(targets)}) are dropped; sequence and report read this run's "
             "results only")


def _from_pixel(dl, from_product, pixel):
    """``--pixel`` as ``(2,)`` after checking it and ``--from`` against ``dl``: InputError (exit 2) for a product
    that is not a left navcam image of the downlink, or a pixel outside it."""
    from ..pipeline.designate import parse_pixel

    p = dl.product(from_product)
    if p.camera != "navcam" or p.eye != "left":
        raise InputError(from_product, "camera", "--from must be a left navcam product (near or far)")
    uv = parse_pixel(pixel)
    if not (-0.5 <= uv[0] <= p.width - 0.5 and -0.5 <= uv[1] <= p.height - 0.5):
        raise InputError(from_product, "pixel", f"({uv[0]:g}, {uv[1]:g}) is outside the image")
    return uv


def simulate_handoff(srcs, target, from_product, pixel, methods, success_px, near, far, hazcam, chain, json_out,
                     fast=False, products_root=None, trust_model=None, chain_answer=None, stereo_selfcal: bool = True):
    """``scipctl simulate-handoff``: run the methods on each source, save its ``handoff.json``, print Table 1
    (and the chains with ``chain``); one JSON document on stdout with ``json_out``. ``stereo_selfcal``: each
    downlink's stereo pairs re-aligned from their own matches first (commands/selfcal.py): the navcam and hazcam
    pairs, and with ``chain`` every pair."""
    from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

    from ..io.provenance import provenance
    from ..io.workspace import open_source
    from ..pipeline.chain_targets import run_marked_chains
    from ..pipeline.handoff import build_setup, check_marked_target, find_products, marked_targets, run_targets, table1
    from .params import handoff_params, success_threshold
    from ..pipeline.stereo_selfcal import handoff_pairs
    from .selfcal import self_calibrate, with_fits
    from .sources import distinct_sources, source_names

    success_px = success_threshold(success_px)
    params = handoff_params(fast, success_px, trust_model)
    if (from_product is None) != (pixel is None):
        raise InputError("--from/--pixel", "pixel", "give both --from PRODUCT_ID and --pixel U,V, or neither")
    if from_product is not None and target is not None:  # the pixel's record would replace the target's scored one
        raise InputError("--target", "target", "selects marked targets; with --from/--pixel the answer is for that "
                         "pixel alone (leave --target out)")
    names, navcams, pairs = _parse_methods(methods)
    from ..pipeline.chain import CHAIN_ANSWERS

    if chain_answer is not None and chain_answer not in CHAIN_ANSWERS:
        raise InputError("simulate-handoff", "--chain-answer", f"must be one of {', '.join(CHAIN_ANSWERS)}, "
                                                               f"got {chain_answer!r}")
    if chain_answer is not None and not chain:
        raise InputError("simulate-handoff", "--chain-answer", "is the chain's answer: give --chain too")
    con = stderr_console()
    records, chains, per_dl, pending = [], [], [], []
    srcs = distinct_sources(srcs)  # a downlink named twice would count twice in Table 1
    sources = [open_source(s, products_root=products_root) for s in srcs]  # validate every input before any work
    uv = None
    for source in sources:
        source.check_writable()  # and say now if a handoff.json could not be saved
        # and a bad product or target option, before the stereo self-calibration's work
        find_products(source.downlink, hazcam, near, far)
        check_marked_target(source.downlink, target)
        if from_product is not None:
            uv = _from_pixel(source.downlink, from_product, pixel)
    n_work = sum(1 for _ in sources) * max(1, len(names) * len(navcams))
    with Progress(TextColumn("{task.description}"), BarColumn(), TextColumn("{task.completed}/{task.total}"),
                  TimeElapsedColumn(), console=con, transient=True, disable=not con.is_terminal) as prog:
        task = prog.add_task("handoff", total=n_work)
        for src, source, name in zip(srcs, sources, source_names(srcs)):
            selfcal = self_calibrate(source, stereo_selfcal, only=None if chain else handoff_pairs)
            fits = selfcal.records
            dl = source.downlink
            setup = build_setup(dl, params, hazcam=hazcam, near=near, far=far, shared=True)
            if from_product is not None:
                p = dl.product(from_product)
                nc = "near" if setup.near is not None and p.product_id == setup.near.product_id else (
                    "far" if setup.far is not None and p.product_id == setup.far.product_id else None)
                if nc is None:
                    setup = build_setup(dl, params, hazcam=hazcam, near=p.product_id if p.position == setup.hazcam.position else near,
                                        far=p.product_id if p.position != setup.hazcam.position else far, shared=True)
                    nc = "near" if p.position == setup.hazcam.position else "far"
                tlist = [("pixel", {nc: uv.tolist()}, None)]
                use_navcams = [nc]
            else:
                tlist = marked_targets(dl, setup, only=target)
                use_navcams = [n for n in navcams if n in setup.cases]
            done = [0]

            def progress(desc, _t=task):
                prog.update(_t, description=desc)

            recs = run_targets(dl, setup, tlist, methods=names, navcams=use_navcams, success_px=success_px,
                               progress=progress, downlink_name=name, only=pairs)
            prog.advance(task, len(names) * len(navcams))
            records.extend(recs)
            # saved after every source has run: a bad --near/--far/--hazcam/--target found at a later source
            # (exit 2) must not leave the earlier sources' handoff.json replaced
            saved_doc = {
                "provenance": with_fits(provenance(_inputs({"downlink": str(src)}, trust_model)), fits),
                "success_px": success_px,
                "results": [r.to_dict() for r in recs], "table1": table1(recs),
            }
            pending.append((source, selfcal, recs, saved_doc))
            per_dl.append({"downlink": name, "hazcam": setup.hazcam.product_id,
                           "near": setup.near.product_id if setup.near else None,
                           "far": setup.far.product_id if setup.far else None,
                           "dense_stereo_s": {k: round(c.nav.dense_seconds, 3) for k, c in setup.cases.items()},
                           "input_sha256": dl.source_sha256, "stereo_selfcal": False if fits is None else fits,
                           "saved_to": None})
            if chain:
                these = run_marked_chains(dl, name, target, answer=chain_answer, keyed=True)
                chains.extend(these)
                # saved with their keys: the report takes a chain back instead of running it again (chain_key.py)
                saved_doc["chains"] = [dict(c, steps=[s.to_dict() for s in c["steps"]]) for c in these]
            del done
    for (source, selfcal, recs, saved_doc), entry in zip(pending, per_dl):
        _note_replaced(source, recs)
        entry["saved_to"] = str(source.save_json("handoff.json", saved_doc))
        selfcal.keep()
        if source.location_note():
            note(source.location_note())
    rows = table1(records)
    doc = {
        "provenance": provenance(_inputs({f"downlink{i}": str(s) for i, s in enumerate(srcs)}, trust_model)),
        "success_px": success_px,
        "downlinks": per_dl,
        "results": [r.to_dict() for r in records],
        "table1": rows,
    }
    if chain:  # as a campaign records them: the key is handoff.json's, for the report (chain_key.py)
        doc["chains"] = [dict({k: v for k, v in c.items() if k != "key"}, steps=[s.to_dict() for s in c["steps"]])
                         for c in chains]
    # scip's NO-GO answers, and chains that end NO-GO: the command's answer is "no" (exit 1)
    nogo = [f"{r.downlink}:{r.target}" for r in records if r.method == "scip" and not r.go]
    nogo_chains = [f"{c['downlink']}:{c['target']}" for c in chains if not c.get("go")]
    if json_out and not nogo and not nogo_chains:
        emit_json(doc)
    _print_table(con, rows, records)
    _print_answers(con, records)
    if chain:
        _print_chains(con, chains)
    if nogo or nogo_chains:
        from ..errors import CommandFailed

        parts = []
        if nogo:
            parts.append(f"scip: NO-GO for {len(nogo)} of {sum(r.method == 'scip' for r in records)} targets "
                         f"({', '.join(nogo[:6])}{', ...' if len(nogo) > 6 else ''})")
        if nogo_chains:
            parts.append(f"chain: NO-GO for {len(nogo_chains)} of {len(chains)} chains "
                         f"({', '.join(nogo_chains[:6])}{', ...' if len(nogo_chains) > 6 else ''})")
        raise CommandFailed("; ".join(parts), payload=doc)


def _print_table(con, rows, records):
    from rich.table import Table

    from ..pipeline.paper_table1 import PAPER_TABLE1

    tab = Table(title=f"Handoff accuracy ({len({(r.downlink, r.target) for r in records})} targets) — compare the paper's Table 1")
    for c in ("method", "navcam", "success", "answered", "mean±std (range) px", "successes / failures px", "paper"):
        tab.add_column(c)
    for r in rows:
        split = "-"
        if r["refined"]:
            split = f"{_fmt_stats(r['successes'])} / {_fmt_stats(r['failures'])}"
        tab.add_row(r["method"], r["navcam"], f"{100 * r['success_rate']:.0f}%", f"{r['answered']}/{r['cases']}",
                    _fmt_stats(r["all"]), split, PAPER_TABLE1.get((r["method"], r["navcam"]), "(not in paper)"))
    con.print(tab)


def _print_answers(con, records):
    """Each target's answer from scip, and any answer with no mark to score it (--from/--pixel): the pixel, its
    error when scored, p_success and GO (Table 1 above only aggregates the scored ones)."""
    from rich.table import Table

    shown = [r for r in records if r.method == "scip" or r.error_px is None]
    if not shown:
        return
    tab = Table(title="Answers (scip, and unscored pixels)")
    for c in ("downlink", "target", "method", "navcam", "hazcam pixel (u, v)", "error px", "p_success", "GO"):
        tab.add_column(c)
    for r in shown:
        uv = "-" if r.predicted_uv is None else f"{r.predicted_uv[0]:.2f}, {r.predicted_uv[1]:.2f}"
        tab.add_row(r.downlink, r.target, r.method, str(r.navcam), uv,
                    "unscored" if r.error_px is None else f"{r.error_px:.2f}",
                    "-" if r.p_success is None else f"{r.p_success:.2f}",
                    "-" if r.go is None else ("GO" if r.go else "NO-GO"))
    con.print(tab)


def _print_chains(con, chains):
    from rich.table import Table

    for ch in chains:
        tab = Table(title=f"{ch['downlink']} target {ch['target']}: tracking chain")
        for c in ("stop", "camera", "kind", "tracked uv", "mark uv", "err px", "range m", "3-D err m", "p", "GO",
                  "trust"):
            tab.add_column(c)
        for s in ch["steps"]:
            f2 = lambda v: "-" if v is None else f"{v[0]:.1f},{v[1]:.1f}"  # noqa: E731
            tab.add_row(f"{s.position[0]}/{s.position[1]}", s.camera, s.kind, f2(s.tracked_uv), f2(s.mark_uv),
                        "-" if s.error_px is None else f"{s.error_px:.2f}",
                        "-" if s.range_m is None else f"{s.range_m:.2f}",
                        "-" if s.error_3d_m is None else f"{s.error_3d_m:.3f}",
                        "-" if s.p_success is None else f"{s.p_success:.2f}",
                        "GO" if s.go else f"NO-GO: {s.advice}", _trust(s))
        con.print(tab)
        if ch.get("error"):
            con.print(f"chain: {ch['error']}")
        con.print(f"chain {'GO' if ch.get('go') else 'NO-GO'}"
                  + ("" if ch.get("go") else f": {ch.get('advice')} ({ch.get('why')})"))


def _trust(step) -> str:
    """How far to trust a chain step (:class:`~scipctl.pipeline.chain.ChainStep`): ``ok`` or ``FLAG``, the
    feature status, and the reason (warning) if any."""
    parts = ["ok" if step.ok else "FLAG"]
    status = (step.extra or {}).get("feature_status")
    if status:
        parts.append(status)
    if (step.extra or {}).get("answer") == "closure":
        ref = (step.extra.get("closure") or {}).get("reference")
        parts.append(f"closure from {ref}")
    d = (step.extra or {}).get("designation") if step.kind == "designate" else None
    if d and d.get("p_ok") is not None:
        # the designation's p is for its 3-D point, not a pixel radius (pipeline/designation_trust.py)
        parts.append(f"p: 3-D point within {d.get('tolerance_pct', 1.0):g} % of the range")
        if d.get("veto"):
            parts.append(f"NO-GO whatever p: {d['veto']}")
    if step.reason:
        parts.append(str(step.reason))
    return " ".join(parts)
