"""A Dask cluster on 127.0.0.1 for the campaign tests (test helper): ``dask scheduler`` and ``dask worker``
processes started here (each worker with its nanny, one thread), stopped by their own process ids."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def _env() -> dict:
    env = dict(os.environ)
    env["PYTHONPATH"] = str(ROOT) + (os.pathsep + env["PYTHONPATH"] if env.get("PYTHONPATH") else "")
    return env


class DaskTestCluster:
    """``with DaskTestCluster(tmp, n_workers=2) as c: c.address ...``"""

    def __init__(self, folder: Path, n_workers: int = 2, start_timeout_s: float = 120.0):
        self.folder = Path(folder)
        self.n_workers = n_workers
        self.timeout_s = start_timeout_s
        self.procs: list = []
        self.address = None

    def _spawn(self, args: list, log: str) -> subprocess.Popen:
        out = open(self.folder / log, "wb")
        p = subprocess.Popen([sys.executable, "-m", "dask", *args], stdout=out, stderr=subprocess.STDOUT,
                             env=_env(), cwd=self.folder, start_new_session=True)
        out.close()
        self.procs.append(p)
        return p

    def __enter__(self) -> "DaskTestCluster":
        self.folder.mkdir(parents=True, exist_ok=True)
        sched_file = self.folder / "scheduler.json"
        try:
            self._spawn(["scheduler", "--host", "127.0.0.1", "--port", "0", "--no-dashboard",
                         "--scheduler-file", str(sched_file)], "scheduler.log")
            t0 = time.monotonic()
            while self.address is None:
                try:
                    self.address = json.loads(sched_file.read_text())["address"]
                except (OSError, ValueError, KeyError):  # not written yet, or not whole yet
                    if time.monotonic() - t0 > self.timeout_s:
                        raise TimeoutError("dask scheduler did not start: "
                                           + (self.folder / "scheduler.log").read_text()) from None
                    time.sleep(0.1)
            for i in range(self.n_workers):
                self._spawn(["worker", "--scheduler-file", str(sched_file), "--nworkers", "1", "--nthreads", "1",
                             "--host", "127.0.0.1", "--no-dashboard", "--memory-limit", "4GiB",
                             "--local-directory", str(self.folder / f"w{i}"), "--death-timeout", "60"],
                            f"worker{i}.log")
            with self.client() as c:
                c.wait_for_workers(self.n_workers, timeout=self.timeout_s)
        except BaseException:
            self.stop()
            raise
        return self

    def __exit__(self, *exc) -> None:
        self.stop()

    def client(self):
        from distributed import Client

        return Client(self.address, timeout=30)

    def stop(self) -> None:
        """SIGTERM to each process group started here (worker processes are their nanny's children), then SIGKILL."""
        for p in self.procs:
            if p.poll() is None:
                os.killpg(p.pid, signal.SIGTERM)
        deadline = time.monotonic() + 20
        for p in self.procs:
            try:
                p.wait(timeout=max(0.1, deadline - time.monotonic()))
            except subprocess.TimeoutExpired:
                os.killpg(p.pid, signal.SIGKILL)
                p.wait()
        self.procs = []
