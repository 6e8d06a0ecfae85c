"""``scipctl campaign``: the handoff methods, the chain and the pre-uplink prediction over many downlinks (files,
folders, globs; or synthetic scenes rendered on the workers) on a Dask cluster; records per downlink, the summary
(docs/campaign.md).

Exit codes: 0 every downlink ran; 1 the campaign finished but some downlink failed (its records say why; the
summary and ``--json`` are still written); 2 bad arguments or inputs, nothing run.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Optional

from ..errors import CommandFailed, InputError
from .output import emit_json, note, stderr_console


def _options(handoff, chain, predict, methods, success_px, fast, predict_route="plan", closure=False,
             chain_answer=None, stereo_selfcal=True):
    from ..campaign.options import CampaignOptions
    from ..pipeline.chain import DEFAULT_CHAIN_ANSWER
    from .handoff import _parse_methods

    if methods is not None and not handoff:
        raise InputError("campaign", "--methods", "only with --handoff")
    if chain_answer is not None and not chain:
        raise InputError("campaign", "--chain-answer", "is the chain's answer: not with --no-chain")
    names, _, pairs = _parse_methods(methods) if handoff else ([], [], set())
    return CampaignOptions(handoff, chain, predict, tuple(names), tuple(sorted(pairs)), success_px, fast,
                           predict_route, closure, DEFAULT_CHAIN_ANSWER if chain_answer is None else chain_answer,
                           stereo_selfcal).check()


def _jobs(srcs, synth, seeds, runs, families, no_errors, error_draws=None):
    from ..campaign.jobs import file_jobs, parse_seeds, synth_jobs

    if synth is None:
        for flag, v in (("--seeds", seeds), ("--runs", runs), ("--families", families), ("--error-draws", error_draws)):
            if v is not None:
                raise InputError("campaign", flag, "only with --synth")
        if no_errors:
            raise InputError("campaign", "--no-errors", "only with --synth")
        if not srcs:
            raise InputError("campaign", "SRC", "give downlinks (files, folders, globs) or --synth SCENARIO")
        return file_jobs(srcs)
    if srcs:
        raise InputError("campaign", "SRC", "give downlinks or --synth, not both")
    if seeds is None:
        raise InputError("campaign", "--seeds", "--synth needs --seeds A-B")
    from .synth import _env_quality

    image_scale, supersample = _env_quality()
    def split(flag, t):
        if t is None:
            return None
        names = [x.strip() for x in t.split(",") if x.strip()]
        if not names:  # an empty list would mean "all" (every run: 6 full renders per seed)
            raise InputError("campaign", flag, f"{t!r} names nothing")
        return names

    draws = None if error_draws is None else parse_seeds(error_draws, "--error-draws")
    return synth_jobs(synth, parse_seeds(seeds), split("--runs", runs), split("--families", families), no_errors,
                      image_scale, supersample, draws)


class _Progress:
    """The progress bar on stderr (a terminal), or one line per finished downlink (a log)."""

    def __init__(self):
        from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

        self.con = stderr_console()
        self.bar = Progress(TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(),
                            TextColumn("{task.fields[rate]}"), TimeElapsedColumn(), TextColumn("{task.fields[left]}"),
                            console=self.con, transient=True, disable=not self.con.is_terminal)
        self.task = None
        self.t0 = time.perf_counter()

    def __enter__(self):
        self.bar.__enter__()
        return self

    def __exit__(self, *exc):
        return self.bar.__exit__(*exc)

    def start(self, planned: int, todo: int) -> None:
        self.t0 = time.perf_counter()
        if planned > todo:
            note(f"{planned - todo} of {planned} downlinks already done in this folder: skipped")
        self.task = self.bar.add_task("campaign", total=todo, rate="", left="")

    def result(self, res, done: int, todo: int) -> None:
        el = time.perf_counter() - self.t0
        per_h = 3600.0 * done / el if el > 0 else 0.0
        left = (todo - done) * el / done
        left_s = time.strftime("%H:%M:%S", time.gmtime(left)) + " left"
        self.bar.update(self.task, completed=done, description=f"{res.job.name} {res.status}",
                        rate=f"{per_h:.1f} downlinks/h", left=left_s)
        if not self.con.is_terminal:
            why = f": {res.error}" if res.error else ""
            note(f"[{done}/{todo}] {res.job.name} ({res.job.family}) {res.status}{why}, "
                 f"{res.seconds.get('total', 0.0):.1f} s; {per_h:.1f} downlinks/h, {left_s}")


def _print_summary(con, summary) -> None:
    from rich.table import Table

    tab = Table(title=f"campaign {summary['out']}")
    for c in ("family", "downlinks", "handoff success", "chains within success px", "sequences written"):
        tab.add_column(c)
    for name, sec in list(summary["families"].items()) + [("overall", summary["overall"])]:
        rows = sec["table1"]
        cases = sum(r["cases"] for r in rows)
        succ = sum(round(r["success_rate"] * r["cases"]) for r in rows)
        ch, pr = sec.get("chain"), sec.get("prediction")
        tab.add_row(name, str(sec["downlinks"]), f"{succ}/{cases}" if cases else "-",
                    f"{ch['within_success_px']}/{ch['scored']}" if ch else "-",
                    f"{pr['sequences_written']}/{pr['targets']}" if pr else "-")
    con.print(tab)
    for f in summary["failed"]:
        con.print(f"failed: {f['downlink']} ({f['family']}): {f['error']}")


def campaign(srcs, out: Optional[Path], synth: Optional[str], seeds: Optional[str], runs: Optional[str],
             families: Optional[str], no_errors: bool, handoff: bool, chain: bool, predict: bool,
             methods: Optional[str], success_px: float, fast: bool, scheduler: Optional[str], workers: Optional[int],
             memory_limit: Optional[str], summarize_dir: Optional[Path], json_out: bool,
             predict_route: str = "plan", closure: bool = False, chain_answer: Optional[str] = None,
             error_draws: Optional[str] = None, stereo_selfcal: bool = True) -> None:
    """``scipctl campaign``: run (or with ``summarize_dir`` only re-aggregate) and write the summary."""
    from ..campaign.cluster import ClusterSpec
    from ..campaign.store import CampaignStore
    from ..campaign.summary import summarize, write_summary

    con = stderr_console()
    if summarize_dir is not None:
        if srcs or synth is not None or out is not None:
            raise InputError("campaign", "--summarize", "re-aggregates a campaign folder: give no SRC, --synth or -o")
        store = CampaignStore(summarize_dir, create=False)
        summary = summarize(store)
        js, page = write_summary(store, summary)
        _print_summary(con, summary)
        note(f"summary: {js}, {page}")
        if json_out:
            emit_json(summary)
        return
    if not srcs and synth is None:
        raise InputError("campaign", "SRC", "give downlinks (files, folders, globs) or --synth SCENARIO")
    if out is None:
        raise InputError("campaign", "-o/--out", "give the output folder")
    options = _options(handoff, chain, predict, methods, success_px, fast, predict_route, closure, chain_answer,
                       stereo_selfcal)
    cluster = ClusterSpec(scheduler, workers, memory_limit).check()
    jobs = _jobs(srcs, synth, seeds, runs, families, no_errors, error_draws)
    store = CampaignStore(out)
    from ..campaign.run import run_campaign

    with _Progress() as prog:
        stats = run_campaign(jobs, options, store, cluster, on_start=prog.start, on_result=prog.result)
    summary = summarize(store, stats.to_dict())
    js, page = write_summary(store, summary)
    _print_summary(con, summary)
    note(f"{stats.ran} downlinks run, {stats.skipped} skipped (done before), {stats.failed} failed; "
         f"summary: {js}, {page}")
    if stats.failed:
        raise CommandFailed(f"{stats.failed} of {stats.planned} downlinks failed (records/*.jsonl say why; "
                            f"the others ran)", payload=summary)
    if json_out:
        emit_json(summary)
