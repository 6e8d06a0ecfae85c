"""The whole campaign (:func:`run_campaign`): skip the downlinks whose records are already in the output folder
under the same key, send the others to the cluster (one task per downlink: the job's path or recipe, never
images), write each downlink's records the moment it finishes, keep the manifest up to date."""

from __future__ import annotations

import contextlib
import time
from dataclasses import dataclass, field
from typing import Callable, Optional

from ..errors import InputError
from .cluster import ClusterSpec, open_client
from .jobs import DownlinkJob
from .options import CampaignOptions, job_key
from .results import DownlinkResult
from .store import FORMAT, CampaignStore, manifest_entry


@dataclass
class RunStats:
    """What one invocation did: downlinks planned, skipped (already done), run, failed; wall and worker CPU time."""

    planned: int = 0
    skipped: int = 0
    ran: int = 0
    failed: int = 0
    wall_s: float = 0.0
    worker_cpu_s: float = 0.0  # sum of the tasks' CPU seconds (their worker processes, all threads)
    cluster: dict = field(default_factory=dict)

    def to_dict(self) -> dict:
        return dict(self.__dict__)


def _provenance(job: DownlinkJob) -> dict:
    from ..io.provenance import provenance

    prov = provenance(None)
    if job.path is not None:
        prov["inputs"] = {"downlink": {"path": job.path, "sha256": job.input_sha256}}
    else:
        prov["inputs"] = {"synth": {"sha256": job.input_sha256, "recipe": job.synth.to_dict(),
                                    "regenerate": job.synth.regenerate_command()}}
    return prov


def worker_version() -> str:
    """Run on each worker: the scipctl version it imports."""
    from .. import __version__

    return __version__


def _check_workers(client, wait_s: float) -> dict:
    """{worker address: scipctl version}; :class:`InputError` when no worker joins within ``wait_s`` or one runs
    another version of scipctl (its answers would differ)."""
    from .. import __version__

    try:
        client.wait_for_workers(1, timeout=wait_s)
    except TimeoutError:
        raise InputError(str(client.scheduler.address), "--scheduler", f"no worker joined within {wait_s:g} s") from None
    try:
        versions = client.run(worker_version)
    except Exception as e:  # noqa: BLE001 -- e.g. the workers cannot import scipctl
        raise InputError(str(client.scheduler.address), "workers", f"cannot run scipctl there: {type(e).__name__}: {e}") from None
    bad = {w: v for w, v in versions.items() if v != __version__}
    if bad:
        w, v = next(iter(bad.items()))
        raise InputError(w, "scipctl version", f"worker has {v}, this client {__version__}")
    return versions


def run_campaign(jobs: list, options: CampaignOptions, store: CampaignStore, cluster: ClusterSpec,
                 on_start: Optional[Callable[[int, int], None]] = None,
                 on_result: Optional[Callable[[DownlinkResult, int, int], None]] = None,
                 worker_wait_s: float = 60.0) -> RunStats:
    """Run ``options`` on every job not already done in ``store``; returns what this invocation did.

    ``on_start(planned, to_run)`` once, ``on_result(result, done, to_run)`` after each downlink's records are
    written. A downlink whose task raised or whose worker died too often (Dask's ``allowed-failures``) is
    recorded failed with that error; the others go on.
    """
    from ..io.provenance import provenance

    options.check()
    cluster.check()
    t_start = time.perf_counter()
    okey = options.key()
    keys = {j.job_id: job_key(j.input_sha256, okey) for j in jobs}
    stats = RunStats(planned=len(jobs), cluster=cluster.describe())
    with contextlib.ExitStack() as stack:
        client = None
        if any(not store.is_done(j, keys[j.job_id]) for j in jobs):
            # connect before anything is written: a cluster that cannot be reached leaves no output behind
            client = stack.enter_context(open_client(cluster))
            stats.cluster["workers"] = len(_check_workers(client, worker_wait_s))
        else:  # every downlink done before: no cluster is started, and the summary says so
            stats.cluster = {"started": False, "why": "every downlink was done before"}
        stack.enter_context(store.locked())
        manifest = store.load_manifest() or {"format": FORMAT, "downlinks": {}}
        manifest.update({"options": options.to_dict(), "options_key": okey, "provenance": provenance(None)})
        todo = []
        for j in jobs:
            done = store.is_done(j, keys[j.job_id])
            old = manifest["downlinks"].get(j.job_id)
            if done and old is not None and old.get("key") == keys[j.job_id]:
                continue
            manifest["downlinks"][j.job_id] = manifest_entry(j, keys[j.job_id], "ok" if done else "pending",
                                                             store.read(j.job_id) if done else None)
            if not done:
                todo.append(j)
        store.save_manifest(manifest)
        stats.skipped = len(jobs) - len(todo)
        if on_start:
            on_start(len(jobs), len(todo))
        if todo:
            from distributed import as_completed

            from .task import run_job

            if client is None:  # records removed since the first look
                client = stack.enter_context(open_client(cluster))
                stats.cluster = cluster.describe()
                stats.cluster["workers"] = len(_check_workers(client, worker_wait_s))

            futures = {}
            for i, j in enumerate(todo):
                k = keys[j.job_id]
                fut = client.submit(run_job, j, options, k, key=f"scipctl-campaign-{j.job_id}-{k[:12]}", priority=-i)
                futures[fut] = j
            for fut in as_completed(list(futures)):
                j = futures.pop(fut)
                try:
                    res = fut.result()
                except Exception as e:  # noqa: BLE001 -- KilledWorker, lost data, ...: recorded, the rest go on
                    res = DownlinkResult(j, keys[j.job_id])
                    res.fail("worker", e)
                fut.release()
                res.provenance = _provenance(j)
                store.write(res)
                manifest["downlinks"][j.job_id] = manifest_entry(j, res.key, res.status, res)
                store.save_manifest(manifest)
                stats.ran += 1
                stats.failed += res.status != "ok"
                stats.worker_cpu_s += res.cpu_s or 0.0
                if on_result:
                    on_result(res, stats.ran, len(todo))
    stats.wall_s = time.perf_counter() - t_start
    return stats
