"""scipctl: ground tool for Single Cycle Instrument Placement (SCIP)."""

import os

__version__ = "0.1.0"

# One BLAS thread unless the caller chose otherwise (effective only if numpy is not imported yet, as when the
# `scipctl` command starts). scipctl's matrix products are small or memory-bound ((N, 3) @ (3, 3)); OpenBLAS's
# extra threads gained nothing on them and their busy-waiting took a core from OpenCV's and Open3D's own threads:
# on the 2-core build machine the handoff of one downlink used ~20 % less CPU time with one BLAS thread
# (docs/handoff.md, "Speed").
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
