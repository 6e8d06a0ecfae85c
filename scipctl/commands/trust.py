"""``scipctl trust-evidence`` and ``scipctl fit-trust``: the evidence table of ``scip``'s trust model from
downlinks with marks, and the model fitted on such tables (docs/handoff.md, "Trust: scip")."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Optional

from ..errors import InputError
from .output import emit_json, note, stderr_console


def _sim_record_path(src: Path) -> Path:
    """Where the simulator's record of a downlink is (``X.mcap`` -> ``X.sim.json``); it may not exist."""
    return src.with_name(src.name[: -len(src.suffix)] + ".sim.json") if src.suffix else src.with_name(src.name + ".sim.json")


def _sim_record(src: Path) -> dict:
    """The simulator's ``.sim.json`` beside a downlink (``X.mcap`` -> ``X.sim.json``), or {}."""
    p = _sim_record_path(src)
    if not p.is_file():
        return {}
    try:
        return json.loads(p.read_text(encoding="utf-8"))
    except ValueError:
        raise InputError(str(p), "sim record", "not JSON") from None


def family_of_record(rec: dict) -> str:
    """The family name of a ``.sim.json`` record: its ``family`` (a name, as ``docs/scripts/trust_render.py`` writes
    it, or a realised scene family, as ``synth --family`` writes it: its ``name``), else its scenario."""
    fam = rec.get("family")
    if isinstance(fam, dict):
        fam = fam.get("name")
    return str(fam or rec.get("scenario") or "unknown")


def trust_evidence(srcs: list, out: Path, family: Optional[str], json_out: bool, products_root=None,
                   stereo_selfcal: bool = True) -> None:
    """Write the evidence rows of every marked target of ``srcs`` to ``out`` (JSON lines, atomically): first a
    ``{"provenance": ...}`` line (tool version, command line, each input's SHA-256, the stereo self-calibration),
    then one row per line. ``stereo_selfcal``: the navcam and hazcam pairs re-aligned first, as
    ``simulate-handoff`` does (commands/selfcal.py)."""
    from ..io.atomic import check_not_input, check_output_file, write_output_text
    from ..io.provenance import provenance, sha256_file
    from ..io.workspace import open_source
    from ..pipeline.trust_data import OccludedTargetError, evidence_rows
    from ..pipeline.stereo_selfcal import handoff_pairs
    from .selfcal import self_calibrate
    from .sources import distinct_sources, source_names

    out = check_output_file(out)
    srcs = distinct_sources(srcs)  # a downlink named twice would give its rows twice (weighted twice in the fit)
    for s in srcs:  # -o SRC (or its .sim.json) replaced the downlink with the table (exit 0)
        check_not_input(out, s, products_root=products_root)
        sim = _sim_record_path(Path(s))
        if out.resolve() == sim.resolve():
            raise InputError(str(out), "-o", f"would overwrite the input {sim} (the simulator's record of a downlink); "
                             "give a file outside the inputs")
    sources = [open_source(s, products_root=products_root) for s in srcs]  # every input checked before any work
    rows, all_fits = [], []
    con = stderr_console()
    for src, source, name in zip(srcs, sources, source_names(srcs)):
        rec = _sim_record(Path(src))
        # the records only: trust-evidence writes nothing beside its inputs (their saved fits are taken, none added)
        all_fits.append(self_calibrate(source, stereo_selfcal, only=handoff_pairs).records)
        fam = family or family_of_record(rec)
        meta = {k: rec[k] for k in ("scenario", "seed", "run", "scene_seed") if k in rec}
        meta["downlink_sha256"] = source.downlink.source_sha256
        occ = rec.get("occluded_targets", [])
        if not isinstance(occ, list) or not all(isinstance(o, dict) and isinstance(o.get("id"), str) for o in occ):
            raise InputError(str(src), "sim record occluded_targets", "not a list of {id: ...} records")
        try:
            got = evidence_rows(source.downlink, name, str(fam), meta, occluded_ids=[o["id"] for o in occ])
        except OccludedTargetError as e:
            raise InputError(str(src), "sim record occluded_targets", str(e)) from None
        note(f"{name}: {len(got)} candidate rows, family {fam}")
        rows += got
    prov = provenance({f"downlink{i}": source.downlink.source_sha256 for i, source in enumerate(sources)})
    for i, src in enumerate(srcs):
        prov["inputs"][f"downlink{i}"]["path"] = str(src)
        sim = _sim_record_path(Path(src))
        if sim.is_file():  # the record gave the rows their family and occluded flags: an input too
            prov["inputs"][f"sim_record{i}"] = {"path": str(sim), "sha256": sha256_file(sim)}
    # per downlink, in input order: the pairs' fits, or false with --no-stereo-selfcal
    prov["stereo_selfcal"] = [False if f is None else f for f in all_fits]
    head = json.dumps({"provenance": prov}, sort_keys=True, allow_nan=False) + "\n"
    write_output_text(out, head + "".join(json.dumps(r.to_dict(), sort_keys=True, allow_nan=False) + "\n" for r in rows))
    if json_out:
        emit_json({"out": str(out), "rows": len(rows), "targets": len({(r.group, r.target) for r in rows})})
    del con


def read_rows(paths: list) -> list:
    from ..core.handoff.evidence import Evidence
    from ..core.handoff.trust_model import FEATURES, feature_matrix
    from ..pipeline.trust_data import EvidenceRow

    rows = []
    for p in paths:
        p = Path(p)
        if not p.is_file():
            raise InputError(str(p), "evidence table", "no such file")
        if p.suffix == ".gz":
            import gzip

            try:
                text = gzip.decompress(p.read_bytes()).decode("utf-8")
            except (OSError, EOFError, UnicodeDecodeError) as e:
                raise InputError(str(p), "evidence table", f"not a gzip'd UTF-8 table ({e})") from None
        else:
            text = p.read_text(encoding="utf-8")
        for i, line in enumerate(text.splitlines(), 1):
            if not line.strip():
                continue
            try:
                d = json.loads(line)
                if isinstance(d, dict) and set(d) == {"provenance"}:
                    continue  # the table's header (trust-evidence writes one)
                row = EvidenceRow.from_dict(d)
                feature_matrix([Evidence.from_dict(row.evidence)], FEATURES)  # the method named, every feature a number
                if row.error_px is not None and not (math.isfinite(row.error_px) and row.error_px >= 0):
                    raise ValueError(f"error_px: {row.error_px}: want a finite number >= 0 or null")
                rows.append(row)
            except (ValueError, KeyError, TypeError) as e:
                raise InputError(f"{p}:{i}", "evidence row", str(e)) from None
    if not rows:
        raise InputError(", ".join(str(p) for p in paths), "evidence table", "no rows")
    return rows


def fit_trust(tables: list, out: Path, report: Optional[Path], success_px: float, json_out: bool) -> None:
    """Fit the trust model on ``tables`` and write it to ``out``; with ``report``, the leave-one-family-out
    evaluation at ``success_px`` too."""
    from ..io.atomic import check_output_file, output_group
    from ..io.provenance import provenance
    from ..io.trust_model import trust_model_json
    from ..jsonutil import strict_json
    from ..pipeline.trust_fit import evaluate, fit_trust_model

    out = check_output_file(out)
    if report is not None:
        report = check_output_file(report, "--report")
        if report.resolve() == out.resolve():  # the report replaced the model just written (exit 0)
            raise InputError(str(report), "--report", "is the -o model file; give another file for the report")
    for option, path in (("-o", out), ("--report", report)):
        if path is not None and any(path.resolve() == Path(t).resolve() for t in tables):  # replaced a table
            raise InputError(str(path), option, "would overwrite an input evidence table; give another file")
    rows = read_rows(tables)
    prov = provenance({f"table{i}": str(t) for i, t in enumerate(tables)}, deterministic=True)
    import sklearn

    prov["scikit_learn"] = sklearn.__version__
    try:
        model = fit_trust_model(rows, provenance=prov)
    except ValueError as e:  # no row to fit on, or one outcome only (a constant model)
        raise InputError(", ".join(str(t) for t in tables), "evidence table", str(e)) from None
    doc = {"out": str(out), "n_rows": model.provenance["n_rows"], "n_targets": model.provenance["n_targets"],
           "families": model.provenance["training_families"],
           "go_min_p": {f"{f.success_px:g}": f.go_min_p for f in model.fits}}
    rep = None
    if report is not None:  # evaluated before anything is written: the model and its report, or neither
        rep = evaluate(rows, success_px, model)
        rep["provenance"] = provenance({f"table{i}": str(t) for i, t in enumerate(tables)})
    with output_group() as outputs:
        outputs.add_text(out, trust_model_json(model))
        if report is not None:
            outputs.add_text(report, json.dumps(strict_json(rep), indent=1, sort_keys=True, allow_nan=False,
                                                default=float) + "\n", "--report")
            doc["report"] = str(report)
    if json_out:
        emit_json(doc)
    else:
        note(f"{out}: {doc['n_targets']} targets, {doc['n_rows']} candidates, families {', '.join(doc['families'])}")
