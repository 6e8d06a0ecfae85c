"""The soil's thresholded specks against the pixel footprint they are rendered with (docs/simulator.md, "Specks and
range").

    PYTHONPATH=. .venv/bin/python docs/scripts/speck_cover.py

On 0.5 m x 0.5 m of flat ground (a 0.5 mm grid, appearance seed 7), per footprint: the mean dark-speck cover as
the renderer makes it today (``specks="lod"``: thresholded from the footprint-faded noise), as the ``filtered``
mode makes it, and what a camera would see of the full-detail specks: their dark amount box-averaged over a
footprint-sized cell (mean, and the share of pixels at least half dark).
"""
from dataclasses import replace

import numpy as np

from scipctl.sim.appearance import SOIL_SPECKS, make_appearance

app = make_appearance(np.random.default_rng(7), np.zeros((0, 3)))
filt = replace(app, specks="filtered")
g = np.arange(0, 0.5, 0.0005)
X, Y = np.meshgrid(g + 3.0, g)
PT = np.ascontiguousarray(np.stack([X.ravel(), Y.ravel(), np.zeros(X.size)]), np.float32)
full, _ = SOIL_SPECKS.apply(app.spots.eval_T(PT, None))
full = full.reshape(X.shape)
print("| footprint (mm) | today's (lod): mean dark | filtered: mean dark | camera (box mean of full detail): mean dark | "
      "pixels >= half dark: lod | filtered | camera |")
print("| --- | --- | --- | --- | --- | --- | --- |")
for fp_mm in (1.3, 2.3, 3.7, 5.0, 7.3, 10.0, 19.0):
    fp = np.full(PT.shape[1], fp_mm / 1000, np.float32)
    lod, _ = app._specks(app.spots, SOIL_SPECKS, PT, fp)
    fil, _ = filt._specks(filt.spots, SOIL_SPECKS, PT, fp)
    k = max(int(round(fp_mm / 0.5)), 1)
    n = (full.shape[0] // k) * k
    box = full[:n, :n].reshape(n // k, k, n // k, k).mean(axis=(1, 3))
    print(f"| {fp_mm} | {lod.mean():.3f} | {fil.mean():.3f} | {box.mean():.3f} | {np.mean(lod >= 0.5):.3f} | "
          f"{np.mean(fil >= 0.5):.3f} | {np.mean(box >= 0.5):.3f} |")
