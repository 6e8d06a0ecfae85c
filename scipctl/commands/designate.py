"""`scipctl designate`: pixel in a left stereo image -> 3-D target, saved for the other commands."""

from __future__ import annotations

import sys

from ..errors import CommandFailed, InputError
from .output import emit_json, note, stderr_console


def designate(src, product, camera, pixel, target_id, band_px, json_out, products_root=None, replace_id=False,
              stereo_selfcal: bool = True):
    """``scipctl designate``: the 3-D target at ``pixel`` of a left product, added to ``targets.json``. An id that
    is already a saved designation or one of the downlink's marked targets is refused unless ``replace_id``.
    ``stereo_selfcal``: the product's stereo pair re-aligned from its own matches first (commands/selfcal.py)."""
    from dataclasses import replace

    from ..io.provenance import provenance
    from ..io.workspace import open_source
    from ..pipeline.designate import (check_designation_input, check_target_id, designate as designate_target,
                                      designations_from_doc, parse_pixel, pick_left_product)
    from .params import designation_params
    from .selfcal import self_calibrate, with_fits

    uv = parse_pixel(pixel)
    if target_id is not None:
        check_target_id(target_id)
    source = open_source(src, products_root=products_root)
    source.check_writable()  # before the work: say now if the products cannot be saved anywhere
    dl = source.downlink
    left = pick_left_product(dl, product, camera)
    check_designation_input(dl, left, uv)  # before the work: a pixel outside the image costs nothing
    explicit_id = target_id is not None

    def saved_ids(doc) -> set:
        where = str(source.read_from.get("targets.json", "targets.json"))
        return {t.id for t in designations_from_doc(doc or {"targets": []}, where)}

    def free_id(doc, wanted):
        """``wanted`` if it may be (re)designated now, else InputError; without --id the first free d<N>."""
        existing = saved_ids(doc)
        if not explicit_id:
            n = 1
            while f"d{n}" in existing or any(t.id == f"d{n}" for t in dl.targets):
                n += 1
            return f"d{n}"
        if not replace_id:
            where = str(source.read_from.get("targets.json", "targets.json"))
            if wanted in existing:
                raise InputError("--id", "id", f"{wanted!r} is already a designated target in {where}; choose "
                                 "another --id, or pass --replace to designate it anew")
            if any(t.id == wanted for t in dl.targets):
                raise InputError("--id", "id", f"{wanted!r} is a marked target of the downlink; choose another --id, "
                                 "or pass --replace to designate it anew (the designation then stands for it)")
        return wanted

    # checked now (before the stereo work) and again when saving, under the products' lock: another command may
    # have saved a target meanwhile
    target_id = free_id(source.load_json("targets.json", default={"targets": []}), target_id)
    params = designation_params(band_px)
    from ..io.trust_model import PACKAGED_DESIGNATION, load_packaged_trust_model

    selfcal = self_calibrate(source, stereo_selfcal, only=lambda im: im.product_id == left.product_id)
    dl = source.downlink
    rec = designate_target(dl, dl.product(left.product_id), uv, target_id=target_id, params=params,
                           trust=load_packaged_trust_model(PACKAGED_DESIGNATION))
    rec = replace(rec, provenance=with_fits(provenance({"downlink": str(src)}), selfcal.records))
    if not rec.ok:
        # not saved; the same keys as a designation's document (null where there is no value; go false), so that
        # a script reading doc["go"] or doc["range_m"] gets an answer, not a KeyError
        payload = dict({k: None for k in _RESULT_KEYS}, **rec.to_dict(), saved_to=None)
        payload["go"] = False
        raise CommandFailed(f"{left.product_id}: no reliable stereo match at ({uv[0]:g}, {uv[1]:g}): {rec.reason}",
                            payload=payload)

    def add(doc):
        nonlocal rec
        doc = doc or {"targets": []}
        where = str(source.read_from.get("targets.json", "targets.json"))
        saved = designations_from_doc(doc, where)
        rec = replace(rec, id=free_id(doc, rec.id))  # without --id: the next free one if d<N> was taken meanwhile
        doc["targets"] = [t.to_dict() for t in saved if t.id != rec.id] + [rec.to_dict()]
        doc["provenance"] = rec.provenance
        return doc

    path, _ = source.update_json("targets.json", add, default={"targets": []})
    selfcal.keep()
    if source.location_note():
        note(source.location_note())
    if json_out:
        emit_json(dict(rec.to_dict(), saved_to=str(path)))
    _print(rec, path)
    if rec.go is False:
        from ..pipeline.designate import VETO_WARNING_PREFIX

        p = "n/a" if rec.p_ok is None else f"{rec.p_ok:.2f}"
        why = next((w[len(VETO_WARNING_PREFIX):] for w in rec.warnings if w.startswith(VETO_WARNING_PREFIX)), None)
        raise CommandFailed(f"{rec.id}: designation NO-GO: " + (f"{why} (P {p} not used)" if why else
                            f"P(within {rec.ok_tolerance_pct:g} % of the range of ideal stereo) {p}")
                            + "; saved, but re-designate (another pixel or image) before planning on it",
                            payload=None)  # the JSON record was already emitted above


_RESULT_KEYS = ("xyz_rover_m", "xyz_site_m", "range_m", "range_sigma_m", "ray_miss_m", "pose", "window_range_gap_pct",
                "surface_normal_rover", "normal_points", "incidence_deg", "p_ok", "ok_tolerance_pct", "go")


def _print(rec, saved_to):
    from rich.table import Table

    con = stderr_console()
    t = Table(title=f"target {rec.id} from {rec.product_id}", show_header=False)
    t.add_row("pixel (u, v)", f"{rec.pixel_uv[0]:.2f}, {rec.pixel_uv[1]:.2f}")
    t.add_row("rover xyz (m)", ", ".join(f"{x:.3f}" for x in rec.xyz_rover_m))
    t.add_row("site xyz (m)", ", ".join(f"{x:.3f}" for x in rec.xyz_site_m))
    sig = rec.range_sigma_m
    t.add_row("range (m)", f"{rec.range_m:.3f}" + (f" ± {sig:.3f}" if sig is not None else ""))
    t.add_row("match score", f"{rec.match_score:.3f}")
    if rec.go is not None:
        p = "n/a" if rec.p_ok is None else f"{rec.p_ok:.2f}"
        t.add_row("trust", f"{'GO' if rec.go else 'NO-GO'}: P(within {rec.ok_tolerance_pct:g} % of the range) {p}")
    eo = rec.epipolar_offset_px
    t.add_row("epipolar offset (px)", "n/a" if eo is None else f"{eo:+.2f}")
    gap = rec.window_range_gap_pct  # point stereo's range against the window's dense-stereo median
    t.add_row("window range gap (% of range)", "n/a" if gap is None else f"{gap:.2f}")
    n = rec.surface_normal_rover
    t.add_row("surface normal (rover)", "n/a" if n is None else ", ".join(f"{x:+.2f}" for x in n))
    t.add_row("warnings", "; ".join(rec.warnings) or "none")
    t.add_row("saved to", str(saved_to))
    con.print(t)
    sys.stderr.flush()
