"""Extra targets for a simulated run: random true surface points near the target rock, seen by given images,
with exact marks (pure numerics, no files).

They multiply the handoff cases one rendering gives (the trust model of ``scip`` is fitted on them, see
docs/handoff.md "Trust: scip"): every point is on the true surface (a ray cast of the reference image's true
model), within ``max_radius_m`` of the rock's centre (where the scenarios' own targets are), and visible (in the
image, not occluded) in every one of the ``required`` images; its marks are :func:`~scipctl.sim.marks.compute_marks`'s.
"""

from __future__ import annotations

import numpy as np

from ..model import TargetMarks
from .marks import compute_marks, project_visible
from .scene import Scene
from .targets import Target

EXTRA_KIND = "extra"


def choose_extra_targets(scene: Scene, products: list, ref_id: str, required_ids: list, n: int,
                         rng: np.random.Generator, max_radius_m: float = 1.5, inner_frac: float = 0.06,
                         id_prefix: str = "x") -> list[Target]:
    """Up to ``n`` :class:`~scipctl.sim.targets.Target` (kind ``"extra"``), ids ``x01``, ``x02``...

    ``products``: the run's :class:`~scipctl.sim.products.ProductPlan` list; ``ref_id``: the image whose
    pixels are sampled (uniformly over its inner ``1 - 2 inner_frac`` part; the near left hazcam in practice);
    ``required_ids``: the images that must see each point inside the same inner part. Site frame, metres.
    """
    by = {p.product_id: p for p in products}
    ref = by[ref_id]
    m_ref = ref.model_true_site
    W, H = ref.width, ref.height
    k = max(20 * n, 200)
    uv = np.stack([rng.uniform(inner_frac * W, (1 - inner_frac) * W, k),
                   rng.uniform(inner_frac * H, (1 - inner_frac) * H, k)], 1)
    o, d = m_ref.unproject(uv)
    hits = scene.cast(o, d)
    ok = hits.hit & (np.hypot(hits.points[:, 0], hits.points[:, 1]) < max_radius_m)
    X = np.where(ok[:, None], hits.points, 0.0)
    for pid in [ref_id] + list(required_ids):
        p = by[pid]
        uvk, vis = project_visible(scene, p.model_true_site, p.width, p.height, X)
        f = inner_frac
        inner = ((uvk[:, 0] > f * p.width) & (uvk[:, 0] < (1 - f) * p.width)
                 & (uvk[:, 1] > f * p.height) & (uvk[:, 1] < (1 - f) * p.height))
        ok &= vis & inner
    idx = np.flatnonzero(ok)[:n]
    return [Target(f"{id_prefix}{i + 1:02d}", EXTRA_KIND, "random visible surface point (trust-model data)",
                   np.asarray(X[j], float)) for i, j in enumerate(idx)]


def extra_marks(scene: Scene, products: list, targets: list[Target]) -> list[TargetMarks]:
    """Exact marks of ``targets`` in every product that sees them."""
    return compute_marks(scene, products, targets) if targets else []
