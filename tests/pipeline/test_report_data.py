"""pipeline/report_data.py: the gain and saturation table judges 12-bit data against 12 bits."""

import numpy as np

from scipctl.io.images import encode_png
from scipctl.pipeline.report_data import image_stats
from tests.io.builders import make_small_downlink


def test_twelve_bit_data_is_not_called_dark():
    """Real MSL navcam products hold 12-bit data in 16-bit words: judged against 65535 they read as dark and flat
    (p99 0.03, "dark 58%; low contrast"), and saturation (4095) could never show."""
    dl = make_small_downlink(width=160, height=120)
    rng = np.random.default_rng(0)
    for i, im in enumerate(dl.images):
        px = rng.integers(800, 3000, (im.height, im.width)).astype(np.uint16)
        if i == 0:
            px[:60] = 4095  # half the image at the 12-bit ceiling
        im.png, im._pixels = encode_png(px), None
    stats = {s["product_id"]: s for s in image_stats(dl)}
    first = stats[dl.images[0].product_id]
    assert first["bits"] == 12 and first["saturated_fraction"] == 0.5 and "saturated 50.0%" in first["flags"]
    rest = [stats[im.product_id] for im in dl.images[1:]]
    assert all(s["bits"] == 12 and s["p99"] > 0.7 and not any("dark" in f or "contrast" in f for f in s["flags"])
               for s in rest)
