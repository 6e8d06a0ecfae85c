"""The downlinks of a campaign (:class:`DownlinkJob`): files, directories and globs (:func:`file_jobs`), or
synthetic scenes named by (scenario, run, seed, family) (:func:`synth_jobs`).

A job carries what a worker needs to load its downlink itself (a path, or the synthetic scene's recipe), never
the images; its ``input_sha256`` (the file's SHA-256, or the recipe's) keys its records.
"""

from __future__ import annotations

import glob
import hashlib
import json
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Optional

from ..errors import InputError

DEFAULT_FAMILY = "default"  # the scenario's own scene (build_run without a family)
FILES_FAMILY = "files"  # a downlink file with no simulation record beside it


@dataclass(frozen=True)
class SynthSpec:
    """A synthetic downlink: ``sim.build.build_run(scenario, run, seed, errors, image_scale, supersample, family,
    error_draw)``."""

    scenario: str
    run: str
    seed: int
    family: str = DEFAULT_FAMILY
    no_errors: bool = False
    image_scale: float = 1.0
    supersample: int = 2
    error_draw: int = 0  # 0: the seed's own errors; N > 0: tomorrow's random errors drawn anew (synth --error-draw)

    def to_dict(self) -> dict:
        d = {"scenario": self.scenario, "run": self.run, "seed": int(self.seed), "family": self.family,
             "no_errors": self.no_errors, "image_scale": float(self.image_scale), "supersample": int(self.supersample)}
        if self.error_draw:  # absent for draw 0: recipes (and their identities) as before the option
            d["error_draw"] = int(self.error_draw)
        return d

    @classmethod
    def from_dict(cls, d: dict) -> "SynthSpec":
        return cls(d["scenario"], d["run"], int(d["seed"]), d.get("family", DEFAULT_FAMILY), bool(d["no_errors"]),
                   float(d["image_scale"]), int(d["supersample"]), int(d.get("error_draw", 0)))

    def sha256(self) -> str:
        """The recipe's identity: same recipe and tool version, same bytes (``synth`` is deterministic)."""
        from .. import __version__

        doc = {"synth": self.to_dict(), "version": __version__}
        if self.family != DEFAULT_FAMILY:
            # a family's jobs rendered with the scenario's unscaled errors before session 32: a new identity, so that
            # resuming an older campaign folder renders them again rather than keeping those records
            doc["family_errors"] = "scaled"
        text = json.dumps(doc, sort_keys=True)
        return hashlib.sha256(text.encode()).hexdigest()

    def regenerate_command(self) -> str:
        """The ``scipctl synth`` command that writes this downlink to a file."""
        env = ""
        if self.image_scale != 1.0:
            env += f"SCIPCTL_SYNTH_IMAGE_SCALE={self.image_scale:g} "
        if self.supersample != 2:
            env += f"SCIPCTL_SYNTH_SUPERSAMPLE={self.supersample} "
        return (f"{env}scipctl synth --scenario {self.scenario} --seed {self.seed} --runs {self.run}"
                + (f" --family {self.family}" if self.family != DEFAULT_FAMILY else "")
                + (" --no-errors" if self.no_errors else "")
                + (f" --error-draw {self.error_draw}" if self.error_draw else "") + " -o OUT")


@dataclass(frozen=True)
class DownlinkJob:
    """One downlink of a campaign: a file (``path``) or a synthetic scene (``synth``).

    ``name`` is the records' ``downlink`` field (the file's name, as ``simulate-handoff`` writes it; or
    ``SCENARIO-RUN-seedN[-FAMILY]``); ``family`` the scene family every record carries.
    """

    name: str
    family: str
    input_sha256: str
    path: Optional[str] = None
    synth: Optional[SynthSpec] = None

    @property
    def job_id(self) -> str:
        """File-name-safe and unique: the name and the start of the input's hash."""
        safe = re.sub(r"[^A-Za-z0-9._-]+", "_", self.name).strip("._") or "downlink"
        return f"{safe}-{self.input_sha256[:12]}"

    def to_dict(self) -> dict:
        return {"name": self.name, "family": self.family, "input_sha256": self.input_sha256, "path": self.path,
                "synth": None if self.synth is None else self.synth.to_dict()}

    @classmethod
    def from_dict(cls, d: dict) -> "DownlinkJob":
        return cls(d["name"], d["family"], d["input_sha256"], d.get("path"),
                   None if d.get("synth") is None else SynthSpec.from_dict(d["synth"]))


# ----------------------------------------------------------------------------- files
_GLOB_CHARS = re.compile(r"[*?\[]")


def _is_product_folder(p: Path) -> bool:
    from ..io.pds_products import is_product_path

    return p.is_dir() and is_product_path(p)


def _downlinks_under(folder: Path) -> list:
    """The downlinks in a folder of downlinks: ``*.mcap`` files and folders holding ``downlink.yaml``, at any depth
    (not inside a downlink folder, nor in hidden folders such as products' ``.scipctl`` sidecars)."""
    found = []
    for p in sorted(folder.iterdir()):
        if p.name.startswith("."):
            continue
        if p.is_file() and p.suffix == ".mcap":
            found.append(p)
        elif p.is_dir():
            found.extend([p] if (p / "downlink.yaml").is_file() else _downlinks_under(p))
    return found


def expand_sources(srcs) -> list:
    """SRC arguments -> downlink paths, in order, each once. A SRC is a downlink (file or folder), a folder of
    downlinks, or a glob (``'sols/*.mcap'``, ``'**'`` recursive). :class:`InputError` naming the SRC when it
    matches nothing."""
    out, seen = [], set()
    for src in srcs:
        s = str(src)
        p = Path(s)
        if p.is_file() or (p / "downlink.yaml").is_file():
            paths = [p]
        elif p.is_dir():  # a folder of downlinks, else one folder of real products
            paths = _downlinks_under(p) or ([p] if _is_product_folder(p) else [])
            if not paths:
                raise InputError(s, "SRC", "no downlinks inside (want .mcap files, folders with downlink.yaml, "
                                 "or rover products)")
        elif p.exists():
            raise InputError(s, "SRC", "not a regular file or directory")
        elif _GLOB_CHARS.search(s):
            hits = [Path(h) for h in sorted(glob.glob(s, recursive=True))]
            paths = [h for h in hits if h.is_file() or (h / "downlink.yaml").is_file()]
            if not paths:
                raise InputError(s, "SRC", "the pattern matches no downlink")
        else:
            raise InputError(s, "SRC", "no such file or directory")
        for q in paths:
            r = q.resolve()
            if r not in seen:
                seen.add(r)
                out.append(q)
    return out


def family_of_file(path: Path) -> str:
    """The scene family of a downlink file: the ``family`` of the simulation record beside it
    (``NAME.sim.json``, as ``synth`` writes it: the realised family's record, whose ``name`` is taken, or a name;
    ``default`` when the record names none), else ``files``."""
    stem = path.name[: -len(".mcap")] if path.name.endswith(".mcap") else path.name
    rec = path.with_name(stem + ".sim.json")
    try:
        doc = json.loads(rec.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return FILES_FAMILY
    fam = doc.get("family", DEFAULT_FAMILY) if isinstance(doc, dict) else None
    if isinstance(fam, dict):  # synth --family writes the realised SceneFamily.to_dict()
        fam = fam.get("name")
    return fam if isinstance(fam, str) and fam else DEFAULT_FAMILY


def file_jobs(srcs) -> list:
    """One :class:`DownlinkJob` per downlink under the SRC arguments (its SHA-256 computed here)."""
    from ..io.provenance import sha256_path

    jobs, ids = [], set()
    for p in expand_sources(srcs):
        try:
            sha = sha256_path(p)
        except OSError as e:
            raise InputError(str(p), "SRC", f"cannot read: {e.strerror or e}") from None
        job = DownlinkJob(p.name, family_of_file(p), sha, path=str(p.resolve()))
        if job.job_id in ids:  # the same bytes under the same name twice: one job
            continue
        ids.add(job.job_id)
        jobs.append(job)
    return jobs


# ----------------------------------------------------------------------------- synthetic
def known_families() -> tuple:
    """``default`` and the simulator's scene families (``scipctl.sim.families.FAMILIES``, when it exists)."""
    try:
        from ..sim.families import FAMILIES
    except ImportError:
        return (DEFAULT_FAMILY,)
    return (DEFAULT_FAMILY,) + tuple(k for k in FAMILIES if k != DEFAULT_FAMILY)


#: the most seeds (or error draws) one campaign may name: a campaign of this many downlinks is ~a core-year
MAX_SEEDS = 100_000


def parse_seeds(text: str, option: str = "--seeds") -> list:
    """``"A-B"`` (inclusive) or ``"A"`` or ``"A,B,C-D"`` -> seeds (or error draws: ``option``) in order, each once;
    at most :data:`MAX_SEEDS` of them (a typo such as ``0-999999999999`` is bad input, not a list built in memory)."""
    seeds = []
    try:
        for part in str(text).split(","):
            part = part.strip()
            if not part:
                continue
            a, sep, b = part.partition("-")
            lo, hi = int(a), int(b) if sep else int(a)
            if lo < 0 or hi < lo:
                raise ValueError
            if len(seeds) + (hi - lo + 1) > MAX_SEEDS:
                raise InputError("campaign", option, f"{text!r}: more than {MAX_SEEDS} values")
            seeds.extend(range(lo, hi + 1))
    except ValueError:
        raise InputError("campaign", option, f"{text!r}: want A-B (0 <= A <= B), A, or a comma-separated list") from None
    if not seeds:
        raise InputError("campaign", option, "nothing given")
    return list(dict.fromkeys(seeds))


def synth_jobs(scenario: str, seeds: list, runs: Optional[list] = None, families: Optional[list] = None,
               no_errors: bool = False, image_scale: float = 1.0, supersample: int = 2,
               error_draws: Optional[list] = None) -> list:
    """One job per (family, seed, run, error draw): ``runs`` default to the scenario's own, ``families`` to
    ``default``, ``error_draws`` to ``[0]`` (the seeds' own errors; a draw N > 0 names its job ``...-dN``)."""
    from ..sim.scenarios import SCENARIOS, list_runs

    if scenario not in SCENARIOS:
        raise InputError("campaign", "--synth", f"unknown scenario {scenario!r} (want one of: {', '.join(SCENARIOS)})")
    known_runs = list_runs(scenario)
    runs = list(dict.fromkeys(runs)) if runs else known_runs
    bad = [r for r in runs if r not in known_runs]
    if bad:
        raise InputError("campaign", "--runs", f"unknown run(s) {', '.join(bad)} for scenario {scenario} "
                         f"(known: {', '.join(known_runs)})")
    fams = list(dict.fromkeys(families)) if families else [DEFAULT_FAMILY]
    known = known_families()
    bad = [f for f in fams if f not in known]
    if bad:
        raise InputError("campaign", "--families", f"unknown famil{'ies' if len(bad) > 1 else 'y'} {', '.join(bad)} "
                         f"(known: {', '.join(known)})")
    draws = list(dict.fromkeys(int(d) for d in error_draws)) if error_draws else [0]
    if any(d < 0 for d in draws):
        raise InputError("campaign", "--error-draws", f"{draws}: want draws >= 0")
    if no_errors and draws != [0]:
        raise InputError("campaign", "--error-draws", "not with --no-errors (there are no random errors to draw anew)")
    jobs = []
    for fam in fams:
        for seed in seeds:
            for run in runs:
                for draw in draws:
                    spec = SynthSpec(scenario, run, int(seed), fam, no_errors, image_scale, supersample, draw)
                    name = (f"{scenario}-{run}-seed{seed}" + ("" if fam == DEFAULT_FAMILY else f"-{fam}")
                            + (f"-d{draw}" if draw else ""))
                    jobs.append(DownlinkJob(name, fam, spec.sha256(), synth=spec))
    return jobs
