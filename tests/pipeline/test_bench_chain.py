"""Benchmark (not a timed test): the whole tracking chain for one target of a bundled sample sol — designation
stereo, the feature-guided tracks through the stops, the pancam->navcam handoff and the navcam->hazcam handoff
(scip, near and far; its timing was measured with consensus, docs/stereo-and-tracking.md) — and over the half-size traverse of tests/data/chain (16 stops, 5 hazcam handoffs).

    .venv/bin/python -m pytest tests/pipeline/test_bench_chain.py --benchmark-enable
"""

from pathlib import Path

import pytest

from scipctl.io.downlink import read_downlink
from scipctl.pipeline.chain import run_chain
from tests.pipeline.chain_expected import EXPECTED_FINAL_PX

ROOT = Path(__file__).resolve().parents[2]
SOLS = {
    "paper-s1-straight-t2": (ROOT / "sample_sols/mcap/paper-s1-straight.mcap", "t2"),
    "traverse-half-t1": (ROOT / "tests/data/chain/traverse-s1-straight-half.mcap", "t1"),
}


@pytest.mark.parametrize("case", list(SOLS))
def test_bench_chain(benchmark, case):
    if not benchmark.enabled:
        pytest.skip("measured with --benchmark-enable only")
    path, tid = SOLS[case]
    dl = read_downlink(path)
    start = min((im for im in dl.images if im.camera == "pancam" and im.eye == "left"), key=lambda i: i.time_s)
    mk = dl.target(tid).mark_in(start.product_id)
    steps = benchmark.pedantic(run_chain, args=(dl, start, [mk.u, mk.v]), kwargs={"target_id": tid},
                               rounds=2, iterations=1)
    assert steps[-1].camera == "hazcam"
    # the answer timed is the answer the chain tests bound (tests/pipeline/chain_expected.py: measured on both
    # OpenCV builds, x1.25); the traverse's own bounds live in test_chain.py
    sol = path.stem
    if sol in EXPECTED_FINAL_PX and tid in EXPECTED_FINAL_PX[sol]:
        assert steps[-1].error_px is not None and steps[-1].error_px <= EXPECTED_FINAL_PX[sol][tid], steps[-1].error_px
