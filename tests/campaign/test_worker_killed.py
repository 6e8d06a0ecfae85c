"""A worker killed in the middle of a campaign: its downlink runs again on a worker that lives, and the campaign
finishes with every downlink's records."""

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

from scipctl.campaign.results import DownlinkResult

ROOT = Path(__file__).resolve().parents[2]
SOLS = sorted((ROOT / "sample_sols/mcap").glob("*.mcap"))
TASK_PREFIX = "scipctl-campaign-"  # scipctl.campaign.run names each downlink's task so


def _campaign(args: list) -> subprocess.Popen:
    env = dict(os.environ, PYTHONPATH=str(ROOT) + (os.pathsep + os.environ["PYTHONPATH"] if os.environ.get("PYTHONPATH") else ""))
    return subprocess.Popen([sys.executable, "-c", "from scipctl.cli import app; app()", "campaign", *args],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=env, cwd=ROOT)


def test_a_worker_killed_mid_campaign_and_the_campaign_finishes(dask_cluster, tmp_path):
    out = tmp_path / "out"
    proc = _campaign([*map(str, SOLS), "-o", str(out), "--scheduler", dask_cluster.address,
                      "--methods", "pure-kinematic", "--no-chain", "--no-predict", "--json"])
    try:
        with dask_cluster.client() as client:
            pids = client.run(os.getpid)  # worker address -> its process (a nanny's child)
            deadline = time.monotonic() + 300
            busy = []
            while not busy:
                assert proc.poll() is None, "the campaign ended before any of its tasks ran: " + proc.stderr.read().decode()
                assert time.monotonic() < deadline, "no campaign task started within 300 s"
                busy = [(w, str(k)) for w, keys in client.processing().items() for k in keys
                        if str(k).startswith(TASK_PREFIX)]
                time.sleep(0.05)
            victim, key = busy[0]
            os.kill(pids[victim], signal.SIGKILL)  # while its downlink runs; its nanny starts a new worker
        stdout, stderr = proc.communicate(timeout=600)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 0, stderr.decode()
    doc = json.loads(stdout)
    assert doc["counts"]["ok"] == len(SOLS) and doc["counts"]["failed"] == 0 and doc["run"]["ran"] == len(SOLS)
    results = [DownlinkResult.from_jsonl(p.read_text()) for p in sorted((out / "records").glob("*.jsonl"))]
    assert sorted(r.job.name for r in results) == sorted(s.name for s in SOLS)
    for r in results:
        assert r.status == "ok" and len(r.handoff) == 3 * 2  # 3 targets, near and far
        assert all(h["predicted_uv"] is not None for h in r.handoff)
    # the killed worker's downlink was computed again elsewhere
    (killed,) = [r for r in results if key.startswith(TASK_PREFIX + r.job.job_id + "-")]
    assert killed.worker["address"] != victim
