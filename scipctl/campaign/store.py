"""A campaign's output folder: one records file per downlink (``OUT/records/<job id>.jsonl``, written atomically
the moment the downlink finishes) and the manifest (``OUT/manifest.json``: every downlink of the campaign with
its input hash, key, status and records file, under the options and their key).

What is done is read from the records files themselves (their header's key and status), so a campaign killed at
any moment leaves a consistent folder: the downlinks that had finished keep their records, those that were
running have none (or an older file under another key) and run again. One campaign at a time per folder
(an exclusive lock on ``OUT/.lock``).
"""

from __future__ import annotations

import contextlib
import json
from pathlib import Path
from typing import Optional

from ..errors import InputError
from ..jsonutil import json_default
from .jobs import DownlinkJob
from .results import DownlinkResult, read_header

MANIFEST = "manifest.json"
FORMAT = "scipctl-campaign/1"


class CampaignStore:
    """The folder ``out`` (made if missing). :class:`InputError` naming ``-o`` if it is not a usable folder."""

    def __init__(self, out, create: bool = True):
        self.out = Path(out)
        if self.out.exists() and not self.out.is_dir():
            raise InputError(str(self.out), "-o/--out", "exists and is not a directory")
        if not create and not self.out.is_dir():
            raise InputError(str(self.out), "--summarize", "no such campaign folder")

    def make(self) -> None:
        """Create the folder (and ``records/``) if missing: only once there is something to write."""
        try:
            self.records_dir.mkdir(parents=True, exist_ok=True)
        except OSError as e:
            raise InputError(str(self.out), "-o/--out", f"cannot create: {e.strerror or e}") from None

    @property
    def records_dir(self) -> Path:
        return self.out / "records"

    @property
    def manifest_path(self) -> Path:
        return self.out / MANIFEST

    def records_path(self, job: DownlinkJob) -> Path:
        return self.records_dir / f"{job.job_id}.jsonl"

    @contextlib.contextmanager
    def locked(self):
        """Make the folder and hold ``OUT/.lock`` exclusively; :class:`InputError` if another campaign holds it."""
        import fcntl

        self.make()
        try:
            f = open(self.out / ".lock", "a+")
        except OSError as e:  # an existing folder that cannot be written (read-only mount, permissions)
            raise InputError(str(self.out), "-o/--out", f"cannot write here: {e.strerror or e}") from None
        try:
            try:
                fcntl.flock(f, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                raise InputError(str(self.out), "-o/--out", "another campaign is running on this folder") from None
            yield self
        finally:
            f.close()

    def is_done(self, job: DownlinkJob, key: str) -> bool:
        """True when the job's records file holds a finished (``ok``) run under ``key``."""
        h = read_header(self.records_path(job))
        return h is not None and h.get("key") == key and h.get("status") == "ok"

    def write(self, result: DownlinkResult) -> Path:
        """The records file, all or nothing (temporary file, then rename)."""
        from ..io.atomic import write_output_text

        path = self.records_path(result.job)
        write_output_text(path, result.to_jsonl(), "-o/--out")  # a full disk, a folder in the way: exit 2, named
        return path

    def read(self, job_id: str) -> Optional[DownlinkResult]:
        """The records of ``job_id``, or None when there are none (or the file is damaged)."""
        try:
            return DownlinkResult.from_jsonl((self.records_dir / f"{job_id}.jsonl").read_text(encoding="utf-8"))
        except (OSError, ValueError, KeyError, TypeError):
            return None

    # ------------------------------------------------------------------------- manifest
    def load_manifest(self) -> Optional[dict]:
        """The manifest, or None when there is none; :class:`InputError` when it is not one."""
        try:
            doc = json.loads(self.manifest_path.read_text(encoding="utf-8"))
        except FileNotFoundError:
            return None
        except (OSError, ValueError) as e:
            raise InputError(str(self.manifest_path), "manifest", f"unreadable: {e}") from None
        if not isinstance(doc, dict) or doc.get("format") != FORMAT or not isinstance(doc.get("downlinks"), dict):
            raise InputError(str(self.manifest_path), "format", f"not a {FORMAT} manifest")
        return doc

    def save_manifest(self, doc: dict) -> None:
        from ..io.atomic import write_output_text

        write_output_text(self.manifest_path, json.dumps(doc, indent=1, sort_keys=True, default=json_default) + "\n",
                          "-o/--out")


def manifest_entry(job: DownlinkJob, key: str, status: str, result: Optional[DownlinkResult] = None) -> dict:
    """One downlink's line in the manifest (``status``: ``ok``, ``failed`` or ``pending``)."""
    return {"name": job.name, "family": job.family, "input_sha256": job.input_sha256, "key": key,
            "records": f"records/{job.job_id}.jsonl", "status": status,
            "error": None if result is None else result.error,
            "seconds": None if result is None else result.seconds.get("total"),
            "job": job.to_dict()}
