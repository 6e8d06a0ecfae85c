"""scipctl.sim.image_effects: blur against scipy, the companding tables, JPEG and tone curves on exact cases."""

import numpy as np
import pytest
import scipy.ndimage as ndi

from scipctl.sim import image_effects as ie


def _random_u8(shape=(48, 64), seed=3):
    return (np.random.default_rng(seed).random(shape) * 256).astype(np.uint8)


def _random_u16(shape=(48, 64), seed=4):
    v = (np.random.default_rng(seed).random(shape) * 4096).astype(np.uint16)
    return (v << 4) | (v >> 8)  # 12-bit data bit-replicated, as render.expose writes


@pytest.mark.parametrize("sigma_px", [0.5, 0.8, 1.5, 3.0])
def test_blur_is_scipys_gaussian_to_the_rounding(sigma_px):
    # scipy's gaussian_filter ('reflect' = OpenCV's BORDER_REFLECT, truncated at 4 sigma as OpenCV's float kernels
    # are) is an independent implementation of the same sampled, normalised kernel: the values agree to ~1e-15,
    # so after rounding to whole codes they are equal (a tie at exactly .5 would differ by one code: bound 1).
    img = _random_u8()
    ours = ie.optical_blur(img, sigma_px).astype(int)
    ref = np.rint(np.clip(ndi.gaussian_filter(img / 255.0, sigma_px, mode="reflect", truncate=4.0), 0, 1) * 255)
    assert ours.dtype == int and np.abs(ours - ref).max() <= 1
    img16 = _random_u16()
    out16 = ie.optical_blur(img16, sigma_px)
    assert out16.dtype == np.uint16
    ref16 = np.rint(np.clip(ndi.gaussian_filter((img16 >> 4) / 4095.0, sigma_px, mode="reflect", truncate=4.0), 0, 1)
                    * 4095)
    assert np.abs((out16 >> 4).astype(int) - ref16).max() <= 1
    assert np.array_equal(out16 & 0xF, out16 >> 12)  # still bit-replicated


def test_blur_keeps_a_flat_image_and_its_mean():
    flat = np.full((20, 30), 117, np.uint8)
    assert np.array_equal(ie.optical_blur(flat, 1.2), flat)
    img = _random_u8((64, 64))
    # the kernel sums to 1 and the border is mirrored, so only rounding (<= 0.5 code per pixel) and the mirror's
    # re-weighting of the border pixels move the mean (0.004 codes on this image, OpenCV 5.0)
    assert abs(ie.optical_blur(img, 0.8).mean() - img.mean()) < 1.0


def test_companding_tables_round_trip():
    compand, expand = ie.sqrt_compand_lut(), ie.sqrt_expand_lut()
    v = np.arange(4096)
    used = np.unique(compand)
    assert compand[0] == 0 and compand[4095] == 255 and np.all(np.diff(compand.astype(int)) >= 0)
    assert np.array_equal(compand[expand[used]], used)  # each code expands into its own bin
    # a value comes back within half its bin: the bin of code c is ~2 * 4095 * c / 255^2 wide (<= 32 at the top)
    err = np.abs(expand[compand].astype(int) - v)
    half_bin = 4095 * (2 * compand.astype(float) + 1) / 255**2 / 2 + 0.5
    assert np.all(err <= np.ceil(half_bin))


def test_jpeg_round_trip_on_a_smooth_ramp():
    ramp = np.tile(np.linspace(20, 230, 128), (64, 1)).astype(np.uint8)
    out = ie.companded_jpeg(ramp, 100)
    assert out.dtype == np.uint8 and out.shape == ramp.shape
    # a ramp is nearly all DC and first AC terms: quality 100 and 75 both kept it to 1 code (OpenCV 5.0);
    # the bound for 75 allows the coarser quantisation table of another encoder build
    assert np.abs(out.astype(int) - ramp).max() <= 1
    assert np.abs(ie.companded_jpeg(ramp, 75).astype(int) - ramp).max() <= 3
    flat16 = np.full((32, 32), (2000 << 4) | (2000 >> 8), np.uint16)
    out16 = ie.companded_jpeg(flat16, 90)
    code = ie.sqrt_compand_lut()[2000]
    assert out16.dtype == np.uint16 and np.all(out16 >> 4 == ie.sqrt_expand_lut()[code])


def test_jpeg_changes_a_textured_image():
    img = _random_u8()
    out = ie.companded_jpeg(img, 75)
    assert out.shape == img.shape and not np.array_equal(out, img)


def test_tone_curve():
    img, img16 = _random_u8(), _random_u16()
    assert np.array_equal(ie.tone_curve(img, 1.0), img) and np.array_equal(ie.tone_curve(img16, 1.0), img16)
    mid = np.array([[0, 255, 128]], np.uint8)
    assert ie.tone_curve(mid, 2.0).tolist() == [[0, 255, round(255 * (128 / 255) ** 2)]]
    assert np.all(ie.tone_curve(img, 0.8).astype(int) >= img)  # gamma < 1 brightens every value


def test_effect_spec_applies_per_eye_in_order():
    img = _random_u8()
    spec = ie.EffectSpec(blur_sigma_px=0.8, gamma_left=0.8, gamma_right=1.25, jpeg_quality=75)
    left = spec.apply(img, "left")
    assert np.array_equal(left, ie.companded_jpeg(ie.tone_curve(ie.optical_blur(img, 0.8), 0.8), 75))
    assert np.array_equal(spec.apply(img, "right"),
                          ie.companded_jpeg(ie.tone_curve(ie.optical_blur(img, 0.8), 1.25), 75))
    assert np.array_equal(ie.EffectSpec().apply(img, "left"), img)
    assert spec.to_dict() == {"blur_sigma_px": 0.8, "gamma_left": 0.8, "gamma_right": 1.25, "jpeg_quality": 75}
    with pytest.raises(ValueError, match="eye"):
        spec.apply(img, "centre")


@pytest.mark.parametrize("call", [
    lambda: ie.optical_blur(np.zeros((4, 4), np.float32), 1.0),
    lambda: ie.optical_blur(np.zeros((4, 4, 3), np.uint8), 1.0),
    lambda: ie.optical_blur(np.zeros((4, 4), np.uint8), 0.0),
    lambda: ie.companded_jpeg(np.zeros((8, 8), np.uint8), 0),
    lambda: ie.tone_curve(np.zeros((4, 4), np.uint8), float("nan")),
])
def test_bad_arguments_are_refused(call):
    with pytest.raises(ValueError):
        call()


def test_degrade_downlinks_script_changes_only_the_pixels(tmp_path):
    """docs/scripts/degrade_downlinks.py on a bundled sol: every image is EffectSpec.apply of the original, everything
    else read back equal, and the .sim.json copy records the variant and its source."""
    import hashlib
    import json
    import shutil
    from pathlib import Path

    from scipctl.io.downlink import read_downlink
    from tests import doc_scripts

    root = Path(__file__).resolve().parents[2]
    mod = doc_scripts.load("degrade_downlinks")
    src_dir = tmp_path / "src" / "sol"
    src_dir.mkdir(parents=True)
    for name in ("paper-s1-straight.mcap", "paper-s1-straight.sim.json"):
        shutil.copy(root / "sample_sols/mcap" / name, src_dir / name)
    src = src_dir / "paper-s1-straight.mcap"
    dst = tmp_path / "out" / "sol" / "paper-s1-straight.mcap"
    mod.degrade(src, dst, "all")
    a, b = read_downlink(src), read_downlink(dst)
    effect = ie.EffectSpec(**mod.VARIANTS["all"])
    assert [i.product_id for i in a.images] == [i.product_id for i in b.images]
    for x, y in zip(a.images, b.images):
        assert np.array_equal(y.pixels, effect.apply(x.pixels, x.eye))
        assert repr(x.pose) == repr(y.pose) and repr(x.camera_model) == repr(y.camera_model) and x.mast == y.mast
    assert repr(a.targets) == repr(b.targets) and repr(a.truth_targets) == repr(b.truth_targets)
    rec = json.loads(dst.with_name("paper-s1-straight.sim.json").read_text())
    assert rec["image_effects"]["variant"] == "all" and rec["image_effects"]["spec"] == effect.to_dict()
    assert rec["image_effects"]["source_sha256"] == hashlib.sha256(src.read_bytes()).hexdigest()
