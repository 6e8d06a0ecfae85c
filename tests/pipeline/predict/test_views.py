"""scipctl.pipeline.predict.views: nominal view checks (texture of the tracker's window)."""

import numpy as np

from scipctl.pipeline import predict as P
from tests.pipeline import scene as S


def test_low_texture_target_is_flagged():
    patch = ((8.6, -0.9), (9.9, 0.9))
    world = S.World(flat_patch=patch)
    target = np.array([9.3, 0.0, 0.0])
    dl = S.make_downlink(world, targets={"t_sand": target})
    ter = P.Terrain(S.oracle_sources(world, dl, step=2))
    params = P.PredictParams(run_chain=False, uncertainty=P.UncertaintyParams(n_samples=50))
    pred = P.predict_target(dl, S.designation_record(dl, "t_sand"), params, terrain=ter)
    reasons = " ".join(" ".join(r.reasons) for r in pred.risks)
    assert "low texture" in reasons
