"""What a worker does with one downlink (:func:`run_job`): load it (read the file, or render the synthetic scene),
then run the handoff methods, the chain and the pre-uplink prediction with the same pipeline calls as
``simulate-handoff --chain`` and ``sequence``; every error is caught and recorded, one line per stage.

Runs in a Dask worker process: it imports what it needs, limits OpenCV's (and, for libraries loaded after it,
OpenMP's and BLAS's) threads to the task's share of the cores, and returns a small :class:`DownlinkResult` (records,
no images).
"""

from __future__ import annotations

import os
import time
from typing import Optional

from ..errors import CommandFailed, InputError
from .jobs import DEFAULT_FAMILY, DownlinkJob
from .options import CampaignOptions
from .results import DownlinkResult

THREAD_ENV = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")


def limit_threads(n: int) -> None:
    """At most ``n`` threads in OpenCV's parallel loops (now) and in OpenMP/BLAS libraries loaded from now on
    (a Dask nanny already starts its worker with those variables at 1)."""
    import cv2

    for var in THREAD_ENV:
        os.environ[var] = str(n)
    cv2.setNumThreads(int(n))


# glibc malloc: large blocks from the heap up to this size, and freed memory kept up to this much before it is
# returned to the system (glibc's own dynamic thresholds grow to these values in a long-running process)
MMAP_THRESHOLD_BYTES = 32 << 20
TRIM_THRESHOLD_BYTES = 64 << 20
_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD = -1, -3  # mallopt parameters (malloc.h)


def tune_malloc() -> bool:
    """Undo, for this process, what ``MALLOC_TRIM_THRESHOLD_=65536`` does to glibc's malloc (distributed's nanny
    starts every worker with it, to give memory back to the system): it switches off glibc's dynamic mmap
    threshold, so every numpy temporary over 128 kB is a fresh ``mmap`` whose pages fault in again, every time.
    Measured on one bundled sol's handoff + chain in one process (CPU seconds, ``time.process_time``; run_job on
    paper-s1-straight, every method): 29.2 s in a plain process, 38.6 s with the nanny's environment
    (``MALLOC_TRIM_THRESHOLD_=65536 OMP_NUM_THREADS=1``: 25x the page faults), 29.4-29.5 s with it and this call;
    a campaign's rendering took 3x the CPU of ``scipctl synth`` with it. Answers do not change (only where memory
    comes from).
    Returns False where there is no glibc (nothing done)."""
    import ctypes
    import ctypes.util

    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        mallopt = libc.mallopt
    except (OSError, AttributeError):
        return False
    return bool(mallopt(_M_MMAP_THRESHOLD, MMAP_THRESHOLD_BYTES)) and bool(mallopt(_M_TRIM_THRESHOLD, TRIM_THRESHOLD_BYTES))


def _worker_info() -> dict:
    import socket

    from .. import __version__

    info = {"host": socket.gethostname(), "pid": os.getpid(), "scipctl": __version__}
    try:
        from distributed import get_worker

        info["address"] = get_worker().address
    except (ImportError, ValueError):
        pass
    return info


def load_downlink(job: DownlinkJob):
    """The job's :class:`~scipctl.model.Downlink`: read from its path (validated), or rendered in memory."""
    if job.path is not None:
        from ..io.downlink import read_downlink

        return read_downlink(job.path)
    from ..sim.build import build_run
    from ..sim.errors import ErrorSettings
    from ..sim.scenarios import default_errors

    s = job.synth
    extra = {} if s.family == DEFAULT_FAMILY else {"family": s.family}
    # as `synth` renders it: a family's errors are the scenario's scaled by the family's error scale (build_run
    # does that when given no errors), so only --no-errors and the default family pass errors explicitly
    if s.no_errors:
        errors = ErrorSettings.none()
    else:
        errors = None if extra else default_errors(s.scenario)
    return build_run(s.scenario, s.run, s.seed, errors=errors, image_scale=s.image_scale, supersample=s.supersample,
                     error_draw=s.error_draw, **extra).downlink


def _handoff(dl, job: DownlinkJob, options: CampaignOptions, res: DownlinkResult) -> None:
    """The handoff methods on every marked target, as ``simulate-handoff`` runs them."""
    from ..core.handoff import HandoffParams
    from ..pipeline.handoff import build_setup, marked_targets, run_targets, table1

    params = HandoffParams(dense_downsample=2 if options.fast else 1)
    setup = build_setup(dl, params, shared=True)
    res.products = {"hazcam": setup.hazcam.product_id, "near": setup.near.product_id if setup.near else None,
                    "far": setup.far.product_id if setup.far else None}
    use_navcams = [n for n in options.navcams if n in setup.cases]
    recs = run_targets(dl, setup, marked_targets(dl, setup), methods=list(options.methods), navcams=use_navcams,
                       success_px=options.success_px, downlink_name=job.name, only=set(options.pairs))
    res.handoff = [r.to_dict() for r in recs]
    res.table1 = table1(recs)


def _plain(x):
    return x.to_dict() if hasattr(x, "to_dict") else x


def _predict(dl, options: CampaignOptions, res: DownlinkResult) -> None:
    """The prediction and sequence of every marked target, designated from its mark at the first stop, as
    ``sequence --target`` makes them (the handoff method chosen from this downlink's Table 1, as ``sequence``
    chooses it from ``handoff.json``; the built-in rules ``sequence`` chooses without ``--rules``: by the
    downlink's rover)."""
    from dataclasses import replace

    from ..pipeline.rules import load_rules, rules_for_downlink
    from ..pipeline.sequence import broken
    from ..pipeline.target_sequence import sequence_for

    name, reason = rules_for_downlink(dl)
    rule_set = load_rules(name, chosen_by=f"not given; {reason}")
    rules_file = rule_set.summary()  # as `sequence --json` reports it
    rows = res.table1 if options.handoff else None
    for t in dl.targets:
        try:
            doc, checks, pred, record = sequence_for(dl, t.id, None, rows or None,
                                                     params=replace(rule_set.predict, route=options.predict_route),
                                                     rules=rule_set.flight, rules_used=rule_set.to_dict(),
                                                     render_views=False)
        except (CommandFailed, InputError) as e:
            payload = getattr(e, "payload", None) or {}
            res.predictions.append({"target": t.id, "error": str(e), "sequence_written": False,
                                    "designation": _plain(payload.get("designation"))})
            continue
        rec = _plain(record)
        res.predictions.append({
            "target": t.id, "designated_now": rec.get("designated_from") == "mark", "confidence": pred.confidence,
            "p_simulated": pred.p_simulated, "sequence_written": doc is not None, "rules": [c.to_dict() for c in checks],
            "broken_rules": [c.rule for c in broken(checks)],
            "commands": None if doc is None else len(doc["commands"]),
            "total_duration_s": None if doc is None else doc["total_duration_s"],
            "designation": rec, "prediction": pred.to_dict(), "rules_file": rules_file})


def _pairs_read(dl, options: CampaignOptions):
    """The stereo pairs the stages ``options`` asks for read, as a predicate on a left product for
    ``self_calibrate_downlink`` (None: every pair): the chain reads every stop's; the handoff the navcam and hazcam
    pairs; the prediction those of each marked target's designation stop (``sequence``'s today's stop). A pair's fit
    reads that pair alone, so fitting fewer changes no answer, only the time."""
    if options.chain:
        return None
    from ..pipeline.predict.from_downlink import designation_position
    from ..pipeline.stereo_selfcal import handoff_pairs

    positions = {designation_position(dl, t.id, []) for t in dl.targets} - {None} if options.predict else set()
    return lambda im: (options.handoff and handoff_pairs(im)) or im.position in positions


def run_job(job: DownlinkJob, options: CampaignOptions, key: str, threads: int = 1) -> DownlinkResult:
    """Load one downlink and run what ``options`` asks; never raises for a bad downlink or a failing stage
    (the result says ``failed`` with the one-line error, and keeps what the other stages computed)."""
    t_start, cpu_start = time.perf_counter(), time.process_time()
    res = DownlinkResult(job, key)
    res.worker = _worker_info()
    limit_threads(threads)
    tune_malloc()
    t0, c0 = time.perf_counter(), time.process_time()
    try:
        dl = load_downlink(job)
    except Exception as e:  # noqa: BLE001 -- a bad downlink is recorded, the campaign goes on
        res.fail("load", e)
        dl = None
    res.seconds["load"] = time.perf_counter() - t0
    res.cpu_s_by_stage["load"] = time.process_time() - c0
    if dl is not None:
        res.downlink_sha256 = dl.source_sha256
        res.truth_targets = {t.id: [float(x) for x in t.xyz_site_m] for t in dl.truth_targets}
        if job.path is not None and dl.source_sha256 not in (None, job.input_sha256):
            res.fail("load", InputError(job.path, "sha256", "the file changed after the campaign hashed it"))
        if options.stereo_selfcal:
            t0, c0 = time.perf_counter(), time.process_time()
            try:
                from ..pipeline.stereo_selfcal import self_calibrate_downlink

                dl, pairs = self_calibrate_downlink(dl, only=_pairs_read(dl, options))
                res.stereo_selfcal = [p.to_dict() for p in pairs]
            except Exception as e:  # noqa: BLE001 -- recorded; the stages run on the downlinked models
                res.fail("stereo_selfcal", e)
            res.seconds["stereo_selfcal"] = time.perf_counter() - t0
            res.cpu_s_by_stage["stereo_selfcal"] = time.process_time() - c0
        stages = (("handoff", options.handoff, lambda: _handoff(dl, job, options, res)),
                  ("chain", options.chain, lambda: _chain(dl, job, res, options.closure, options.chain_answer)),
                  ("predict", options.predict, lambda: _predict(dl, options, res)))
        for stage, wanted, fn in stages:
            if not wanted:
                continue
            t0, c0 = time.perf_counter(), time.process_time()
            try:
                fn()
            except Exception as e:  # noqa: BLE001 -- recorded; the other stages still run
                res.fail(stage, e)
            res.seconds[stage] = time.perf_counter() - t0
            res.cpu_s_by_stage[stage] = time.process_time() - c0
    res.seconds["total"] = time.perf_counter() - t_start
    res.cpu_s = time.process_time() - cpu_start
    return res


def _chain(dl, job: DownlinkJob, res: DownlinkResult, closure: bool = False, answer: Optional[str] = None) -> None:
    from ..pipeline.chain_targets import run_marked_chains

    res.chains = [dict(c, steps=[s.to_dict() for s in c["steps"]])
                  for c in run_marked_chains(dl, job.name, closure=closure, answer=answer)]
