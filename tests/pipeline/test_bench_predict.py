"""Speed of the pre-uplink prediction and of the report.

Measure with ``pytest tests/pipeline/test_bench_predict.py --benchmark-enable``;
without it only the small test-world case runs, once, as a plain test. Targets
(docs/sequence.md, docs/report.md): a prediction in well under 15 s per target
and a report under ~30 s for one simulated 1024 px sol, on the 2-core build
machine.
"""

import numpy as np
import pytest

from scipctl.pipeline import predict as P
from tests.pipeline import scene as S


def test_bench_prediction_test_world(benchmark):
    world, dl = S.cached("slab")
    ter = P.Terrain(S.oracle_sources(world, dl, step=2))
    rec = S.designation_record(dl, "t_slab")
    pred = benchmark.pedantic(P.predict_target, args=(dl, rec), kwargs={"terrain": ter},
                              rounds=1 if benchmark.disabled else 3, iterations=1)
    assert pred.mc.n_samples == P.UncertaintyParams().n_samples and pred.chain is not None
    assert np.isfinite(pred.confidence)


def test_bench_report_simulated_sol(benchmark, tmp_path):
    if benchmark.disabled:
        pytest.skip("measured with --benchmark-enable only (simulates a 1024 px sol first, ~1 min)")
    from scipctl.commands.report import build
    from scipctl.io.downlink import write_downlink
    from scipctl.io.workspace import open_source
    from scipctl.sim.build import build_run

    sol = tmp_path / "paper-s1-straight.mcap"
    write_downlink(build_run("paper", "s1-straight", 0).downlink, sol)
    source = open_source(sol)
    html, summary, _ = benchmark.pedantic(build, args=(source,), rounds=1, iterations=1)
    benchmark.extra_info["seconds"] = summary["seconds"]
    assert html.count("<img ") > 0 and len(summary["targets"]) == 3
