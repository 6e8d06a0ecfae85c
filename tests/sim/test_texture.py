"""Real surface texture (``synth --texture-from``): the atlas is the real pictures' contrast, the rendered ground
reproduces a known crop of a source picture, the texture is deterministic, and bad folders are one-line errors.

The pictures are read where they are (``shared/real`` beside the checkout); the repository keeps no copy."""

import json

import numpy as np
import pytest
from typer.testing import CliRunner

from scipctl.cli import app
from scipctl.commands.synth import read_texture_sources
from scipctl.core.camera import cahv_from_intrinsics
from scipctl.core.transforms import RigidTransform
from scipctl.io.downlink import read_downlink
from scipctl.sim import build as sim_build
from scipctl.sim.appearance import MAT_TERRAIN
from scipctl.sim.render import render_radiance
from scipctl.sim.scene import make_scene
from scipctl.sim.texture import OVERLAP_PX, PATCH_PX, build_surface_texture, patch_pixels, relative_contrast
from tests.io.real_data import real

runner = CliRunner()
SMALL_ENV = {"SCIPCTL_SYNTH_IMAGE_SCALE": "0.125", "SCIPCTL_SYNTH_SUPERSAMPLE": "1"}
SCENE_SEED = 4242


@pytest.fixture(scope="module")
def sources():
    return read_texture_sources(real("05_"))  # two MSL navcam frames (.IMG; their .LBL twins are skipped as duplicates)


@pytest.fixture(scope="module")
def atlas(sources):
    return build_surface_texture(sources, SCENE_SEED)


def _ncc(a, b):
    a = a - a.mean()
    b = b - b.mean()
    return float((a * b).sum() / np.sqrt((a * a).sum() * (b * b).sum()))


def test_sources_are_read_once_with_hashes(sources):
    names = [im.name for im in sources.images]
    assert len(names) == 2 and all(n.endswith(".IMG") for n in names)
    assert {n.rsplit("/", 1)[-1].rsplit(".", 1)[1] for n, why in sources.skipped if "same pixels" in why} == {"LBL"}
    from scipctl.io.provenance import sha256_file

    for im in sources.images:
        assert im.sha256 == sha256_file(real("05_") / im.name.split("/", 1)[-1])


def test_atlas_patch_cores_are_exactly_the_source_contrast(sources, atlas):
    contrast = [relative_contrast(im.pixels) for im in sources.images]
    c = slice(OVERLAP_PX, PATCH_PX - OVERLAP_PX)  # the core: one patch only
    n = atlas.levels[0].shape[0]
    used = set()
    for p in atlas.patches[::37]:
        want = patch_pixels(contrast[p.source], p)[c, c]
        rows = (p.atlas_row0 + np.arange(PATCH_PX))[c] % n
        cols = (p.atlas_col0 + np.arange(PATCH_PX))[c] % n
        assert np.allclose(atlas.levels[0][np.ix_(rows, cols)], want, atol=1e-6)
        used.add(p.source)
    assert used == {0, 1}
    # every patch lies inside the default crop (the lower middle of the frame: ground, not sky)
    H, W = sources.images[0].pixels.shape
    assert all(p.row0 >= 0.55 * H - 1 and p.row0 + PATCH_PX <= 0.92 * H + 1 for p in atlas.patches)


def test_atlas_is_seeded(sources, atlas):
    again = build_surface_texture(sources, SCENE_SEED)
    assert np.array_equal(again.levels[0], atlas.levels[0]) and again.patches == atlas.patches
    other = build_surface_texture(sources, SCENE_SEED + 1)
    assert not np.array_equal(other.levels[0], atlas.levels[0])


def _nadir_view(scene, atlas, patch, height_m=1.0, px=64, f_px=800.0):
    """A CAHV camera ``height_m`` above the middle of ``patch``'s core (the copy of the periodic tile within
    +-2.5 m of the rock), looking straight down; returns (model in the site frame, xy of the centre)."""
    P = atlas.period_m
    rc = np.array([patch.atlas_row0 + PATCH_PX / 2, patch.atlas_col0 + PATCH_PX / 2]) * atlas.pixel_m
    xy = np.where(rc > P / 2, rc - P, rc)
    g = scene.ground_height_m(xy[None])[0]
    R = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])  # u -> site +y, v -> site -x, boresight down
    T_site_cam = RigidTransform(R, np.array([xy[0], xy[1], -g - height_m]))
    return cahv_from_intrinsics(f_px, f_px, (px - 1) / 2, (px - 1) / 2, T_site_cam), xy


def test_flat_ground_renders_a_known_crop_of_the_source(sources, atlas):
    """A nadir view of a patch's core: the rendered radiance follows the source crop (rotated as placed), and not
    the procedural grain of the same scene without the texture."""
    textured = make_scene(SCENE_SEED, texture=atlas)
    plain = make_scene(SCENE_SEED)
    contrast = [relative_contrast(im.pixels) for im in sources.images]
    px = 64
    results = []
    for patch in atlas.patches[::29]:
        model, xy = _nadir_view(textured, atlas, patch, px=px)
        if np.hypot(*xy) < 1.0 or textured.appearance.sand_weight(xy[None])[0] > 0:
            continue
        us, vs = np.meshgrid(np.arange(px, dtype=float), np.arange(px, dtype=float))
        o, d = model.unproject(np.stack([us.ravel(), vs.ravel()], 1))
        hits = textured.cast(o, d)
        ground = (hits.material == MAT_TERRAIN) & (textured.appearance.sand_weight(hits.points[:, :2]) == 0)
        if ground.mean() < 0.85:
            continue  # a pebble or rock in the way: try another patch
        # expected: the source contrast at the hit, through the patch's placement (the core holds this patch only)
        a_rc = atlas.atlas_rc(hits.points[:, :2]) - np.array([patch.atlas_row0, patch.atlas_col0])
        a_rc = np.mod(a_rc + atlas.levels[0].shape[0] / 2, atlas.levels[0].shape[0]) - atlas.levels[0].shape[0] / 2
        assert np.all((a_rc[ground] > OVERLAP_PX - 0.5) & (a_rc[ground] < PATCH_PX - OVERLAP_PX - 0.5))
        src = patch_pixels(contrast[patch.source], patch)
        i0 = np.clip(np.floor(a_rc[:, 0]).astype(int), 0, PATCH_PX - 2)
        j0 = np.clip(np.floor(a_rc[:, 1]).astype(int), 0, PATCH_PX - 2)
        fr, fc = a_rc[:, 0] - i0, a_rc[:, 1] - j0
        want = ((src[i0, j0] * (1 - fc) + src[i0, j0 + 1] * fc) * (1 - fr)
                + (src[i0 + 1, j0] * (1 - fc) + src[i0 + 1, j0 + 1] * fc) * fr)
        got = render_radiance(textured, model, px, px, supersample=2, shadows=False).ravel()
        procedural = render_radiance(plain, model, px, px, supersample=2, shadows=False).ravel()
        results.append((_ncc(got[ground], want[ground]), _ncc(procedural[ground], want[ground]),
                        got[ground].std() / got[ground].mean(), want[ground].std()))
        if len(results) == 3:
            break
    assert len(results) == 3, "no clear patch of ground found"
    for ncc_tex, ncc_proc, rel_std, src_std in results:
        assert ncc_tex > 0.9, results  # the texture is the source crop, up to the box filter and smooth shading
        assert abs(ncc_proc) < 0.3, results  # the procedural grain has nothing to do with it
        assert 0.6 < rel_std / src_std < 1.4, results  # the real contrast survives (base albedo x (1 + T))


def test_synth_with_texture_validates_records_the_sources_and_repeats_bytes(tmp_path, monkeypatch):
    import shlex
    import shutil

    folder = tmp_path / "real pics é"  # a path a shell would split: the record's command quotes it
    shutil.copytree(real("05_"), folder)
    outs = []
    for name in ("a", "b"):
        monkeypatch.setattr(sim_build, "_SCENES", {})  # rebuild the scene and its atlas from scratch each time
        r = runner.invoke(app, ["synth", "--seed", "1", "--runs", "s1-straight", "--texture-from", str(folder),
                                "-o", str(tmp_path / name), "--json"], env=SMALL_ENV)
        assert r.exit_code == 0, r.stderr
        outs.append(json.loads(r.stdout)["runs"][0])
    assert outs[0]["sha256"] == outs[1]["sha256"]
    dl = read_downlink(tmp_path / "a" / "paper-s1-straight.mcap")
    assert len(dl.images) == 12 and len(dl.targets) == 3
    rec = json.loads((tmp_path / "a" / "paper-s1-straight.sim.json").read_text())
    from scipctl.io.provenance import sha256_file

    assert {f["file"]: f["sha256"] for f in rec["texture"]["files"]} == {
        p.name: sha256_file(p) for p in sorted(folder.glob("*.IMG"))}
    argv = shlex.split(rec["written_by"]["regenerate"])
    assert argv[argv.index("--texture-from") + 1] == str(folder)
    # the texture changes the pixels, not the geometry: same poses and marks as without it
    monkeypatch.setattr(sim_build, "_SCENES", {})
    r = runner.invoke(app, ["synth", "--seed", "1", "--runs", "s1-straight", "-o", str(tmp_path / "plain")], env=SMALL_ENV)
    assert r.exit_code == 0, r.stderr
    plain = read_downlink(tmp_path / "plain" / "paper-s1-straight.mcap")
    assert [im.product_id for im in plain.images] == [im.product_id for im in dl.images]
    assert all(np.array_equal(a.pose.T_site_rover.t, b.pose.T_site_rover.t) for a, b in zip(plain.images, dl.images))
    assert any(not np.array_equal(a.pixels, b.pixels) for a, b in zip(plain.images, dl.images))


@pytest.mark.parametrize("setup,args,field", [
    ("empty", [], "--texture-from"),
    ("text", [], "--texture-from"),
    ("missing", [], "--texture-from"),
    ("empty", ["--texture-crop", "0.5,0.2,0.4,0.9"], "--texture-crop"),
    (None, ["--texture-crop", "0,0,1,1"], "--texture-crop"),
])
def test_bad_texture_input_exit_2_nothing_written(tmp_path, setup, args, field):
    src = tmp_path / "src"
    if setup in ("empty", "text"):
        src.mkdir()
    if setup == "text":
        (src / "notes.txt").write_text("no pictures here\n")
        (src / "tiny.png").write_bytes(b"\x89PNG\r\n\x1a\nbroken")
    extra = ["--texture-from", str(src)] if setup is not None else []
    r = runner.invoke(app, ["synth", "-o", str(tmp_path / "o"), *extra, *args], env=SMALL_ENV)
    assert r.exit_code == 2 and field in r.stderr and "Traceback" not in r.stderr, r.stderr
    assert len(r.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "o").exists()
