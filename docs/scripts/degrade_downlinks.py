"""Copies of rendered downlinks with image formation the renderer does not do (``scipctl.sim.image_effects``).

    python docs/scripts/degrade_downlinks.py SRC_ROOT OUT_ROOT VARIANT

Every ``SRC_ROOT/<name>.mcap`` and ``SRC_ROOT/<dir>/<name>.mcap`` (as ``scipctl synth`` writes them, the ``.sim.json`` beside) is read,
each image's pixels are changed by the variant's :class:`~scipctl.sim.image_effects.EffectSpec`, and the
downlink is written to the same place under ``OUT_ROOT`` with everything else as it was (poses, models, marks,
truth). The ``.sim.json`` is copied with an ``image_effects`` entry (the variant, its settings, the source's
SHA-256), so ``scipctl trust-evidence`` and ``scipctl campaign`` see the same family and targets.

VARIANT: ``blur`` (Gaussian PSF sigma 0.8 px), ``jpeg`` (12 -> 8-bit square-root companding, JPEG quality 75),
``gamma`` (left eye gamma 0.8, right eye 1.25), ``all`` (the three, in that order); ``aug`` (blur 0.6 px, gamma
0.85 / 1.18, JPEG 60: a different setting, for training data); ``jpeg100`` (JPEG quality 100: a control). Session 25, docs/handoff.md
"Image formation the renderer does not do".
"""

from __future__ import annotations

import argparse
import json
from dataclasses import replace
from pathlib import Path

VARIANTS = {
    "blur": dict(blur_sigma_px=0.8),
    "jpeg": dict(jpeg_quality=75),
    "gamma": dict(gamma_left=0.8, gamma_right=1.25),
    "all": dict(blur_sigma_px=0.8, gamma_left=0.8, gamma_right=1.25, jpeg_quality=75),
    # another setting of the same three, for training data (so that a test on the four above is not of the
    # setting a model was fitted with)
    "aug": dict(blur_sigma_px=0.6, gamma_left=0.85, gamma_right=1.18, jpeg_quality=60),
    # a control: the least change of the same kind (pixels move by a code or two), to see how much an answer
    # moves for nothing
    "jpeg100": dict(jpeg_quality=100),
}


def degrade(src: Path, dst: Path, variant: str) -> None:
    from scipctl.io.atomic import atomic_write_text
    from scipctl.io.downlink import read_downlink, write_downlink
    from scipctl.io.images import encode_png
    from scipctl.sim.image_effects import EffectSpec

    spec = EffectSpec(**VARIANTS[variant])
    dl = read_downlink(src)
    source_sha256 = dl.source_sha256  # of the file as read
    dl.images = [replace(im, png=encode_png(spec.apply(im.pixels, im.eye)), _pixels=None) for im in dl.images]
    dst.parent.mkdir(parents=True, exist_ok=True)
    write_downlink(dl, dst)
    sim = src.with_name(src.name[: -len(".mcap")] + ".sim.json")
    if sim.exists():
        rec = json.loads(sim.read_text())
        rec["image_effects"] = {"variant": variant, "spec": spec.to_dict(),
                                "source": str(src), "source_sha256": source_sha256}
        atomic_write_text(dst.with_name(sim.name), json.dumps(rec, indent=1))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("src_root", type=Path)
    ap.add_argument("out_root", type=Path)
    ap.add_argument("variant", choices=sorted(VARIANTS))
    a = ap.parse_args()
    for src in sorted(a.src_root.glob("*.mcap")) + sorted(a.src_root.glob("*/*.mcap")):
        dst = a.out_root / src.relative_to(a.src_root)
        if not dst.exists():
            degrade(src, dst, a.variant)
            print(dst, flush=True)


if __name__ == "__main__":
    main()
