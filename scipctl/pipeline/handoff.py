"""Run the navcam -> hazcam handoff methods on a downlink and score them against marks.

Finds the hazcam pair, the near navcam pair (same rover position) and the far
navcam pair (the latest earlier position with navcams) in a downlink, builds
one :class:`~scipctl.core.handoff.HandoffCase` for each (shared products are
computed once), and runs every method on every marked target.
"""

from __future__ import annotations

import math
import pickle
import weakref
from dataclasses import dataclass, field
from typing import Callable, Optional

import numpy as np

from ..core.handoff import ALL_METHODS, PAPER_METHODS, HandoffCase, HandoffParams, Method, StereoView, run_method
from ..core.handoff.evidence import CANDIDATE_METHODS
from ..core.handoff.scip import SCIP, scip_from_results
from ..core.kinematics import T_roverB_roverA
from ..core.transforms import RigidTransform
from ..model import Downlink, ImageProduct, InputError

REFINED = {Method.REFINED_KINEMATIC, Method.REFINED_GEOMETRIC}


@dataclass
class HandoffSetup:
    hazcam: ImageProduct
    near: Optional[ImageProduct]
    far: Optional[ImageProduct]
    cases: dict = field(default_factory=dict)  # "near"/"far" -> HandoffCase


def _view(dl: Downlink, left: ImageProduct, min_range_m: float, max_range_m: float, downsample: int = 1) -> StereoView:
    right = dl.stereo_pair(left)
    if right is None:
        raise InputError(left.product_id, "eye", f"no right-eye {left.camera} image at position {left.position}")
    return StereoView(
        left_img=left.pixels_float(), right_img=right.pixels_float(),
        left_model=left.camera_model, right_model=right.camera_model,
        width=left.width, height=left.height, min_range_m=min_range_m, max_range_m=max_range_m,
        dense_downsample=downsample,
    )


def find_products(dl: Downlink, hazcam: Optional[str] = None, near: Optional[str] = None,
                  far: Optional[str] = None) -> tuple:
    """(hazcam left, near navcam left or None, far navcam left or None) products. A product named by the caller
    must be a left image of the right camera, the near navcam at the hazcam's stop and the far one at another
    (else :class:`InputError` naming the product: a pancam or the hazcam itself given as a navcam was answered)."""
    def left_of(pid, camera):
        p = dl.product(pid)
        if p.camera != camera:
            raise InputError(pid, "camera", f"expected a left {camera} product, got a {p.camera} image")
        if p.eye != "left":
            raise InputError(pid, "eye", f"expected a left-eye {camera} product, got {p.eye}")
        return p

    if hazcam:
        haz = left_of(hazcam, "hazcam")
    else:
        hz = sorted((im for im in dl.images if im.camera == "hazcam" and im.eye == "left"), key=lambda i: i.time_s)
        if not hz:
            raise InputError(dl.source or "downlink", "images", "no left hazcam image to hand off to")
        haz = hz[-1]
    navs = sorted((im for im in dl.images if im.camera == "navcam" and im.eye == "left"), key=lambda i: i.time_s)
    if near:
        nr = left_of(near, "navcam")
        if nr.position != haz.position:
            raise InputError(near, "position", f"the near navcam must be at the hazcam's stop {haz.position}, "
                             f"this one is at {nr.position} (a navcam at another stop is a far one)")
    else:
        same = [n for n in navs if n.position == haz.position]
        nr = min(same, key=lambda n: abs(n.time_s - haz.time_s)) if same else None
    if far:
        fr = left_of(far, "navcam")
        if fr.position == haz.position:
            raise InputError(far, "position", f"the far navcam must be at another stop than the hazcam's "
                             f"{haz.position} (a navcam at that stop is the near one)")
    else:
        earlier = [n for n in navs if n.position != haz.position and n.time_s < haz.time_s]
        fr = earlier[-1] if earlier else None
    return haz, nr, fr


# id(downlink) -> its shared views and cases (build_setup(..., shared=True)); emptied when the downlink is freed
_SHARED: dict = {}


def _shared_store(dl: Downlink) -> dict:
    key = id(dl)
    if key not in _SHARED:
        _SHARED[key] = {}
        weakref.finalize(dl, _SHARED.pop, key, None)
    return _SHARED[key]


def build_setup(dl: Downlink, params: Optional[HandoffParams] = None, hazcam=None, near=None, far=None,
                shared: bool = False) -> HandoffSetup:
    """The handoff cases of ``dl``; ``params`` without a trust model for ``scip`` get the packaged one.

    ``shared``: the cases (with what they compute once: dense stereo, clouds, registration, point stereo,
    method steps) are those of an earlier shared setup of the same downlink object with the same products
    and equal ``params``, if any, so that the chain's hazcam handoffs reuse what the handoff computed.
    Nothing changes in the answers (each of those is a function of the images, models and params alone);
    without ``shared``, every product is computed afresh (benchmarks and tests that time or isolate them).
    """
    params = params or HandoffParams()
    if params.scip.model is None:
        from dataclasses import replace

        from ..io.trust_model import load_packaged_trust_model

        params = replace(params, scip=replace(params.scip, model=load_packaged_trust_model()))
    haz, nr, fr = find_products(dl, hazcam, near, far)
    ds = params.dense_downsample
    # this setup's views and cases (the near and far cases share the hazcam view), or the downlink's shared ones
    store = _shared_store(dl) if shared else {}
    pkey = pickle.dumps(params) if shared else None  # equal params, equal bytes (a differing pickle: not shared)

    def view(prod, lo, hi):
        k = ("view", prod.product_id, lo, hi, ds)
        if k not in store:
            store[k] = _view(dl, prod, lo, hi, ds)
        return store[k]

    def case(label, nav, T_roverhaz_rovernav):
        k = ("case", label, nav.product_id, haz.product_id, pkey)
        if k not in store:
            store[k] = HandoffCase(label, view(nav, 0.8, 30.0), view(haz, 0.3, 6.0), T_roverhaz_rovernav, params)
        return store[k]

    view(haz, 0.3, 6.0)  # ranges: hazcam sees 0.3-6 m, navcams 0.8-30 m (an error here before any navcam's)
    setup = HandoffSetup(haz, nr, fr)
    if nr is not None:
        T_roverhaz_rovernav = T_roverB_roverA(haz.pose, nr.pose) if nr.position != haz.position else RigidTransform.identity()
        setup.cases["near"] = case("near", nr, T_roverhaz_rovernav)
    if fr is not None:
        setup.cases["far"] = case("far", fr, T_roverB_roverA(haz.pose, fr.pose))
    return setup


@dataclass
class HandoffRecord:
    """One method's navcam -> hazcam handoff of one target (a ``results`` entry of ``handoff.json``).

    ``source_uv``: the navcam-left pixel handed off (None: the target is not marked there); ``predicted_uv``:
    the method's hazcam-left pixel (None: no answer); ``truth_uv``: the hazcam mark (None: not marked);
    ``error_px`` their distance and ``success`` whether it is within the success threshold.
    """

    downlink: str
    target: str
    method: str
    navcam: str  # "near" | "far"
    source_product: str
    source_uv: Optional[list]
    predicted_uv: Optional[list]
    truth_uv: Optional[list]
    error_px: Optional[float]
    success: Optional[bool]
    ok: bool
    reason: str
    diagnostics: dict
    seconds: float
    p_success: Optional[float] = None  # scip's trust model's P(error <= success_px) for this answer (None: not scored)
    go: Optional[bool] = None  # p_success >= the GO threshold (None: not scored)

    def to_dict(self) -> dict:
        return dict(self.__dict__)

    @classmethod
    def from_dict(cls, d, product: str = "handoff.json", index: Optional[int] = None) -> "HandoffRecord":
        """A record as read back from ``handoff.json`` (``to_dict``'s inverse); :class:`InputError` naming
        ``product`` and the field (``results[index].field``) on a missing or ill-typed value."""
        from ..jsonutil import RecordReader

        r = RecordReader(d, product, "" if index is None else f"results[{index}].", "handoff record")
        out = cls(
            downlink=r.text("downlink", required=True, nullable=False),
            target=r.text("target", required=True, nullable=False),
            method=r.text("method", required=True, nullable=False),
            navcam=r.text("navcam", required=True, nullable=False),
            source_product=r.text("source_product", required=True, nullable=False),
            source_uv=r.vector("source_uv", 2, required=True, kind=list),
            predicted_uv=r.vector("predicted_uv", 2, required=True, kind=list),
            truth_uv=r.vector("truth_uv", 2, required=True, kind=list),
            error_px=r.number("error_px", required=True), success=r.flag("success", required=True),
            ok=r.flag("ok", required=True, nullable=False), reason=r.text("reason", required=True, nullable=False),
            diagnostics=r.mapping("diagnostics", required=True, nullable=False),
            seconds=r.number("seconds", required=True, nullable=False),
            p_success=r.number("p_success"), go=r.flag("go"))  # absent in files written before scip's trust
        return out


def handoff_records_from_doc(doc, product: str = "handoff.json") -> list:
    """The :class:`HandoffRecord` results of a ``handoff.json`` document (``[]`` when it has none)."""
    if not isinstance(doc, dict) or not doc.get("results"):
        return []
    results = doc["results"]
    if not isinstance(results, list):
        raise InputError(product, "results", "expected a list of handoff records")
    return [HandoffRecord.from_dict(r, product, i) for i, r in enumerate(results)]


def table1_rows_from_doc(doc, product: str = "handoff.json") -> Optional[list]:
    """The ``table1`` rows of a ``handoff.json`` document, checked (None when it has none): each row a JSON object
    with a known method name, a navcam, whole ``cases``/``answered`` and a ``success_rate`` and ``all.mean_px`` that
    are numbers (or null). :class:`InputError` naming the product and the field otherwise: these rows choose the
    handoff method that the uplink sequence commands, so nothing unchecked may reach it. Statistics written before
    their keys carried the unit (``mean``, ``std``, ``min``, ``max``) are read as ``mean_px`` ... ``max_px``."""
    from ..jsonutil import RecordReader

    if not isinstance(doc, dict) or doc.get("table1") is None:
        return None
    rows = doc["table1"]
    if not isinstance(rows, list):
        raise InputError(product, "table1", f"expected a list of rows, got {type(rows).__name__}")
    rows = [_with_px_keys(row) for row in rows]
    for i, row in enumerate(rows):
        r = RecordReader(row, product, f"table1[{i}].", "table1 row")
        method = r.text("method", required=True, nullable=False)
        if method not in ALL_METHODS:
            r.bad("method", f"unknown method {method!r}")
        r.text("navcam", required=True, nullable=False)
        r.integer("cases", required=True, nullable=False)
        r.integer("answered")
        r.number("success_rate")
        stats = r.mapping("all")
        if stats is not None:
            RecordReader(stats, product, f"table1[{i}].all.", "statistics").number("mean_px")
    return rows


def _with_px_keys(row):
    """A Table-1 row with its statistics' keys as :data:`STATS_KEYS` (a row of an older ``handoff.json`` has
    ``mean`` ... ``max``); anything else as it is (the checks name it)."""
    if not isinstance(row, dict):
        return row
    out = dict(row)
    for part in ("all", "successes", "failures"):
        s = out.get(part)
        if isinstance(s, dict) and any(k in s for k in _STATS_KEYS_BEFORE):
            out[part] = {_STATS_KEYS_BEFORE.get(k, k): v for k, v in s.items()}
    return out


def run_targets(
    dl: Downlink,
    setup: HandoffSetup,
    targets: list,  # list of (target_id, {"near": uv or None, "far": uv or None}, truth_uv or None)
    methods=ALL_METHODS,
    navcams=("near", "far"),
    success_px: float = 4.0,
    progress: Optional[Callable[[str], None]] = None,
    downlink_name: str = "",
    only: Optional[set] = None,
    scip_outcomes: Optional[dict] = None,
) -> list:
    """Run ``methods`` x ``navcams`` (restricted to the (method, navcam) pairs in ``only``, if given) on ``targets``.

    Records come in the order target, navcam, method; ``scip`` (one record per target, ``navcam`` the view its
    answer came from: ``near``, ``far`` or ``both``) after the target's others. With ``scip`` the candidate
    methods run on every navcam in ``navcams`` (reported only when asked for), every record of a candidate
    method gets its ``p_success`` and ``go``, and ``scip_outcomes`` (if given) receives target id ->
    :class:`~scipctl.core.handoff.scip.ScipOutcome`. When mesh registration is
    asked for, the registrations are started first in a worker thread (ICP
    runs outside Python's lock; the far one first, the longest) and the
    mesh-registration records are computed after every other method, so that
    the other methods run meanwhile.
    """
    from concurrent.futures import ThreadPoolExecutor

    def wanted(m, nc):
        return only is None or (m, nc) in only

    with_scip = SCIP in methods
    run_names = [m for m in methods if m != SCIP] + [m for m in CANDIDATE_METHODS if with_scip and m not in methods]

    def needed(m, nc):
        return (with_scip and m in CANDIDATE_METHODS) or wanted(m, nc)

    mesh = "mesh-registration"
    cases = {nc: setup.cases[nc] for nc in navcams if nc in setup.cases}
    reg_cases = [c for nc, c in cases.items()
                 if mesh in run_names and needed(mesh, nc) and any(src.get(nc) is not None for _, src, _ in targets)]
    results = {}
    with ThreadPoolExecutor(max_workers=1) as pool:
        # the far registration first: it is the longest job (a coarser start, a bigger overlap), so the near
        # navcams' dense stereo and the other methods run while it does (docs/handoff.md has the A/B timing)
        for case in sorted(reg_cases, key=lambda c: c.label != "far"):
            case.start_registration(pool)
        for phase in ("others", mesh):
            for target_id, src, truth in targets:
                near_pk = None
                near_case = setup.cases.get("near")
                if (phase == "others" and "far" in navcams and "refined-kinematic" in run_names and near_case is not None
                        and src.get("near") is not None):
                    # the far refined search centre (the paper's), passed to every method of the target
                    near_pk = run_method(near_case, Method.PURE_KINEMATIC, src["near"])
                for nc, case in cases.items():
                    nav_uv = src.get(nc)
                    for m in run_names:
                        if not needed(m, nc) or (m == mesh) != (phase == mesh) or nav_uv is None:
                            continue
                        if progress:
                            progress(f"{downlink_name} {target_id} {m} {nc}")
                        results[(target_id, nc, m)] = run_method(case, m, nav_uv, near_hint=near_pk)
    outcomes = {}
    if with_scip and cases:
        from dataclasses import replace

        p0 = next(iter(cases.values())).params
        sparams = replace(p0, scip=replace(p0.scip, success_px=success_px))
        for target_id, src, _ in targets:
            got = [results[k] for k in results if k[0] == target_id and k[2] in CANDIDATE_METHODS]
            outcomes[target_id] = scip_from_results(cases, {nc: src.get(nc) for nc in cases}, got, sparams)
        if scip_outcomes is not None:
            scip_outcomes.update(outcomes)
    records = []
    for target_id, src, truth in targets:
        out = outcomes.get(target_id)
        for nc, case in cases.items():
            nav_uv = src.get(nc)
            product = setup.near if nc == "near" else setup.far
            for m in methods:
                if m == SCIP or not wanted(m, nc):
                    continue
                if nav_uv is None:
                    records.append(HandoffRecord(downlink_name, target_id, m, nc, product.product_id, None, None,
                                                 truth, None, None if truth is None else False, False,
                                                 "target not marked in this navcam image", {}, 0.0))
                    continue
                res = results[(target_id, nc, m)]
                pred = None if res.uv is None or not np.all(np.isfinite(res.uv)) else [float(x) for x in res.uv]
                err = None
                succ = None
                if truth is not None:
                    if pred is not None:
                        err = float(math.hypot(pred[0] - truth[0], pred[1] - truth[1]))
                        succ = err <= success_px
                    else:
                        succ = False
                p_m = out.p_of(m, nc) if out is not None and pred is not None else None
                go_min = None if out is None else out.result.diagnostics.get("go_min_p")
                records.append(HandoffRecord(downlink_name, target_id, m, nc, product.product_id,
                                             [float(x) for x in nav_uv], pred, truth, err, succ,
                                             bool(res.ok and pred is not None), res.reason, res.diagnostics,
                                             res.seconds, p_m,
                                             None if p_m is None or go_min is None else bool(p_m >= go_min)))
        if out is not None:
            records.append(_scip_record(downlink_name, target_id, src, setup, out, truth, success_px))
    return records


def _scip_record(downlink_name, target_id, src, setup, out, truth, success_px) -> HandoffRecord:
    """The ``scip`` record of one target: ``navcam`` and ``source_product`` of the view its answer used (both
    navcams: ``source_product`` the near one's)."""
    res = out.result
    nc = res.navcam if res.navcam in ("near", "far") else ("near" if src.get("near") is not None else "far")
    product = setup.near if nc == "near" else setup.far
    pred = None if res.uv is None else [float(x) for x in res.uv]
    err = succ = None
    if truth is not None:
        err = None if pred is None else float(math.hypot(pred[0] - truth[0], pred[1] - truth[1]))
        succ = err is not None and err <= success_px
    nav_uv = src.get(nc)
    return HandoffRecord(downlink_name, target_id, SCIP, res.navcam, product.product_id if product else "",
                         None if nav_uv is None else [float(x) for x in nav_uv], pred, truth, err, succ,
                         bool(res.ok and pred is not None), res.reason, res.diagnostics, res.seconds,
                         out.p_success, bool(out.go))


def check_marked_target(dl: Downlink, only: Optional[str]) -> None:
    """InputError (exit 2) when ``only`` (``--target``; None: every target) is not a marked target of ``dl``."""
    if only and not any(t.id == only for t in dl.targets):
        raise InputError(only, "target", "no such marked target in the downlink")


def marked_targets(dl: Downlink, setup: HandoffSetup, only: Optional[str] = None) -> list:
    """(target id, {near: uv, far: uv}, truth hazcam uv) for each marked target."""
    check_marked_target(dl, only)
    out = []
    for t in dl.targets:
        if only and t.id != only:
            continue
        src = {}
        for nc, prod in (("near", setup.near), ("far", setup.far)):
            mk = t.mark_in(prod.product_id) if prod is not None else None
            src[nc] = [mk.u, mk.v] if mk is not None else None
        hm = t.mark_in(setup.hazcam.product_id)
        out.append((t.id, src, [hm.u, hm.v] if hm is not None else None))
    return out


STATS_KEYS = ("n", "mean_px", "std_px", "min_px", "max_px")  # a Table-1 row's error statistics (all, successes, failures)
_STATS_KEYS_BEFORE = {"mean": "mean_px", "std": "std_px", "min": "min_px", "max": "max_px"}  # handoff.json before session 37


def _stats(errs):
    """``{n, mean_px, std_px, min_px, max_px}`` of hazcam errors ``errs`` (px); None for none."""
    if not errs:
        return None
    a = np.asarray(errs, float)
    return dict(zip(STATS_KEYS, (int(len(a)), float(a.mean()), float(a.std()), float(a.min()), float(a.max()))))


def table1(records: list) -> list:
    """Rows like the paper's Table 1: per method and navcam, success rate and error statistics."""
    rows = []
    order = [m for m in ALL_METHODS]
    def view(r):  # scip's answers form one row whatever view each used
        return "any" if r.method == SCIP else r.navcam

    keys = sorted({(r.method, view(r)) for r in records}, key=lambda k: (order.index(k[0]) if k[0] in order else 99, k[1] != "near"))
    for m, nc in keys:
        rs = [r for r in records if r.method == m and view(r) == nc and r.truth_uv is not None]
        if not rs:
            continue
        answered = [r for r in rs if r.error_px is not None]
        succ = [r.error_px for r in answered if r.success]
        fail = [r.error_px for r in answered if not r.success]
        rows.append({
            "method": m, "navcam": nc, "paper_method": m in PAPER_METHODS, "cases": len(rs),
            "answered": len(answered), "success_rate": len(succ) / len(rs),
            "all": _stats([r.error_px for r in answered]), "successes": _stats(succ), "failures": _stats(fail),
            "refined": m in REFINED,
        })
    return rows
