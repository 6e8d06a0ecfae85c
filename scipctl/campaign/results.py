"""One downlink's outcome (:class:`DownlinkResult`) and its records file: JSON Lines, one object per line.

The first line (``"kind": "downlink"``) is the header: the job, its key, ``status`` (``ok`` / ``failed``), the
one-line ``error``, per-stage errors, timings, CPU time, the worker, the provenance. Then one line per record::

    {"kind": "handoff",    "downlink": NAME, "family": F, "record": HandoffRecord.to_dict()}
    {"kind": "chain",      "downlink": NAME, "family": F, "record": {"downlink", "target", "steps": [ChainStep.to_dict()], ["error"]}}
    {"kind": "prediction", "downlink": NAME, "family": F, "record": {"target", "confidence", "sequence_written", ...}}

``record`` is each pipeline record's own ``to_dict()`` output, unchanged.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from typing import Optional

from ..jsonutil import json_default
from .jobs import DownlinkJob

KINDS = ("handoff", "chain", "prediction")
FORMAT = "scipctl-campaign-records/1"


@dataclass
class DownlinkResult:
    """What a worker returns for one downlink (and what its records file holds)."""

    job: DownlinkJob
    key: str  # options.job_key(input, options): records with the same key are not computed again
    status: str = "ok"  # "ok" | "failed"
    error: Optional[str] = None  # the first error, one line
    stage_errors: dict = field(default_factory=dict)  # stage ("load", "handoff", "chain", "predict") -> one line
    handoff: list = field(default_factory=list)  # HandoffRecord.to_dict()
    table1: list = field(default_factory=list)  # this downlink's Table 1 rows (pipeline.handoff.table1)
    chains: list = field(default_factory=list)  # pipeline.chain_targets.run_marked_chains entries
    predictions: list = field(default_factory=list)  # one per marked target (commands' sequence summary + prediction)
    products: dict = field(default_factory=dict)  # "hazcam" / "near" / "far" -> product id
    seconds: dict = field(default_factory=dict)  # stage -> wall seconds on the worker, and "total"
    cpu_s: Optional[float] = None  # CPU seconds of the worker process during the task (all its threads)
    cpu_s_by_stage: dict = field(default_factory=dict)  # stage ("load": reading or rendering) -> CPU seconds
    worker: dict = field(default_factory=dict)  # host, pid, scipctl version, address
    downlink_sha256: Optional[str] = None  # as the worker read it (files), to check against the job's
    provenance: dict = field(default_factory=dict)  # io.provenance: tool version, command line, input hashes
    truth_targets: dict = field(default_factory=dict)  # target id -> [x, y, z] site m, where the downlink has truth
    stereo_selfcal: list = field(default_factory=list)  # PairSelfCal.to_dict() per stereo pair, when the option is on

    def fail(self, stage: str, exc: BaseException) -> None:
        """Record ``exc`` as ``stage``'s one-line error; the downlink is failed."""
        from ..errors import one_line

        msg = one_line(str(exc) if type(exc).__name__ in ("InputError", "CommandFailed") else f"{type(exc).__name__}: {exc}")
        self.stage_errors[stage] = msg
        self.status = "failed"
        if self.error is None:
            self.error = f"{stage}: {msg}"

    def header(self) -> dict:
        return {"kind": "downlink", "format": FORMAT, "downlink": self.job.name, "family": self.job.family,
                "job_id": self.job.job_id, "job": self.job.to_dict(), "key": self.key, "status": self.status,
                "error": self.error, "stage_errors": self.stage_errors, "table1": self.table1,
                "products": self.products, "seconds": self.seconds, "cpu_s": self.cpu_s,
                "cpu_s_by_stage": self.cpu_s_by_stage, "worker": self.worker,
                "downlink_sha256": self.downlink_sha256, "provenance": self.provenance,
                "truth_targets": self.truth_targets,
                **({"stereo_selfcal": self.stereo_selfcal} if self.stereo_selfcal else {}),
                "counts": {k: len(self._records(k)) for k in KINDS}}

    def _records(self, kind: str) -> list:
        return {"handoff": self.handoff, "chain": self.chains, "prediction": self.predictions}[kind]

    def to_jsonl(self) -> str:
        lines = [self.header()]
        for kind in KINDS:
            lines += [{"kind": kind, "downlink": self.job.name, "family": self.job.family, "record": r}
                      for r in self._records(kind)]
        return "".join(json.dumps(x, sort_keys=True, default=json_default) + "\n" for x in lines)

    @classmethod
    def from_jsonl(cls, text: str) -> "DownlinkResult":
        """``ValueError`` when the text is not a records file."""
        lines = [json.loads(ln) for ln in text.splitlines() if ln.strip()]
        if not lines or lines[0].get("kind") != "downlink" or lines[0].get("format") != FORMAT:
            raise ValueError("not a campaign records file (no header line)")
        h = lines[0]
        res = cls(DownlinkJob.from_dict(h["job"]), h["key"], h["status"], h.get("error"), h.get("stage_errors") or {},
                  table1=h.get("table1") or [], products=h.get("products") or {}, seconds=h.get("seconds") or {},
                  cpu_s=h.get("cpu_s"), cpu_s_by_stage=h.get("cpu_s_by_stage") or {}, worker=h.get("worker") or {},
                  downlink_sha256=h.get("downlink_sha256"),
                  provenance=h.get("provenance") or {}, truth_targets=h.get("truth_targets") or {},
                  stereo_selfcal=h.get("stereo_selfcal") or [])
        for x in lines[1:]:
            if x.get("kind") in KINDS:
                res._records(x["kind"]).append(x["record"])
        want = h.get("counts") or {}
        if any(len(res._records(k)) != want.get(k, 0) for k in KINDS):
            raise ValueError("records file is incomplete (counts in its header differ)")
        return res


def read_header(path) -> Optional[dict]:
    """The header line of a records file, or None when there is none or it does not parse."""
    try:
        with open(path, encoding="utf-8") as f:
            first = f.readline()
        h = json.loads(first)
    except (OSError, ValueError):
        return None
    return h if isinstance(h, dict) and h.get("kind") == "downlink" and h.get("format") == FORMAT else None
