"""``scipctl synth``: render synthetic downlinks with exact truth (see docs/simulator.md).

One downlink per run is written into OUT: ``OUT/<scenario>-<run>.mcap`` (or
the directory ``OUT/<scenario>-<run>/``), plus ``OUT/<scenario>-<run>.sim.json``,
the simulation record (error settings and every realised error, true and
estimated poses, target selection). Same arguments, same bytes: nothing in
the data depends on the clock or on the output path.

``--rover m2020`` renders with the Mars 2020 configuration read at run time
from ``--rover-dir`` (``m2020-camera-models.json`` + ``m2020.urdf``);
``--texture-from DIR`` drapes the texture of the pictures under DIR on the
terrain. Both are recorded (file SHA-256s) in the ``.sim.json``; without them
the output is byte-identical to what it was before they existed.

``--family NAME`` builds every run from a scene family of
:data:`scipctl.sim.families.FAMILIES` (terrain, rock shape, texture, sun,
error scale, rover); it is recorded in the ``.sim.json`` (``family``) and in the
regenerate command. ``--rover`` / ``--rover-dir`` / ``--texture-from`` may only
supply what the family itself uses (its Mars 2020 models folder or its real
texture folder; default ``shared/real``).
"""

from __future__ import annotations

import json
import shlex
import sys
from pathlib import Path
from typing import Optional

from ..errors import InputError
from ..jsonutil import json_default
from .output import emit_json, stderr_console


def regenerate_command(scenario: str, seed: int, container: str, run: str, no_errors: bool,
                       image_scale: float = 1.0, supersample: int = 2, extra_args: str = "") -> str:
    """The command that makes the same bytes (``extra_args``: the rover/texture options, empty for the defaults)."""
    env = ""
    if image_scale != 1.0:
        env += f"SCIPCTL_SYNTH_IMAGE_SCALE={image_scale:g} "
    if supersample != 2:
        env += f"SCIPCTL_SYNTH_SUPERSAMPLE={supersample} "
    cmd = f"{env}scipctl synth --scenario {scenario} --seed {seed} --container {container} --runs {run}"
    return cmd + (" --no-errors" if no_errors else "") + (f" {extra_args}" if extra_args else "") + " -o OUT"


ROVERS = ("default", "m2020")
M2020_FOLDER_PREFIX = "12_"


def _default_m2020_dir() -> Optional[Path]:
    """``shared/real/12_*`` beside the checkout (``$SCIPCTL_SHARED_REAL`` first), as the tests find it."""
    from ..io.shared_real import shared_real_sub

    return shared_real_sub(M2020_FOLDER_PREFIX)


def load_rover(rover: str, rover_dir: Optional[Path]):
    """The :class:`~scipctl.sim.rover.SimRover` for ``--rover`` (None for the default: the scenarios' own)."""
    if rover not in ROVERS:
        raise InputError("synth", "--rover", f"unknown rover {rover!r} (want one of: {', '.join(ROVERS)})")
    if rover == "default":
        if rover_dir is not None:
            raise InputError("synth", "--rover-dir", "only with --rover m2020")
        return None
    folder = rover_dir if rover_dir is not None else _default_m2020_dir()
    if folder is None:
        raise InputError("synth", "--rover-dir", "no Mars 2020 models folder given and no shared/real/12_* beside the checkout")
    if not Path(folder).is_dir():
        raise InputError(str(folder), "--rover-dir", "not a folder")
    return m2020_sim_rover(folder)


def m2020_sim_rover(folder, **config_kwargs):
    """The Mars 2020 rover for the simulator's scenarios (:func:`scipctl.sim.families.m2020_sim_rover`)."""
    from ..sim.families import m2020_sim_rover as load

    return load(folder, **config_kwargs)


def load_family(name: Optional[str], scenario: str, seed: int, runs: list, rover: Optional[str], rover_dir: Optional[Path],
                texture_from: Optional[Path]):
    """``--family``: ``(family, sim_rover, texture)`` -- the :class:`~scipctl.sim.families.SceneFamily` (None without
    ``--family``) and the rover / texture it needs, loaded now (from ``--rover-dir`` / ``--texture-from`` if given,
    else ``shared/real``), so that bad input stops before anything is written. A randomised family's needs are
    loaded for each run's scene. InputError for an unknown name or options the family does not use."""
    from ..sim.families import FAMILIES, family_of_run, family_rover, family_texture

    if name is None:
        return None, None, None
    if name not in FAMILIES:
        raise InputError("synth", "--family", f"unknown family {name!r} (want one of: {', '.join(FAMILIES)})")
    fam = FAMILIES[name]
    if rover is not None and (fam.randomised or fam.rover != rover):  # None: --rover not given
        raise InputError("synth", "--rover", f"family {name} sets the rover ({'drawn per scene' if fam.randomised else fam.rover}): leave --rover out")
    if rover_dir is not None and (fam.randomised or fam.rover != "m2020"):
        raise InputError("synth", "--rover-dir", f"family {name} does not use a fixed Mars 2020 rover")
    if texture_from is not None and (fam.randomised or fam.texture != "real"):
        raise InputError("synth", "--texture-from", f"family {name} does not use a fixed real texture")
    if fam.randomised:  # load what each run's scene draws (cached), and check it exists
        for r in runs:
            real = family_of_run(fam, scenario, r, seed)
            family_rover(real)
            family_texture(real)
        return fam, None, None
    sim_rover = None
    if fam.rover == "m2020":
        sim_rover = load_rover("m2020", rover_dir) if rover_dir is not None else family_rover(fam)
    texture = read_texture_sources(texture_from) if texture_from is not None else family_texture(fam)
    return fam, sim_rover, texture


def read_texture_sources(folder, crop_frac=None, pixel_m=None):
    """:class:`~scipctl.sim.texture.TextureSources` from the pictures under ``folder`` (``--texture-from``):
    :func:`scipctl.io.texture_sources.iter_texture_pictures` reads them,
    :func:`scipctl.sim.texture.texture_sources_from_pictures` chooses the usable ones."""
    from ..io.texture_sources import iter_texture_pictures
    from ..sim.texture import texture_sources_from_pictures

    return texture_sources_from_pictures(folder, iter_texture_pictures(folder), crop_frac, pixel_m)


def parse_crop(text: Optional[str]) -> Optional[tuple]:
    """``"X0,Y0,X1,Y1"`` (fractions, ``0 <= X0 < X1 <= 1``, same for Y) -> tuple, None -> None."""
    if text is None:
        return None
    try:
        vals = tuple(float(v) for v in text.split(","))
        if len(vals) != 4 or not (0 <= vals[0] < vals[2] <= 1 and 0 <= vals[1] < vals[3] <= 1):
            raise ValueError
    except ValueError:
        raise InputError("synth", "--texture-crop", f"{text!r}: want X0,Y0,X1,Y1 fractions with 0 <= X0 < X1 <= 1, 0 <= Y0 < Y1 <= 1") from None
    return vals


def record_json(record: dict) -> str:
    """The simulation record as deterministic JSON text."""
    return json.dumps(record, indent=1, sort_keys=True, allow_nan=False, default=_plain) + "\n"


_plain = json_default


def synth(scenario: str, seed: int, out: Path, container: str, runs: Optional[str], no_errors: bool, json_out: bool,
        rover: Optional[str] = None, rover_dir: Optional[Path] = None, texture_from: Optional[Path] = None,
        texture_crop: Optional[str] = None, texture_pixel_mm: float = 2.5, family: Optional[str] = None,
        error_draw: int = 0) -> None:
    from ..sim.scenarios import SCENARIOS, list_runs

    if scenario not in SCENARIOS:
        raise InputError("synth", "--scenario", f"unknown scenario {scenario!r} (want one of: {', '.join(SCENARIOS)})")
    if container not in ("mcap", "dir"):
        raise InputError("synth", "--container", f"unknown container {container!r} (want mcap or dir)")
    known = list_runs(scenario)
    if runs is None or not runs.strip():
        selected = known
    else:
        selected = [r.strip() for r in runs.split(",") if r.strip()]
        if not selected:
            raise InputError("synth", "--runs", f"{runs!r} names no run (known: {', '.join(known)})")
        bad = [r for r in selected if r not in known]
        if bad:
            raise InputError("synth", "--runs", f"unknown run(s) {', '.join(bad)} for scenario {scenario} (known: {', '.join(known)})")
        selected = list(dict.fromkeys(selected))
    from ..io.atomic import check_output_dir, check_output_file

    out = check_output_dir(out, "-o/--out")
    for run_name in selected:  # each run's files (a folder in the way of one): said before the work
        downlink_path, record_path = run_paths(out, scenario, run_name, container)
        check_output_file(record_path, "-o/--out")
        if container == "mcap":
            check_output_file(downlink_path, "-o/--out")
    if error_draw < 0:
        raise InputError("synth", "--error-draw", f"{error_draw}: want an integer >= 0")
    if error_draw and no_errors:
        raise InputError("synth", "--error-draw", "not with --no-errors (there are no random errors to draw anew)")
    image_scale, supersample = _env_quality()
    # everything that can be bad input is checked before anything is written
    if family is not None:
        if texture_crop is not None or texture_pixel_mm != 2.5:
            raise InputError("synth", "--texture-crop" if texture_crop is not None else "--texture-pixel-mm",
                             "not with --family (a family's real texture uses the default crop and pixel size)")
        fam, sim_rover, texture = load_family(family, scenario, seed, selected, rover, rover_dir, texture_from)
        rovers = [sim_rover]
        if fam.randomised:
            from ..sim.families import family_of_run, family_rover

            rovers = [family_rover(family_of_run(fam, scenario, r, seed)) for r in selected]
        for rv in rovers:
            _check_scale(image_scale, rv)
        extra = [f"--family {family}"] + ([f"--error-draw {error_draw}"] if error_draw else [])
        if rover_dir is not None:
            extra.append(f"--rover-dir {shlex.quote(str(rover_dir))}")
        if texture_from is not None:
            extra.append(f"--texture-from {shlex.quote(str(texture_from))}")
        written = synthesize(scenario, seed, out, container, selected, no_errors, image_scale=image_scale,
                             supersample=supersample, rover=sim_rover, texture=texture, extra_args=" ".join(extra),
                             family=fam, error_draw=error_draw)
    else:
        rover = rover or "default"
        sim_rover = load_rover(rover, rover_dir)
        _check_scale(image_scale, sim_rover)
        crop = parse_crop(texture_crop)
        if not (0.1 <= texture_pixel_mm <= 100.0):
            raise InputError("synth", "--texture-pixel-mm", f"{texture_pixel_mm:g}: want 0.1 .. 100")
        texture = None
        extra = []
        if sim_rover is not None:
            extra.append(f"--rover {rover}" + (f" --rover-dir {shlex.quote(str(rover_dir))}" if rover_dir is not None
                                               else ""))
        if texture_from is not None:
            texture = read_texture_sources(texture_from, crop, texture_pixel_mm * 1e-3)
            extra.append(f"--texture-from {shlex.quote(str(texture_from))}"
                         + (f" --texture-crop {shlex.quote(texture_crop)}" if texture_crop else "")
                         + (f" --texture-pixel-mm {texture_pixel_mm:g}" if texture_pixel_mm != 2.5 else ""))
        elif texture_crop is not None or texture_pixel_mm != 2.5:
            raise InputError("synth", "--texture-crop" if texture_crop is not None else "--texture-pixel-mm", "only with --texture-from")
        if error_draw:
            extra.append(f"--error-draw {error_draw}")
        written = synthesize(scenario, seed, out, container, selected, no_errors, image_scale=image_scale, supersample=supersample,
                             rover=sim_rover, texture=texture, extra_args=" ".join(extra), error_draw=error_draw)
    if json_out:
        emit_json({"scenario": scenario, "seed": seed, "container": container, "no_errors": no_errors, "runs": written})
    else:
        for w in written:
            sys.stdout.write(f"{w['path']}  ({w['images']} images, {len(w['targets'])} targets, {w['bytes']} bytes)\n")


def _env_quality() -> tuple[float, int]:
    """Preview/test hooks: ``SCIPCTL_SYNTH_IMAGE_SCALE`` (e.g. 0.125 -> 128 x 128 images) and
    ``SCIPCTL_SYNTH_SUPERSAMPLE`` (samples per pixel side, default 2). Both are recorded in the .sim.json."""
    import os

    raw_s = os.environ.get("SCIPCTL_SYNTH_IMAGE_SCALE", "1")
    raw_q = os.environ.get("SCIPCTL_SYNTH_SUPERSAMPLE", "2")
    try:
        scale = float(raw_s)
        if not (0 < scale <= 1):
            raise ValueError
    except ValueError:
        raise InputError("environment", "SCIPCTL_SYNTH_IMAGE_SCALE", f"{raw_s!r}: want a number in (0, 1]") from None
    try:
        ss = int(raw_q)
        if not 1 <= ss <= 8:
            raise ValueError
    except ValueError:
        raise InputError("environment", "SCIPCTL_SYNTH_SUPERSAMPLE", f"{raw_q!r}: want an integer 1 .. 8") from None
    return scale, ss


def _check_scale(scale: float, sim_rover) -> None:
    """``SCIPCTL_SYNTH_IMAGE_SCALE`` must give whole image sizes for every camera of the rover (1024 px default)."""
    from ..sim.rover import default_rover_config

    config = default_rover_config() if sim_rover is None else sim_rover.config
    for name, cam in sorted(config.cameras.items()):
        for spec in (cam.left, cam.right):
            w, h = spec.width * scale, spec.height * scale
            if abs(w - round(w)) > 1e-9 or abs(h - round(h)) > 1e-9:
                raise InputError("environment", "SCIPCTL_SYNTH_IMAGE_SCALE",
                                 f"{scale:g}: {name} {spec.width} x {spec.height} x scale is not whole")


def run_paths(out: Path, scenario: str, run_name: str, container: str) -> tuple[Path, Path]:
    """``(downlink, truth record)`` that ``synth`` writes for one run into ``out``."""
    name = f"{scenario}-{run_name}"
    return out / (f"{name}.mcap" if container == "mcap" else name), out / f"{name}.sim.json"


def synthesize(scenario: str, seed: int, out: Path, container: str, runs: list, no_errors: bool,
               image_scale: float = 1.0, supersample: int = 2, show_progress: bool = True,
               rover=None, texture=None, extra_args: str = "", family=None, error_draw: int = 0) -> list[dict]:
    """Build and write each run; returns one summary per run (path, counts, sha256).

    ``rover``: a :class:`~scipctl.sim.rover.SimRover` (None: default, or the family's); ``texture``: a
    :class:`~scipctl.sim.texture.TextureSources` (None: procedural, or the family's); ``family``: a
    :class:`~scipctl.sim.families.SceneFamily` or None; ``extra_args``: their options, for the record's
    ``regenerate`` command; ``error_draw``: :func:`~scipctl.sim.build.build_run`'s."""
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

    from ..io.atomic import output_group
    from ..io.downlink import write_downlink
    from ..io.provenance import sha256_path
    from ..sim.errors import ErrorSettings
    from ..sim.build import build_run
    from ..sim.scenarios import default_errors

    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise InputError(str(out), "-o/--out", f"cannot make the folder: {e.strerror or e}") from None
    console = stderr_console()
    written = []
    with Progress(TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn(),
                  console=console, disable=not show_progress, transient=False) as bar:
        for run_name in runs:
            name = f"{scenario}-{run_name}"
            task = bar.add_task(f"{name}: scene", total=None)

            def cb(done, total, pid, task=task, name=name):
                bar.update(task, total=total, completed=done, description=f"{name}: {pid}")

            if no_errors:
                errors = ErrorSettings.none()
            elif family is not None:
                errors = None  # the scenario's default errors scaled by the family's error scale
            else:
                errors = default_errors(scenario)
            sim = build_run(scenario, run_name, seed, errors=errors, image_scale=image_scale, supersample=supersample, progress=cb,
                            rover=rover, texture=texture, family=family, error_draw=error_draw)
            path, rec_path = run_paths(out, scenario, run_name, container)
            bar.update(task, description=f"{name}: writing {path.name}")
            rec = dict(sim.record)
            from .. import __version__

            rec["written_by"] = {"tool": "scipctl", "version": __version__,
                                 "regenerate": regenerate_command(scenario, seed, container, run_name, no_errors,
                                                                 image_scale, supersample, extra_args)}
            rec["no_errors"] = bool(no_errors)
            # the downlink and its truth record together: the record is staged first and goes in after the
            # downlink (itself written atomically); a failed downlink write leaves neither
            with output_group() as outputs:
                outputs.add_text(rec_path, record_json(rec), "-o/--out")
                try:
                    write_downlink(sim.downlink, path, container)
                except OSError as e:
                    raise InputError(str(path), "-o/--out", f"cannot write: {e.strerror or e}") from None
            bar.update(task, description=f"{name}: done")
            written.append({
                "run": run_name, "path": str(path), "record": str(rec_path), "container": container,
                "images": len(sim.downlink.images), "targets": [t.id for t in sim.downlink.targets],
                "bytes": _size(path), "sha256": sha256_path(path),
            })
    return written


def _size(path: Path) -> int:
    if path.is_file():
        return path.stat().st_size
    return sum(p.stat().st_size for p in path.rglob("*") if p.is_file())
