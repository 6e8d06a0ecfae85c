"""The ``scipctl`` command line (thin layer: parse, call, print).

Exit codes: 0 ok; 1 the answer is "no" (failure detected, rule broken, no
reliable match); 2 bad input or usage (:mod:`scipctl.commands.output`, which
also holds what the commands print with). Each command here calls the function
of the same name in ``scipctl.commands.<module>``, imported inside the command,
as are the heavy modules (cv2, open3d), so that ``scipctl --help`` stays fast.
"""

from __future__ import annotations

import os
import sys

# Small matrix products dominate our numerics; multi-threaded BLAS only adds overhead on 2 cores.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "2")
from pathlib import Path
from typing import List, Optional

import typer

from . import __version__
from .commands.empty_values import NonEmptyCommand
from .commands.output import guarded

app = typer.Typer(
    name="scipctl",
    help="Single Cycle Instrument Placement ground tool: ingest downlinks, designate targets, "
    "simulate pancam->navcam->hazcam handoffs, emit uplink sequences and reports.\n\n"
    "Exit codes: 0 ok, 1 the answer is no (failure detected), 2 bad input or usage, 3 a bug in scipctl, "
    "130 interrupted, 143 terminated, 141 stdout closed by its reader.",
    no_args_is_help=True,
    context_settings={"help_option_names": ["-h", "--help"]},
    add_completion=False,
    pretty_exceptions_enable=False,
    rich_markup_mode=None,
)


def _products_dir_option(writes: bool = True):
    what = "Write (and also look for)" if writes else "Look for"
    return typer.Option(
        None, "--products-dir", envvar="SCIPCTL_PRODUCTS_DIR",
        help=f"{what} products of raw downlinks and workspaces in DIR/<name>-<hash>/ "
        "instead of beside them (docs/workspace.md).")


def _rules_option():
    return typer.Option(
        None, "--rules", help="Rules file (YAML): flight-rule limits and approach parameters, or a built-in: "
        "default, m2020 (default: chosen from the downlink's rover: m2020 for Mars 2020, else the package's "
        "scipctl/data/rules.yaml; docs/sequence.md).")


def _selfcal_option(which: str = "every stereo pair it reads"):
    return typer.Option(
        True, "--stereo-selfcal/--no-stereo-selfcal",
        help=f"Re-align the right eye of {which} from the pair's own feature matches before any stereo runs; "
        "--no-stereo-selfcal uses the downlinked camera models as they are (docs/stereo-and-tracking.md, "
        "'Stereo self-calibration').")


def _version_cb(value: bool):
    if value:
        sys.stdout.write(f"scipctl {__version__}\n")
        raise typer.Exit(0)


@app.callback()
def _main(
    version: bool = typer.Option(False, "--version", callback=_version_cb, is_eager=True, help="Print the version and exit."),
):
    pass


@app.command(cls=NonEmptyCommand)
@guarded
def ingest(
    src: Path = typer.Argument(..., metavar="SRC", help="Downlink: an .mcap file or a directory with downlink.yaml."),
    out: Path = typer.Option(..., "-o", "--out", help="Workspace directory to write (replaced atomically; "
                             "the products of an existing workspace are kept)."),
    force: bool = typer.Option(False, "--force", help="Replace a workspace made from a different downlink; its "
                               "products are set aside in WS/scipctl/superseded-<UTC time>/."),
    json_out: bool = typer.Option(False, "--json", help="Machine-readable summary on stdout."),
):
    """Read and validate a downlink into a workspace, and summarise it."""
    from .commands import ingest as command

    command.ingest(src, out, json_out, force=force)


@app.command(cls=NonEmptyCommand)
@guarded
def info(
    src: Path = typer.Argument(..., metavar="SRC", help="Downlink (.mcap or directory) or workspace."),
    products_dir: Optional[str] = _products_dir_option(writes=False),
    json_out: bool = typer.Option(False, "--json", help="Machine-readable summary on stdout."),
):
    """Validate and summarise a downlink or workspace without writing anything."""
    from .commands import ingest as command

    command.info(src, json_out, products_root=products_dir)


@app.command(cls=NonEmptyCommand)
@guarded
def synth(
    scenario: str = typer.Option("paper", "--scenario", help="paper | traverse"),
    seed: int = typer.Option(0, "--seed", help="Random seed (same seed, same bytes)."),
    out: Path = typer.Option(..., "-o", "--out", help="Output directory (one downlink per run inside)."),
    container: str = typer.Option("mcap", "--container", help="mcap | dir"),
    runs: Optional[str] = typer.Option(None, "--runs", help="Comma-separated run names to make (default: all)."),
    no_errors: bool = typer.Option(False, "--no-errors", help="Inject no calibration/pose/vibration/gain errors."),
    json_out: bool = typer.Option(False, "--json", help="Machine-readable list of what was written."),
    rover: Optional[str] = typer.Option(None, "--rover", help="default | m2020 (Mars 2020 static camera models + URDF); "
                                        "default: the default rover, or the --family's."),
    rover_dir: Optional[Path] = typer.Option(
        None, "--rover-dir", help="Folder of m2020-camera-models.json + m2020.urdf (default: shared/real/12_* beside the checkout)."),
    texture_from: Optional[Path] = typer.Option(
        None, "--texture-from", help="Folder of real pictures/products whose texture is draped on the terrain."),
    texture_crop: Optional[str] = typer.Option(
        None, "--texture-crop", help="X0,Y0,X1,Y1: the part of each picture to use, fractions of width/height (default 0.1,0.55,0.9,0.92)."),
    texture_pixel_mm: float = typer.Option(2.5, "--texture-pixel-mm", help="Ground size of one texture pixel, mm."),
    family: Optional[str] = typer.Option(
        None, "--family", help="Scene family (terrain, rocks, texture, sun, error scale, rover), e.g. default, bedrock-slabs, "
                               "sand-sheet, low-sun, errors-double, m2020, mixed; all in docs/simulator.md."),
    error_draw: int = typer.Option(
        0, "--error-draw", help="0: the seed's own errors. N > 0: draw the random errors of every stop after the first "
                                "(odometry, pointing, vibration, sensor noise) anew; the scene, the targets and the first "
                                "stop's images stay the seed's."),
):
    """Render synthetic downlinks with exact truth."""
    from .commands import synth as command

    command.synth(scenario, seed, out, container, runs, no_errors, json_out, rover=rover, rover_dir=rover_dir,
        texture_from=texture_from, texture_crop=texture_crop, texture_pixel_mm=texture_pixel_mm, family=family,
        error_draw=error_draw)


@app.command(cls=NonEmptyCommand)
@guarded
def designate(
    src: Path = typer.Argument(..., metavar="SRC", help="Workspace or downlink."),
    product: Optional[str] = typer.Option(None, "--product", help="Left-eye product id."),
    camera: Optional[str] = typer.Option(None, "--camera", help="Use this camera's left image at the latest position."),
    pixel: str = typer.Option(..., "--pixel", help="U,V (column,row; sub-pixel allowed)."),
    target_id: Optional[str] = typer.Option(None, "--id", help="Target name: letters, digits, _ . - (default: d<N>, the first free one)."),
    replace_id: bool = typer.Option(False, "--replace", help="Designate --id anew although it is already a saved designation or a marked target."),
    band_px: Optional[float] = typer.Option(None, "--band-px", help="Half-width of the epipolar search band."),
    stereo_selfcal: bool = _selfcal_option("the product's stereo pair"),
    products_dir: Optional[str] = _products_dir_option(),
    json_out: bool = typer.Option(False, "--json", help="Machine-readable result on stdout."),
):
    """Designate a 3-D target from a pixel in a left stereo image."""
    from .commands import designate as command

    command.designate(src, product, camera, pixel, target_id, band_px, json_out, products_root=products_dir,
                      replace_id=replace_id, stereo_selfcal=stereo_selfcal)


@app.command("simulate-handoff", cls=NonEmptyCommand)
@guarded
def simulate_handoff(
    srcs: List[Path] = typer.Argument(..., metavar="SRC", help="Downlinks or workspaces."),
    target: Optional[str] = typer.Option(None, "--target", help="Only this marked target id (a target with marks in the downlink; designated-only ids have no truth to score against)."),
    from_product: Optional[str] = typer.Option(None, "--from", help="Source left navcam product id, near or far (with --pixel): hand off that pixel, unscored."),
    pixel: Optional[str] = typer.Option(None, "--pixel", help="U,V in the --from product."),
    methods: Optional[str] = typer.Option(None, "--methods", help="Comma-separated method names, NAME-near/NAME-far, or 'all' (default: scip, the recommended handoff)."),
    success_px: float = typer.Option(4.0, "--success-px", help="Success threshold in hazcam pixels (scip's p_success is for it; the trust model is fitted for 1-8 px, and outside that range scip has no probability: every scip answer is NO-GO)."),
    near: Optional[str] = typer.Option(None, "--near", help="Left near-navcam product id."),
    far: Optional[str] = typer.Option(None, "--far", help="Left far-navcam product id."),
    hazcam: Optional[str] = typer.Option(None, "--hazcam", help="Left hazcam product id."),
    chain: bool = typer.Option(False, "--chain", help="Also run the whole chain from the pancam designation (each step with p_success and GO)."),
    chain_answer: Optional[str] = typer.Option(None, "--chain-answer", help="With --chain: the chain's final hazcam answer, closure (the default: the closure's pixel when it is confirmed, else the handoff's) or handoff (scip's handoff of the chain's navcam pixel); docs/stereo-and-tracking.md, 'Closure as the answer'."),
    fast: bool = typer.Option(False, "--fast", help="Half-resolution shared dense stereo: ~2.5x faster, less accurate (docs/handoff.md)."),
    trust_model: Optional[Path] = typer.Option(None, "--trust-model", help="scip's trust model (scipctl fit-trust; default: the packaged one)."),
    stereo_selfcal: bool = _selfcal_option("each navcam and hazcam pair (with --chain every pair)"),
    products_dir: Optional[str] = _products_dir_option(),
    json_out: bool = typer.Option(False, "--json", help="One JSON document on stdout."),
):
    """Predict and validate navcam->hazcam (and pancam->navcam) handoffs offline.

    Exit code 1 when scip's answer for any requested target is NO-GO (p_success under its GO threshold), or
    with --chain when a requested target's chain ends NO-GO (a step NO-GO, or no final hazcam answer)."""
    from .commands import handoff as command

    command.simulate_handoff(srcs, target, from_product, pixel, methods, success_px, near, far, hazcam, chain, json_out, fast=fast,
        products_root=products_dir, trust_model=trust_model, chain_answer=chain_answer, stereo_selfcal=stereo_selfcal)


@app.command("trust-evidence", cls=NonEmptyCommand)
@guarded
def trust_evidence(
    srcs: List[Path] = typer.Argument(..., metavar="SRC", help="Downlinks or workspaces with marks in the hazcam."),
    out: Path = typer.Option(..., "-o", "--out", help="Evidence table to write (JSON lines)."),
    family: Optional[str] = typer.Option(None, "--family", help="Scene family name (default: the .sim.json's)."),
    stereo_selfcal: bool = _selfcal_option("each navcam and hazcam pair, as simulate-handoff"),
    products_dir: Optional[str] = _products_dir_option(),
    json_out: bool = typer.Option(False, "--json", help="A summary on stdout."),
):
    """Evidence of every scip candidate answer of every marked target, with its true error (trust-model data)."""
    from .commands import trust as command

    command.trust_evidence(srcs, out, family, json_out, products_root=products_dir, stereo_selfcal=stereo_selfcal)


@app.command("fit-trust", cls=NonEmptyCommand)
@guarded
def fit_trust(
    tables: List[Path] = typer.Argument(..., metavar="TABLE", help="Evidence tables (scipctl trust-evidence; .jsonl or .jsonl.gz)."),
    out: Path = typer.Option(..., "-o", "--out", help="Trust model to write (e.g. scipctl/data/trust_model.json)."),
    report: Optional[Path] = typer.Option(None, "--report", help="Also write the leave-one-family-out evaluation (JSON)."),
    success_px: float = typer.Option(4.0, "--success-px", help="Success radius of the evaluation, hazcam px."),
    json_out: bool = typer.Option(False, "--json", help="A summary on stdout."),
):
    """Fit scip's trust model (logistic regression per success radius, 1/2/4/8 px) on evidence tables."""
    from .commands import trust as command

    command.fit_trust(tables, out, report, success_px, json_out)


@app.command(cls=NonEmptyCommand)
@guarded
def sequence(
    src: Path = typer.Argument(..., metavar="SRC", help="Workspace or downlink."),
    target: str = typer.Option(..., "--target", help="Target id."),
    out: Optional[Path] = typer.Option(None, "-o", "--out", help="Output file (default: stdout)."),
    fmt: str = typer.Option("seqn", "--format", help="seqn | seqjson | json | text"),
    sigma_position_m: Optional[float] = typer.Option(
        None, "--sigma-position-m", help="Pose-estimate 1-sigma position noise per stop, relative to the previous stop, for the Monte Carlo (default: the rules file's default_sigma_position_m)."),
    sigma_yaw_deg: Optional[float] = typer.Option(
        None, "--sigma-yaw-deg", help="Pose-estimate 1-sigma heading noise per stop, relative to the previous stop, degrees (default: the rules file's default_sigma_yaw_deg)."),
    rules: Optional[Path] = _rules_option(),
    min_p_success: Optional[float] = typer.Option(
        None, "--min-p-success", help="Flight rule prediction-confidence: minimum predicted P(success), calibrated (overrides the rules file)."),
    min_p_simulated: Optional[float] = typer.Option(
        None, "--min-p-simulated", help="Flight rule simulated-risk: minimum simulated P (geometry x tracking on expected views; overrides the rules file)."),
    rock_keep_out_m: Optional[float] = typer.Option(
        None, "--rock-keep-out-m", help="Flight rule rock-keep-out, metres (overrides the rules file)."),
    target_keep_out_m: Optional[float] = typer.Option(
        None, "--target-keep-out-m", help="Flight rule target-keep-out, metres (overrides the rules file)."),
    max_drive_m: Optional[float] = typer.Option(
        None, "--max-drive-m", help="Flight rule max-drive-distance, metres (overrides the rules file)."),
    standoff_m: Optional[float] = typer.Option(
        None, "--standoff-m", help="Final rover-origin-to-target distance, metres (overrides the rules file; default: arm workspace centre)."),
    handoff: str = typer.Option(
        "scip", "--handoff", help="The navcam->hazcam handoff the sequence commands: scip (the recommended handoff, "
        "near and far navcams, NO-GO halts before the arm) | best-single (one paper method, chosen by the saved "
        "near-navcam results of simulate-handoff, else the paper's Table 1)."),
    stereo_selfcal: bool = _selfcal_option("the stereo pairs of today's stop (the designation's)"),
    products_dir: Optional[str] = _products_dir_option(),
    json_out: bool = typer.Option(False, "--json", help="Rule-check summary as JSON on stdout."),
):
    """Emit the uplink command sequence for the single-cycle approach."""
    from .commands import sequence as command

    command.sequence(src, target, out, fmt, json_out, sigma_position_m=sigma_position_m, sigma_yaw_deg=sigma_yaw_deg,
        products_root=products_dir, rules_path=rules, handoff_choice=handoff, stereo_selfcal=stereo_selfcal,
        rule_options={"--min-p-success": min_p_success, "--min-p-simulated": min_p_simulated,
                      "--rock-keep-out-m": rock_keep_out_m,
                      "--target-keep-out-m": target_keep_out_m, "--max-drive-m": max_drive_m,
                      "--standoff-m": standoff_m})


@app.command(cls=NonEmptyCommand)
@guarded
def report(
    src: Path = typer.Argument(..., metavar="SRC", help="Workspace or downlink."),
    out: Path = typer.Option(Path("report.html"), "-o", "--out", help="HTML report to write."),
    sigma_position_m: Optional[float] = typer.Option(
        None, "--sigma-position-m", help="Pose-estimate 1-sigma position noise per stop, relative to the previous stop, for the prediction (default: the rules file's default_sigma_position_m)."),
    sigma_yaw_deg: Optional[float] = typer.Option(
        None, "--sigma-yaw-deg", help="Pose-estimate 1-sigma heading noise per stop, relative to the previous stop, degrees (default: the rules file's default_sigma_yaw_deg)."),
    rules: Optional[Path] = _rules_option(),
    stereo_selfcal: bool = _selfcal_option(),
    products_dir: Optional[str] = _products_dir_option(),
    json_out: bool = typer.Option(False, "--json", help="Summary as JSON on stdout."),
):
    """Write a self-contained HTML diagnostic report."""
    from .commands import report as command

    command.report(src, out, json_out, sigma_position_m=sigma_position_m, sigma_yaw_deg=sigma_yaw_deg,
        products_root=products_dir, rules_path=rules, stereo_selfcal=stereo_selfcal)


@app.command(cls=NonEmptyCommand)
@guarded
def campaign(
    srcs: Optional[List[Path]] = typer.Argument(None, metavar="SRC", help="Downlinks: .mcap files, downlink folders, folders of downlinks, globs."),
    out: Optional[Path] = typer.Option(None, "-o", "--out", help="Campaign folder: records/, manifest.json, summary.json, "
                                       "summary.html. A re-run into the same folder skips the downlinks already done."),
    synth: Optional[str] = typer.Option(None, "--synth", help="SCENARIO: render synthetic downlinks on the workers (paper | traverse)."),
    seeds: Optional[str] = typer.Option(None, "--seeds", help="With --synth: seeds A-B (inclusive), or A,B,C."),
    runs: Optional[str] = typer.Option(None, "--runs", help="With --synth: comma-separated run names (default: all of the scenario)."),
    families: Optional[str] = typer.Option(None, "--families", help="With --synth: comma-separated scene families (default: default)."),
    no_errors: bool = typer.Option(False, "--no-errors", help="With --synth: inject no errors."),
    error_draws: Optional[str] = typer.Option(None, "--error-draws", help="With --synth: error draws A-B or A,B,C (default 0, the seeds' own errors); each draw N > 0 renders every scene again with tomorrow's random errors drawn anew (synth --error-draw)."),
    handoff: bool = typer.Option(True, "--handoff/--no-handoff", help="Run the handoff methods."),
    chain: bool = typer.Option(True, "--chain/--no-chain", help="Run the chain from the pancam designation."),
    predict: bool = typer.Option(True, "--predict/--no-predict", help="Run the pre-uplink prediction of each marked target."),
    closure: bool = typer.Option(False, "--closure", help="Record each chain's closure check with --chain-answer handoff too (with the default answer it always runs; docs/stereo-and-tracking.md, 'Closure')."),
    chain_answer: Optional[str] = typer.Option(None, "--chain-answer", help="The chain's final hazcam answer: closure (the default: the closure's pixel when it is confirmed, skipping the navcam tracks, else the handoff's) or handoff (scip's handoff of the chain's navcam pixel); docs/stereo-and-tracking.md, 'Closure as the answer'."),
    predict_route: str = typer.Option("plan", "--predict-route", help="The approach predicted: plan (the planner's, as sequence uplinks it) or downlink (the downlink's own later stops, which its chain ran over: for scoring the prediction against the chain)."),
    stereo_selfcal: bool = _selfcal_option("every stereo pair of each downlink"),
    methods: Optional[str] = typer.Option(None, "--methods", help="Comma-separated handoff methods, as simulate-handoff (default: scip only, as simulate-handoff; 'all' for every method of the paper and ours)."),
    success_px: float = typer.Option(4.0, "--success-px", help="Success threshold in hazcam pixels."),
    fast: bool = typer.Option(False, "--fast", help="Half-resolution shared dense stereo for the handoff (as simulate-handoff --fast)."),
    scheduler: Optional[str] = typer.Option(None, "--scheduler", help="ADDRESS of an existing Dask scheduler (default: a local cluster)."),
    workers: Optional[int] = typer.Option(None, "--workers", help="Local cluster: worker processes (default: one per core)."),
    memory_limit: Optional[str] = typer.Option(None, "--memory-limit", help="Local cluster: memory per worker, e.g. 4GiB (default: machine memory / workers)."),
    summarize: Optional[Path] = typer.Option(None, "--summarize", help="OUT: only re-aggregate the campaign folder OUT."),
    json_out: bool = typer.Option(False, "--json", help="The summary as JSON on stdout."),
):
    """Run the handoff, the chain and the prediction over many downlinks on a Dask cluster (docs/campaign.md).

    Exit 0: every downlink ran; 1: some downlink failed (recorded with its error, the others ran); 2: bad arguments."""
    from .commands import campaign as command

    command.campaign(srcs, out, synth, seeds, runs, families, no_errors, handoff, chain, predict, methods, success_px,
        fast, scheduler, workers, memory_limit, summarize, json_out, predict_route, closure, chain_answer,
        error_draws=error_draws, stereo_selfcal=stereo_selfcal)


def main() -> None:
    app()


if __name__ == "__main__":
    main()
