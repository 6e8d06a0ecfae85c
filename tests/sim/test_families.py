"""Scene families (scipctl/sim/families.py): the registry, each family's runs (targets marked exactly), the default
family is today's output, ``mixed`` is drawn from the seed, the families' scenes differ as described."""

import json

import numpy as np
import pytest

from scipctl.sim.build import build_run
from scipctl.sim.errors import ErrorSettings
from scipctl.sim.families import FAMILIES, SceneFamily, resolve_family
from scipctl.sim.rocks import ROCK_SHAPES
from scipctl.sim.scenarios import default_errors
from scipctl.sim.terrain import TERRAIN_KINDS
from tests.io.real_data import real_dir
from tests.sim.marks_check import count_exact_marks

SMALL = 0.125


def _needs_real(fam: SceneFamily):
    if fam.needs_shared_real and real_dir() is None:
        pytest.skip("real products absent: no shared/real beside the checkout (set SCIPCTL_SHARED_REAL)")


def test_registry_covers_every_dimension_and_round_trips():
    assert "default" in FAMILIES and "mixed" in FAMILIES
    for name, fam in FAMILIES.items():
        assert fam.name == name and fam.check() is fam and fam.description
        assert SceneFamily.from_dict(json.loads(json.dumps(fam.to_dict()))) == fam
        assert resolve_family(name) is fam and resolve_family(fam) == fam
    fixed = [f for f in FAMILIES.values() if not f.randomised]
    assert {f.terrain for f in fixed} == set(TERRAIN_KINDS)
    assert {f.rocks for f in fixed} == set(ROCK_SHAPES)
    assert {f.texture for f in fixed} == {"procedural", "real", "procedural-filtered"} and {f.rover for f in fixed} == {"default", "m2020"}
    assert {0.0, 0.5, 1.0, 2.0} <= {f.error_scale for f in fixed}
    sun = [f.sun_elevation_deg for f in fixed]
    assert min(lo for lo, _ in sun) <= 20 and max(hi for _, hi in sun) >= 70
    # each fixed family other than default changes exactly one dimension of default
    d = FAMILIES["default"]
    dims = ("terrain", "rocks", "texture", "sun_elevation_deg", "error_scale", "rover")
    for f in fixed:
        changed = [k for k in dims if getattr(f, k) != getattr(d, k)]
        assert len(changed) == (0 if f is d else 1), (f.name, changed)
    assert resolve_family(None) is None
    with pytest.raises(ValueError, match="default, bedrock-slabs"):
        resolve_family("moon-dust")
    for bad in (dict(name="Bad_Name"), dict(name="x", terrain="lava"), dict(name="x", error_scale=2.5),
                dict(name="x", sun_elevation_deg=(50.0, 40.0)), dict(name="x", rover="curiosity")):
        with pytest.raises(ValueError):
            SceneFamily(**bad).check()


def test_mixed_is_drawn_from_the_seed_per_scene():
    mixed = FAMILIES["mixed"]
    draws = [mixed.realise(seed, "paper", scene) for seed in range(12) for scene in (1, 2, 3)]
    assert all(d.realised and not d.randomised and d.name == "mixed" for d in draws)
    assert draws[0] == mixed.realise(0, "paper", 1)  # same seed and scene, same family
    for dim in ("terrain", "rocks", "texture", "sun_elevation_deg", "error_scale", "rover"):
        assert len({getattr(d, dim) for d in draws}) >= 2, dim  # every dimension varies over 36 scenes
    assert SceneFamily.from_dict(draws[3].to_dict()) == draws[3]
    assert FAMILIES["default"].realise(7, "paper", 2) is FAMILIES["default"]


@pytest.mark.parametrize("name", list(FAMILIES))
def test_each_family_builds_a_run_with_three_exactly_marked_targets(name):
    fam = FAMILIES[name]
    _needs_real(fam)
    sim = build_run("paper", "s1-straight", 1, image_scale=SMALL, supersample=1, render=False, family=name)
    real = fam.realise(1, "paper", 1)
    assert sim.record["family"] == real.to_dict()
    assert len(sim.downlink.targets) == 3
    # every target is marked in both eyes of the key pairs (near hazcam, near navcam, far navcam) at least
    assert all(len(t.marks) >= 6 for t in sim.downlink.targets)
    assert count_exact_marks(sim.downlink, sim.scene) >= 18
    sc = sim.scene
    el_deg = np.degrees(np.arcsin(-sc.sun_dir_site[2]))
    lo, hi = real.sun_elevation_deg
    assert lo - 1e-9 <= el_deg <= hi + 1e-9
    want_errors = default_errors("paper").scaled(real.error_scale)
    assert sim.record["errors"] == want_errors.to_dict()
    assert ("rover" in sim.record) == (real.rover == "m2020")
    assert ("texture" in sim.record) == (real.texture == "real")


def test_error_scales_of_the_error_families():
    base = default_errors("paper")
    assert FAMILIES["errors-none"].error_scale == 0.0 and base.scaled(0.0) == ErrorSettings.none()
    assert base.scaled(1.0) is base
    half, double = base.scaled(FAMILIES["errors-half"].error_scale), base.scaled(FAMILIES["errors-double"].error_scale)
    assert half.mast_tilt_offset_rad == pytest.approx(0.5 * base.mast_tilt_offset_rad)
    assert double.heading_drift_sigma_rad_per_m == pytest.approx(2 * base.heading_drift_sigma_rad_per_m)


def test_default_family_is_todays_output():
    a = build_run("paper", "s2-arc", 1, image_scale=SMALL, supersample=1, render=True)
    b = build_run("paper", "s2-arc", 1, image_scale=SMALL, supersample=1, render=True, family="default")
    assert [im.png for im in a.downlink.images] == [im.png for im in b.downlink.images]
    rec = dict(b.record)
    assert rec.pop("family") == FAMILIES["default"].to_dict()
    assert json.dumps(rec, sort_keys=True, default=str) == json.dumps(a.record, sort_keys=True, default=str)
    assert "family" not in a.record


def _scene(name, seed=1):
    return build_run("paper", "s1-straight", seed, image_scale=SMALL, supersample=1, render=False, family=name).scene


def test_terrain_families_differ_from_default_as_described():
    from scipctl.sim.appearance import MAT_PEBBLE, MAT_TERRAIN

    def stats(name):
        sc = _scene(name)
        xy = np.random.default_rng(3).uniform(-3.0, 3.0, (20000, 2))
        xy = xy[np.hypot(xy[:, 0], xy[:, 1]) > 0.8]
        h = sc.cast(np.concatenate([xy, np.full((len(xy), 1), -5.0)], 1), np.tile([0.0, 0.0, 1.0], (len(xy), 1)))
        ter = h.material == MAT_TERRAIN
        sand = sc.appearance.sand_weight(h.points[ter, :2]).mean()
        return {"pebbles": float(np.mean(h.material == MAT_PEBBLE)), "sand": float(sand),
                "near_rocks": sum(1 for r in sc.rocks[1:] if np.hypot(*r.centre_xy_m) < 4.0), "scene": sc}

    d, sand, peb, strewn, slabs = (stats(n) for n in ("default", "sand-sheet", "pebble-field", "rock-strewn", "bedrock-slabs"))
    assert sand["sand"] > 0.99 and d["sand"] < 0.2  # sand everywhere around the rock
    assert peb["pebbles"] > 2 * d["pebbles"] and sand["pebbles"] < 0.5 * d["pebbles"]
    assert strewn["near_rocks"] >= 2 * max(d["near_rocks"], 1)
    # bedrock: the plates show as rock in the albedo (exposure 1 off the cracks), the field has steps and cracks
    sc = slabs["scene"]
    ex = sc.appearance.bedrock_exposure  # the field's exposure at the mesh vertices, interpolated
    k = np.arange(0, len(sc.terrain_xy), 97)
    assert np.allclose(ex(sc.terrain_xy[k]), sc.field.exposure(sc.terrain_xy[k], sc.terrain_spacing_m[k]), atol=1e-6)
    e = ex(np.random.default_rng(4).uniform(-3, 3, (5000, 2)))
    assert 0.5 < np.mean(e == 1.0) < 0.99 and e.min() < 0.5
    assert d["scene"].appearance.bedrock_exposure is None


def test_rock_shape_families_change_the_rocks():
    def aspect(name):
        r = _scene(name).target_rock
        return r.size_m[2] / r.size_m[0]

    assert aspect("slab-rocks") < 0.6 * aspect("default")
    sharp = {n: float(np.max(_scene(n).target_rock.corner_sharpness_rad)) for n in ("default", "rounded-boulders")}
    assert sharp["rounded-boulders"] < 0.5 * sharp["default"]
