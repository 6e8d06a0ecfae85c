"""The numbers behind ``tests/pipeline/test_handoff_broken.py``: ``scip`` on each deliberately broken copy of the
sample sol (issue #14 item 6), the same breaks and code path as the tests, as a markdown table.

    PYTHONPATH=. python docs/scripts/scip_broken_report.py [CASE ...]      (from the repository root; default: all)

Per case and target: scip's p_success, GO, error (px), the navcam its answer used, the highest probability of a
candidate more than 4 px off, whether the geometry veto fired, and the CPU seconds of the case (it reuses what
the break leaves unchanged, as the tests do).
"""

from __future__ import annotations

import resource
import sys

from scipctl.io.downlink import read_downlink
from scipctl.pipeline.handoff import build_setup
from tests.pipeline import broken_downlinks as B
from tests.pipeline import test_handoff_broken as T


def cpu_s() -> float:
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def main(argv):
    dl = read_downlink(T.SAMPLE)
    base = build_setup(dl)
    sol = (dl, base)
    ids = [t.id for t in dl.targets]
    kind = {t.id: t.kind for t in dl.targets}
    prods = B.pair_of(dl, base.hazcam) + B.pair_of(dl, base.near) + B.pair_of(dl, base.far)
    flat = [t for t in ids if kind[t] == "flat"]
    cases = {
        "washed-out far x4": lambda: B.washed_out_copy(dl, B.pair_of(dl, base.far), 4.0),
        "washed-out far saturated": lambda: B.washed_out_copy(dl, B.pair_of(dl, base.far), 1e3),
        "mast tilt +3 deg near": lambda: B.mast_error_copy(dl, B.pair_of(dl, base.near), dtilt_rad=3 * B.DEG),
        "mast tilt +3 deg far": lambda: B.mast_error_copy(dl, B.pair_of(dl, base.far), dtilt_rad=3 * B.DEG),
        "occluder 40 cm in front": lambda: B.occluded_copy(dl, base.hazcam, ids, T.FAR_OCCLUDER[1],
                                                           T.FAR_OCCLUDER[0], seed=7),
        "occluder 5 cm in front": lambda: B.occluded_copy(dl, base.hazcam, ids, T.NEAR_OCCLUDER[1],
                                                          T.NEAR_OCCLUDER[0], seed=7),
        "textureless sand (flat target)": lambda: B.textureless_copy(
            dl, B.sim_scene(T.SAMPLE.with_suffix(".sim.json")), prods, flat, T.SAND_RADIUS_M, seed=5),
    }
    if argv:
        cases = {k: v for k, v in cases.items() if k in argv}
    print("| case | target (kind) | scip p_success | GO | error px | navcam | best candidate > 4 px off: p | veto |")
    print("|---|---|---|---|---|---|---|---|")
    for name, make in cases.items():
        t0 = cpu_s()
        recs, _ = T.run_scip(make(), sol)
        for tid, r in recs.items():
            wrong = [p for _, e, p, _ in T.candidates(r) if e > T.SUCCESS_PX]
            print(f"| {name} | {tid} ({kind[tid]}) | {r.p_success:.3f} | {'GO' if r.go else 'NO-GO'} | "
                  f"{r.error_px:.1f} | {r.navcam} | {max(wrong) if wrong else float('nan'):.3f} | "
                  f"{'yes' if 'geometry_veto' in r.diagnostics else ''} |", flush=True)
        print(f"<!-- {name}: {cpu_s() - t0:.1f} CPU s -->", flush=True)


if __name__ == "__main__":
    main(sys.argv[1:])
