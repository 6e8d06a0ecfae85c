"""Run Debian's mrcal (an independent implementation) through /usr/bin/python3 in a subprocess."""

import json
import os
import subprocess
import tempfile
from pathlib import Path

import numpy as np

MRCAL_PYTHON = "/usr/bin/python3"


def mrcal_available() -> bool:
    if not os.path.exists(MRCAL_PYTHON):
        return False
    r = subprocess.run([MRCAL_PYTHON, "-c", "import mrcal"], capture_output=True)
    return r.returncode == 0


_SCRIPT = r"""
import sys, json, numpy as np, mrcal
cmod_path, pts_path, out_path = sys.argv[1:4]
m = mrcal.cameramodel(cmod_path)
p = np.load(pts_path)
pc = mrcal.transform_point_Rt(m.extrinsics_Rt_fromref(), p)
q = mrcal.project(pc, *m.intrinsics())
np.save(out_path, q)
print(json.dumps({"lensmodel": m.intrinsics()[0]}))
"""


def cmod_text_for_mrcal(model, width, height) -> str:
    """Minimal JPL cmod text that mrcal's reader takes (CAHVORE always as type 3 with its linearity)."""
    f = lambda v: " ".join(repr(float(x)) for x in v)  # noqa: E731
    lines = [f"Dimensions = {width} {height}"]
    if model.kind == "CAHV":
        lines.append("Model = CAHV = perspective, linear")
    elif model.kind == "CAHVOR":
        lines.append("Model = CAHVOR = perspective, distortion")
    else:
        lines.append(f"Model = CAHVORE3,{float(model.linearity)!r} = general")
    for name in ("C", "A", "H", "V", "O", "R", "E"):
        val = getattr(model, name)
        if val is not None:
            lines.append(f"{name} = {f(val)}")
    return "\n".join(lines) + "\n"


def mrcal_project(model, points, width=1024, height=1024, cmod_text=None, suffix=".cahvor"):
    """Project ``points`` (N, 3) (the model's frame) with mrcal; returns ((N, 2), lensmodel name)."""
    with tempfile.TemporaryDirectory() as td:
        td = Path(td)
        (td / f"m{suffix}").write_text(cmod_text or cmod_text_for_mrcal(model, width, height))
        np.save(td / "p.npy", np.asarray(points, float))
        r = subprocess.run(
            [MRCAL_PYTHON, "-c", _SCRIPT, str(td / f"m{suffix}"), str(td / "p.npy"), str(td / "q.npy")],
            capture_output=True, text=True,
        )
        if r.returncode != 0:
            raise RuntimeError(f"mrcal failed: {r.stderr.strip()[-2000:]}")
        return np.load(td / "q.npy"), json.loads(r.stdout.strip().splitlines()[-1])["lensmodel"]
