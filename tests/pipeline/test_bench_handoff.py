"""Benchmark (not a timed test): all handoff methods, near and far, for the three targets of one
bundled sample sol, shared dense stereo and registration included. Target: under 5 s.

    .venv/bin/python -m pytest tests/pipeline/test_bench_handoff.py --benchmark-enable
"""

from pathlib import Path

import pytest

from scipctl.core.handoff import ALL_METHODS, PAPER_METHODS
from scipctl.io.downlink import read_downlink
from scipctl.pipeline.handoff import build_setup, marked_targets, run_targets

SAMPLE = Path(__file__).resolve().parents[2] / "sample_sols/mcap/paper-s1-straight.mcap"


@pytest.mark.parametrize("fast", [False, True], ids=["full-res-stereo", "fast"])
@pytest.mark.parametrize("methods", ["paper", "all"])
def test_bench_handoff_one_downlink(benchmark, methods, fast):
    if not benchmark.enabled:
        pytest.skip("measured with --benchmark-enable only")
    import open3d  # noqa: F401  (import cost is paid once per process, not per downlink)

    dl = read_downlink(SAMPLE)
    names = PAPER_METHODS if methods == "paper" else None

    from scipctl.core.handoff import HandoffParams

    params = HandoffParams(dense_downsample=2 if fast else 1)

    def run():
        setup = build_setup(dl, params)  # fresh shared products every round
        kw = {} if names is None else {"methods": names}
        return run_targets(dl, setup, marked_targets(dl, setup), **kw)

    recs = benchmark.pedantic(run, rounds=3, iterations=1)
    # all methods: each from near and far, scip once per target
    assert len(recs) == (len(PAPER_METHODS) * 2 * 3 if names else (len(ALL_METHODS) - 1) * 2 * 3 + 3)
