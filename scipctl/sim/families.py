"""Scene families: named recipes for the simulator's scenes, so a population is not one kind of scene.

A :class:`SceneFamily` fixes six dimensions of what :func:`scipctl.sim.build.build_run` makes:

* ``terrain``: a key of :data:`scipctl.sim.terrain.TERRAIN_KINDS` (``rolling`` today's soil; ``bedrock-slabs``,
  ``sand-sheet``, ``pebble-field``, ``rock-strewn``) -- height field, rocks, pebbles and drift sand;
* ``rocks``: a key of :data:`scipctl.sim.rocks.ROCK_SHAPES` (``faceted`` today's; ``angular``, ``slab``,
  ``rounded``);
* ``texture``: ``procedural`` (today's), ``real`` (the pictures of ``shared/real`` draped on the terrain, read at
  run time through :mod:`scipctl.io.texture_sources`; the repository keeps no copy) or ``procedural-filtered``
  (today's, with the thresholded specks filtered after the threshold, so the texture does not change with range:
  :class:`~scipctl.sim.appearance.Appearance` ``specks``; docs/simulator.md, "Specks and range");
* ``sun_elevation_deg``: the range the sun's elevation is drawn from (today 35-60 deg); shadows are cast by
  shadow rays (:meth:`scipctl.sim.scene.Scene.radiance`), so a low sun makes long shadows;
* ``error_scale``: in [0, 2], multiplying the scenario's default :class:`~scipctl.sim.errors.ErrorSettings`
  magnitudes (:meth:`~scipctl.sim.errors.ErrorSettings.scaled`; 0 is ``ErrorSettings.none()``);
* ``rover``: ``default`` (``rocky8-sim``) or ``m2020`` (Mars 2020's real camera models and URDF from
  ``shared/real/12_*``, read at run time through :mod:`scipctl.io.m2020_geometry`).

:data:`FAMILIES` is the registry (kebab-case names). ``default`` is exactly today's output. Each other fixed
family changes one dimension from ``default``; ``mixed`` draws every dimension per scene from the seed
(:meth:`SceneFamily.realise`), for populations.
"""

from __future__ import annotations

import re
from dataclasses import asdict, dataclass, replace
from typing import Optional, Union

from .rocks import ROCK_SHAPES
from .terrain import TERRAIN_KINDS

TEXTURES = ("procedural", "real", "procedural-filtered")
ROVERS = ("default", "m2020")
DEFAULT_SUN_ELEVATION_DEG = (35.0, 60.0)
MIXED_SUN_ELEVATION_DEG = (10.0, 80.0)
MIXED_P_REAL_TEXTURE = 0.3
MIXED_P_M2020 = 0.25
_KEBAB = re.compile(r"^[a-z0-9]+(-[a-z0-9]+)*$")


@dataclass(frozen=True)
class SceneFamily:
    """A scene family (see the module docstring). ``randomised``: every dimension is drawn per scene by
    :meth:`realise` (the fields are then placeholders); ``realised``: this is such a draw for one scene;
    ``description``: one line for the docs."""

    name: str
    terrain: str = "rolling"
    rocks: str = "faceted"
    texture: str = "procedural"
    sun_elevation_deg: tuple = DEFAULT_SUN_ELEVATION_DEG
    error_scale: float = 1.0
    rover: str = "default"
    description: str = ""
    randomised: bool = False
    realised: bool = False

    def check(self) -> "SceneFamily":
        """``self`` if every field is valid, else ValueError naming the field."""
        if not _KEBAB.match(self.name):
            raise ValueError(f"family name {self.name!r}: want kebab-case (a-z, 0-9, single hyphens)")
        if self.terrain not in TERRAIN_KINDS:
            raise ValueError(f"family {self.name}: terrain {self.terrain!r} (want one of {', '.join(TERRAIN_KINDS)})")
        if self.rocks not in ROCK_SHAPES:
            raise ValueError(f"family {self.name}: rocks {self.rocks!r} (want one of {', '.join(ROCK_SHAPES)})")
        if self.texture not in TEXTURES:
            raise ValueError(f"family {self.name}: texture {self.texture!r} (want one of {', '.join(TEXTURES)})")
        if self.rover not in ROVERS:
            raise ValueError(f"family {self.name}: rover {self.rover!r} (want one of {', '.join(ROVERS)})")
        lo, hi = self.sun_elevation_deg
        if not 0 < lo <= hi < 90:
            raise ValueError(f"family {self.name}: sun_elevation_deg {self.sun_elevation_deg} (want 0 < lo <= hi < 90)")
        if not 0.0 <= self.error_scale <= 2.0:
            raise ValueError(f"family {self.name}: error_scale {self.error_scale} (want 0 .. 2)")
        return self

    @property
    def scene_key(self) -> tuple:
        """What the scene depends on (besides seed, rover and real texture): terrain, rocks, sun range, and how the
        specks meet the footprint (:class:`~scipctl.sim.appearance.Appearance` ``specks``)."""
        specks = "filtered" if self.texture == "procedural-filtered" else "lod"
        return (self.terrain, self.rocks, tuple(float(v) for v in self.sun_elevation_deg), specks)

    @property
    def needs_shared_real(self) -> bool:
        """True if building it reads ``shared/real`` (real texture or the Mars 2020 rover; ``mixed`` may)."""
        return self.randomised or self.texture == "real" or self.rover != "default"

    def realise(self, seed: int, scenario: str, scene_index: int) -> "SceneFamily":
        """The concrete family of one scene: ``self`` unless ``randomised``; then each dimension is drawn from
        ``(seed, scenario, scene_index)`` (both runs of a scene share it): terrain and rock shape uniformly, real
        texture with probability 0.3, the sun's elevation uniformly in 10-80 deg, the error scale uniformly in
        [0, 2] (to 0.01), the Mars 2020 rover with probability 0.25. The result keeps the name and has
        ``realised`` set."""
        if not self.randomised:
            return self
        from .scenarios import _rng

        r = _rng(int(seed), scenario, "family", self.name, int(scene_index))
        terrain = list(TERRAIN_KINDS)[int(r.integers(len(TERRAIN_KINDS)))]
        rocks = list(ROCK_SHAPES)[int(r.integers(len(ROCK_SHAPES)))]
        texture = "real" if r.uniform() < MIXED_P_REAL_TEXTURE else "procedural"
        el = round(float(r.uniform(*MIXED_SUN_ELEVATION_DEG)), 1)
        scale = round(float(r.uniform(0.0, 2.0)), 2)
        rover = "m2020" if r.uniform() < MIXED_P_M2020 else "default"
        return replace(self, terrain=terrain, rocks=rocks, texture=texture, sun_elevation_deg=(el, el), error_scale=scale,
                       rover=rover, randomised=False, realised=True).check()

    def to_dict(self) -> dict:
        d = asdict(self)
        d["sun_elevation_deg"] = [float(v) for v in self.sun_elevation_deg]
        return d

    @staticmethod
    def from_dict(d: dict) -> "SceneFamily":
        known = {k: d[k] for k in SceneFamily.__dataclass_fields__ if k in d}
        if "sun_elevation_deg" in known:
            known["sun_elevation_deg"] = tuple(float(v) for v in known["sun_elevation_deg"])
        return SceneFamily(**known).check()


def _families(*fams: SceneFamily) -> dict:
    return {f.name: f.check() for f in fams}


FAMILIES: dict[str, SceneFamily] = _families(
    SceneFamily("default", description="today's scenes: rolling soil, faceted rocks, procedural texture, sun 35-60 deg, "
                                       "default errors, rocky8-sim rover"),
    SceneFamily("bedrock-slabs", terrain="bedrock-slabs",
                description="flat bedrock plates ~1.6 m across with 1-2 cm steps and dusty cracks; few pebbles"),
    SceneFamily("sand-sheet", terrain="sand-sheet",
                description="smooth rippled sand everywhere, sparse pebbles, few rocks: low texture"),
    SceneFamily("pebble-field", terrain="pebble-field",
                description="ground paved with pebbles (3x today's count, up to 1.5x larger), no drift sand"),
    SceneFamily("rock-strewn", terrain="rock-strewn",
                description="30 rocks within 0.6-4 m of the target rock (cobbles up to 18 cm also in the approach corridors) "
                            "and 150 out to 25 m; default: 5 and 40"),
    SceneFamily("angular-rocks", rocks="angular", description="jointed blocks: few large planar faces, straight edges"),
    SceneFamily("slab-rocks", rocks="slab", description="tabular slabs with flat tops, ~0.4x as high"),
    SceneFamily("rounded-boulders", rocks="rounded", description="weathered rounded boulders, no sharp corners"),
    SceneFamily("low-sun", sun_elevation_deg=(10.0, 20.0), description="sun 10-20 deg high: long cast shadows"),
    SceneFamily("high-sun", sun_elevation_deg=(70.0, 85.0), description="sun 70-85 deg high: short shadows, flat light"),
    SceneFamily("errors-none", error_scale=0.0, description="no injected errors (ErrorSettings.none(); sensor noise stays)"),
    SceneFamily("errors-half", error_scale=0.5, description="every default error at half its magnitude"),
    SceneFamily("errors-double", error_scale=2.0, description="every default error at twice its magnitude"),
    SceneFamily("filtered-specks", texture="procedural-filtered",
                description="today's scenes with the specks filtered after their threshold: the texture is the same "
                            "at any range (docs/simulator.md, 'Specks and range')"),
    SceneFamily("real-texture", texture="real",
                description="real Mars image texture from shared/real draped on the soil (read at run time)"),
    SceneFamily("m2020", rover="m2020",
                description="Mars 2020 rig: real static camera models and URDF from shared/real/12_* (read at run time)"),
    SceneFamily("mixed", randomised=True,
                description="every dimension drawn per scene from the seed (terrain, rocks, texture, sun, errors, rover)"),
)


def resolve_family(family: Union[SceneFamily, str, None]) -> Optional[SceneFamily]:
    """A :class:`SceneFamily` from a name of :data:`FAMILIES` or a family (checked); None stays None.
    ValueError naming the known families for an unknown name."""
    if family is None:
        return None
    if isinstance(family, SceneFamily):
        return family.check()
    if family not in FAMILIES:
        raise ValueError(f"unknown scene family {family!r} (want one of: {', '.join(FAMILIES)})")
    return FAMILIES[family]


def family_of_run(family: Union[SceneFamily, str], scenario: str, run: str, seed: int) -> SceneFamily:
    """The realised family of one run (its scene's draw for ``mixed``); ValueError for an unknown family or run."""
    from .scenarios import list_runs

    fam = resolve_family(family)
    runs = list_runs(scenario)
    if run not in runs:
        raise ValueError(f"run: unknown {run!r} for scenario {scenario} (want one of {', '.join(runs)})")
    return fam.realise(seed, scenario, int(run.split("-")[0][1:]))


# ----------------------------------------------------------------------------- run-time inputs (through io)
_LOADED: dict = {}


def _shared_real(what: str):
    from ..errors import InputError
    from ..io.shared_real import ENV, shared_real_dir

    root = shared_real_dir()
    if root is None:
        raise InputError("shared/real", ENV, f"{what} reads shared/real at run time: none beside the checkout (set {ENV})")
    return root


def m2020_sim_rover(folder, **config_kwargs):
    """The Mars 2020 rover for the simulator's scenarios (:class:`~scipctl.sim.rover.SimRover`), from the two files
    in ``folder`` (:func:`scipctl.io.m2020_geometry.m2020_rover_files`); InputError naming the folder if the
    configuration does not fit the simulator."""
    from ..errors import InputError
    from ..io.m2020_geometry import MODELS_FILE, m2020_rover_files
    from .rover import sim_rover_from_config

    config, wheels, inputs, notes = m2020_rover_files(folder, **config_kwargs)
    try:
        return sim_rover_from_config("m2020", config, wheels, inputs, notes)
    except ValueError as e:
        raise InputError(str(folder), MODELS_FILE, str(e)) from None


def family_rover(family: SceneFamily):
    """The :class:`~scipctl.sim.rover.SimRover` a (realised) family needs: None for ``default``; the Mars 2020
    rover from ``shared/real/12_*`` (loaded once per process)."""
    if family.rover == "default":
        return None
    from ..errors import InputError
    from ..io.shared_real import ENV, shared_real_sub

    _shared_real(f"family {family.name} (rover m2020)")
    folder = shared_real_sub("12_")
    if folder is None:
        raise InputError("shared/real", "12_*", f"family {family.name} needs the Mars 2020 models folder 12_* (set {ENV})")
    key = ("rover", str(folder))
    if key not in _LOADED:
        _LOADED[key] = m2020_sim_rover(folder)
    return _LOADED[key]


def family_texture(family: SceneFamily):
    """The :class:`~scipctl.sim.texture.TextureSources` a (realised) family needs: None for ``procedural``; for
    ``real`` every usable picture under ``shared/real`` (default crop and pixel size; loaded once per process)."""
    if family.texture != "real":
        return None
    from ..io.texture_sources import iter_texture_pictures
    from .texture import texture_sources_from_pictures

    root = _shared_real(f"family {family.name} (real texture)")
    key = ("texture", str(root))
    if key not in _LOADED:
        # recorded as "shared/real" (the machine's path is not part of the scene)
        _LOADED[key] = texture_sources_from_pictures("shared/real", iter_texture_pictures(root))
    return _LOADED[key]
