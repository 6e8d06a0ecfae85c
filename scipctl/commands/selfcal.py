"""The stereo self-calibration a command applies to its downlink before any stereo runs (on by default;
``--no-stereo-selfcal`` reads the downlinked models as they are), and the fits it keeps among the downlink's
products (``stereo_selfcal.json``) so that the next command on the same downlink does not fit a pair again.
docs/stereo-and-tracking.md, 'Stereo self-calibration'; docs/workspace.md."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Optional

CACHE_PRODUCT = "stereo_selfcal.json"  # the fits made so far, by pair key (pipeline.stereo_selfcal.pair_key)
CACHE_FORMAT = 1


@dataclass
class SelfCalRun:
    """What :func:`self_calibrate` did: ``records``, one JSON-ready record per fitted pair (None when the command
    runs with ``--no-stereo-selfcal``), and :meth:`keep`, which the command calls once its own products are
    written, to save the new fits for the next command (a command that stops on bad input leaves nothing)."""

    records: Optional[list]
    _keep: Callable[[], None] = lambda: None

    def keep(self) -> None:
        self._keep()


def self_calibrate(source, enabled: bool, only: Optional[Callable] = None) -> SelfCalRun:
    """Replace ``source.downlink`` (a :class:`scipctl.io.workspace.Source`) by its copy whose stereo pairs (those
    whose left product ``only`` accepts; None: all) are re-aligned from their own matches
    (:func:`scipctl.pipeline.stereo_selfcal.self_calibrate_downlink`).

    A pair fitted before by this code on the same pixels, models and parameters (its key is in the source's
    ``stereo_selfcal.json``) takes that fit, bit for bit what fitting again gives; :meth:`SelfCalRun.keep` adds the
    new fits to the product (:func:`_saved_fits`, :func:`_keep_fits`).

    The records (for the products' provenance): a pair with too few matches keeps its downlinked model, ``applied``
    false with the ``reason``; a fit taken from the product has the record of the fit made. ``enabled`` false:
    nothing changes and the records are None. Nothing is printed: stderr stays the command's (one line for an error)."""
    if not enabled:
        return SelfCalRun(None)
    from ..pipeline.stereo_selfcal import fit_code_identity, self_calibrate_downlink

    code = fit_code_identity()
    entries = _saved_fits(source, code)
    known = {k: e["fit"] for k, e in entries.items()}
    dl, pairs = self_calibrate_downlink(source.downlink, only=only, known=known)
    source.downlink = dl
    records = [p.to_dict() for p in pairs]
    if all(p.cached for p in pairs):
        return SelfCalRun(records)
    return SelfCalRun(records, lambda: _keep_fits(source, code, entries, pairs))


def _saved_fits(source, code: str) -> dict:
    """The entries of the source's ``stereo_selfcal.json`` made by this code, ``{pair key: {"left", "right",
    "camera", "fit": StereoRotationFit}}``; empty when there is none, or it was made by other code, or it cannot be
    read: a fit not found is made again, so a damaged or foreign file costs time, never an answer, and is replaced
    when the command saves its fits."""
    import json

    from ..core.stereo_selfcal import StereoRotationFit
    from ..errors import InputError

    try:
        path = source.product_path(CACHE_PRODUCT)
        if path is None:
            return {}
        doc = json.loads(path.read_text(encoding="utf-8"))
        if not (isinstance(doc, dict) and doc.get("format") == CACHE_FORMAT and doc.get("code") == code
                and isinstance(doc.get("fits"), dict)):
            return {}
        out = {}
        for key, e in doc["fits"].items():
            if not isinstance(e, dict):
                return {}
            out[key] = dict(e, fit=StereoRotationFit.from_dict(e.get("fit"), CACHE_PRODUCT, f"fits.{key}.fit."))
        return out
    except (OSError, UnicodeDecodeError, ValueError, InputError):
        return {}


def _keep_fits(source, code: str, entries: dict, pairs: list) -> None:
    """Save ``entries`` (as :func:`_saved_fits` gives them) with the fits of ``pairs`` added, as the source's
    ``stereo_selfcal.json`` (atomically, with provenance). A folder that takes no products leaves the command as it
    was: the saved fits only save time."""
    from ..errors import InputError
    from ..io.provenance import provenance

    fits = {k: dict(e, fit=e["fit"].to_dict()) for k, e in entries.items()}
    for p in pairs:
        fits[p.key] = {"left": p.left_product_id, "right": p.right_product_id, "camera": p.camera,
                       "fit": p.fit.to_dict()}
    doc = {"format": CACHE_FORMAT, "code": code, "fits": fits,
           "provenance": provenance({"downlink": source.downlink.source_sha256})}
    try:
        source.save_json(CACHE_PRODUCT, doc)
    except (OSError, InputError):
        pass


def with_fits(prov: dict, fits: Optional[list]) -> dict:
    """``prov`` (a provenance record) with the self-calibration it ran on: ``stereo_selfcal`` is the per-pair
    records, or false when the command ran with ``--no-stereo-selfcal``."""
    return dict(prov, stereo_selfcal=False if fits is None else fits)
