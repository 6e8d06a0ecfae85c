"""io/report_html.py: what the report page draws and says, checked on small hand-made inputs (no report run)."""

import re

import numpy as np

from scipctl.core.handoff.registry import ALL_METHODS
from scipctl.io.report_html import STYLE, _chip_html, annotate_chip
from scipctl.pipeline.handoff import HandoffRecord
from scipctl.pipeline.report_data import chips_for_target
from tests.io.builders import make_small_downlink


def _hazcam_chip_with_every_method():
    dl = make_small_downlink(width=160, height=120)
    haz = next(im for im in dl.images if im.camera == "hazcam" and im.eye == "left")
    tid = dl.targets[0].id
    mk = dl.targets[0].mark_in(haz.product_id)  # the chip's centre
    recs = [HandoffRecord("x", tid, m, nc, "p", [1.0, 2.0], [mk.u - 32 + 8 * i, mk.v - 15 + 30 * j], None, None, None,
                          True, "", {}, 0.0) for i, m in enumerate(ALL_METHODS) for j, nc in enumerate(("near", "far"))]
    chips = chips_for_target(dl, tid, None, [], recs, 40, haz.product_id)
    return next(c for c in chips if c.product_id == haz.product_id)


def test_every_handoff_method_has_a_colour_of_its_own():
    """The chips coloured handoff predictions per "method (navcam)" label from 8 colours in turn: with the five
    methods the report runs from both navcams, alt-pure-kinematic and refined-kinematic were drawn in one colour
    from each navcam, and pure-geometric (near) in the designated marker's yellow."""
    chip = _hazcam_chip_with_every_method()
    html = _chip_html(chip, {})
    legend = re.findall(r'background:(#[0-9a-f]{6})"></span>(?:&#9650; |&#9660; )?([a-z-]+) \((near|far)\)', html)
    assert len(legend) == 2 * len(ALL_METHODS)
    colour = {}
    for css, method, _ in legend:
        colour.setdefault(method, set()).add(css)
    assert all(len(c) == 1 for c in colour.values()), colour  # near and far: the method's one colour
    per_method = [next(iter(c)) for c in colour.values()]
    assert len(set(per_method)) == len(ALL_METHODS), colour  # no two methods alike
    assert not set(per_method) & {s[2] for s in STYLE.values()}  # nor a true/designated/tracked/expected marker
    # the navcam is the marker's shape, said beside the label
    for nc, glyph in (("near", "&#9650;"), ("far", "&#9660;")):
        assert html.count(f"{glyph} ") == len(ALL_METHODS) and all(f"{glyph} {m} ({nc})" in html for m in ALL_METHODS)
    # and the chip is drawn in those colours: each method's marker alone puts its legend colour on the image
    for m in (m for m in chip.markers if m.kind == "predicted"):
        alone = annotate_chip(type(chip)(**{**chip.__dict__, "markers": [m]}), {})
        css = next(c for c, meth, nc in legend if f"{meth} ({nc})" == m.label)
        bgr = np.array([int(css[5:7], 16), int(css[3:5], 16), int(css[1:3], 16)], np.uint8)
        assert (alone == bgr).all(axis=2).any(), m.label
