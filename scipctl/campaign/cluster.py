"""Where a campaign runs (:class:`ClusterSpec`, :func:`open_client`): a local Dask cluster sized to the machine
(one single-threaded worker process per core, each with its share of the memory), or an existing cluster
(``--scheduler ADDRESS``: ``dask scheduler`` / ``dask worker``, or any deployment of distributed)."""

from __future__ import annotations

import contextlib
import os
import re
from dataclasses import dataclass
from typing import Optional

from ..errors import InputError

_MEMORY = re.compile(r"^\s*\d+(\.\d+)?\s*([kKmMgGtT]i?[bB]?|[bB])?\s*$")


def machine_cores() -> int:
    """The cores this process may run on."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:
        return max(1, os.cpu_count() or 1)


@dataclass(frozen=True)
class ClusterSpec:
    """``scheduler``: an existing scheduler's address (``tcp://host:8786``), or None for a local cluster of
    ``workers`` processes (default: one per core) with ``memory_limit`` each (``"4GiB"``; default: the machine's
    memory divided among the workers), one thread each."""

    scheduler: Optional[str] = None
    workers: Optional[int] = None
    memory_limit: Optional[str] = None

    def check(self) -> "ClusterSpec":
        if self.scheduler is not None:
            if self.workers is not None or self.memory_limit is not None:
                raise InputError("campaign", "--workers/--memory-limit",
                                 "only for a local cluster: the workers of --scheduler have their own")
            if not self.scheduler.strip():
                raise InputError("campaign", "--scheduler", "empty address")
        if self.workers is not None and not (1 <= int(self.workers) <= 1024):
            raise InputError("campaign", "--workers", f"{self.workers}: want 1 .. 1024")
        if self.memory_limit is not None and not _MEMORY.match(self.memory_limit):
            raise InputError("campaign", "--memory-limit", f"{self.memory_limit!r}: want a size such as 4GiB or 3000MB")
        return self

    @property
    def n_workers(self) -> int:
        return int(self.workers) if self.workers is not None else machine_cores()

    def describe(self) -> dict:
        if self.scheduler is not None:
            return {"scheduler": self.scheduler}
        return {"local": True, "workers": self.n_workers, "threads_per_worker": 1,
                "memory_limit": self.memory_limit or "auto (machine memory / workers)"}


@contextlib.contextmanager
def open_client(spec: ClusterSpec, connect_timeout_s: float = 20.0):
    """A :class:`distributed.Client` on the cluster ``spec`` names (a local one is started and stopped here).
    :class:`InputError` naming ``--scheduler`` when the address cannot be reached."""
    import logging

    from distributed import Client, LocalCluster

    spec.check()
    if spec.scheduler is not None:
        try:
            client = Client(spec.scheduler, timeout=connect_timeout_s)
        except (OSError, TimeoutError, ValueError) as e:
            raise InputError(spec.scheduler, "--scheduler", f"cannot connect: {e}") from None
        try:
            yield client
        finally:
            client.close()
        return
    # each worker's nanny starts it with OMP/MKL/OPENBLAS_NUM_THREADS=1 (distributed.nanny.pre-spawn-environ's
    # defaults); the task sets OpenCV's threads (task.limit_threads)
    cluster = LocalCluster(n_workers=spec.n_workers, threads_per_worker=1, processes=True,
                           memory_limit=spec.memory_limit or "auto", host="127.0.0.1",
                           # no fixed port: the scheduler's HTTP server still starts with the dashboard off, and on
                           # the default :8787 it warns when another cluster holds that port
                           dashboard_address="127.0.0.1:0", silence_logs=logging.ERROR)
    try:
        client = Client(cluster)
        try:
            yield client
        finally:
            client.close()
    finally:
        cluster.close()
