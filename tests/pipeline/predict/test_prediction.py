"""scipctl.pipeline.predict.prediction: run_prediction on its grouped inputs gives predict_target's answer."""

from scipctl.pipeline import predict as P
from tests.pipeline import scene as S


def test_run_prediction_on_a_designation_and_sigmas_is_predict_target(slab_case):
    _, dl, ter = slab_case
    rec = S.designation_record(dl, "t_slab")
    params = P.PredictParams(run_chain=False, uncertainty=P.UncertaintyParams(n_samples=60))
    via_target = P.predict_target(dl, rec, params, terrain=ter)
    ctx = P.target_context(dl, rec)
    plan = P.plan_approach(ctx.start, ctx.target_site_m, ter, dl.rover_config, params.approach,
                           designation_camera=ctx.product.camera, uncertainty=params.uncertainty)
    sig = P.PoseSigmas(*P.sigmas_for(ctx.product, params.uncertainty))
    from scipctl.io.prediction_calibration import load_packaged_prediction_calibration

    direct = P.run_prediction(plan, ter, dl.rover_config, rec, ctx.product.pixels_float(),
                              ctx.product.camera_model.transformed(ctx.start.T_site_rover), sig, params,
                              calibration=load_packaged_prediction_calibration(params.route))
    a, b = via_target.to_dict(), direct.to_dict()
    a.pop("seconds"), b.pop("seconds")
    assert a == b
    assert direct.sigma_source == sig.source and direct.mc.sigma_position_m == sig.position_m
