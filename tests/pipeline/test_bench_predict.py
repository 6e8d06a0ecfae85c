"""Speed of the pre-uplink prediction and of the report.

Measure with ``pytest tests/pipeline/test_bench_predict.py --benchmark-enable``;
without it only the small test-world case runs, once, as a plain test. Targets
(docs/sequence.md, docs/report.md): a prediction in well under 15 s per target
and a report under ~30 s for one simulated 1024 px sol, on the 2-core build
machine.
"""

import os
import resource
import subprocess
import sys
from pathlib import Path

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


@pytest.mark.parametrize("target", ["t1", "t2", "t3"])
def test_bench_sequence_command(benchmark, tmp_path, target):
    """``scipctl sequence paper-s1-straight.mcap --target tN`` as an operator runs it: a process (imports
    included); wall time by the benchmark, CPU seconds (user + system of the child) in ``extra_info``."""
    if benchmark.disabled:
        pytest.skip("measured with --benchmark-enable only (a process per round, ~7-10 s each)")
    root = Path(__file__).resolve().parents[2]
    sol = root / "sample_sols/mcap/paper-s1-straight.mcap"
    env = dict(os.environ, PYTHONPATH=str(root))
    argv = [sys.executable, "-c", "from scipctl.cli import app; app()", "sequence", str(sol), "--target", target,
            "--format", "json", "--json", "-o", str(tmp_path / "seq.json")]
    cpu = []

    def run():
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        p = subprocess.run(argv, env=env, cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        cpu.append((after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime))
        return p

    p = benchmark.pedantic(run, rounds=3, iterations=1)
    benchmark.extra_info["cpu_s"] = cpu
    benchmark.extra_info["load_average"] = os.getloadavg()
    assert p.returncode in (0, 1), p.stderr.decode()[-2000:]  # 1: a flight rule is broken (t3), still an answer
    assert '"confidence"' in p.stdout.decode()
