"""The stereo self-calibration a command applies to its downlink before any stereo runs (on by default;
``--no-stereo-selfcal`` reads the downlinked models as they are). docs/stereo-and-tracking.md, 'Stereo
self-calibration'."""

from __future__ import annotations

from typing import Callable, Optional


def self_calibrate(source, enabled: bool, only: Optional[Callable] = None) -> Optional[list]:
    """Replace ``source.downlink`` (a :class:`scipctl.io.workspace.Source`) by its copy whose stereo pairs (those
    whose left product ``only`` accepts; None: all) are re-aligned from their own matches
    (:func:`scipctl.pipeline.stereo_selfcal.self_calibrate_downlink`).

    Returns one JSON-ready record per fitted pair (for the products' provenance; a pair with too few matches keeps
    its downlinked model, ``applied`` false with the ``reason``), or None when ``enabled`` is false (nothing
    changes). Nothing is printed: stderr stays the command's (one line for an error)."""
    if not enabled:
        return None
    from ..pipeline.stereo_selfcal import self_calibrate_downlink

    dl, pairs = self_calibrate_downlink(source.downlink, only=only)
    source.downlink = dl
    return [p.to_dict() for p in pairs]


def with_fits(prov: dict, fits: Optional[list]) -> dict:
    """``prov`` (a provenance record) with the self-calibration it ran on: ``stereo_selfcal`` is the per-pair
    records, or false when the command ran with ``--no-stereo-selfcal``."""
    return dict(prov, stereo_selfcal=False if fits is None else fits)
