#!/usr/bin/env bash
# The test suite on the locked stack with one thing changed (docs/stereo-and-tracking.md, "Reproducibility"):
#
#   bash docs/scripts/other_builds.sh opencv4    # OpenCV 4.x in place of the locked 5.x: a venv made from the lock,
#                                                 # then opencv-python-headless 4.14.0.94 over it (VENV=/tmp/scipctl-cv4)
#   bash docs/scripts/other_builds.sh threads1   # the project's .venv, every thread pool at one thread
#                                                 # (OMP_NUM_THREADS=1 for Open3D/OpenMP, OPENCV_FOR_THREADS_NUM=1)
#
# Extra arguments go to pytest (e.g. tests/pipeline). Run .ci/setup first.
set -euo pipefail
cd "$(dirname "$0")/../.."
what=${1:?usage: other_builds.sh opencv4|threads1 [pytest args]}
shift
case "$what" in
  opencv4)
    VENV=${VENV:-/tmp/scipctl-cv4}
    [ -x "$VENV/bin/python" ] || python3 -m venv "$VENV"
    "$VENV/bin/python" -m pip install -q --require-hashes --no-deps -r .ci/requirements.lock
    "$VENV/bin/python" -m pip install -q --no-deps opencv-python-headless==4.14.0.94
    "$VENV/bin/python" -m pip install -q --no-deps --no-build-isolation -e .
    "$VENV/bin/python" -c "import cv2; assert cv2.__version__.startswith('4.'), cv2.__version__; print('OpenCV', cv2.__version__)"
    "$VENV/bin/python" -m pytest -q "$@"
    ;;
  threads1)
    OMP_NUM_THREADS=1 OPENCV_FOR_THREADS_NUM=1 .venv/bin/python -m pytest -q "$@"
    ;;
  *) echo "usage: other_builds.sh opencv4|threads1 [pytest args]" >&2; exit 2 ;;
esac
