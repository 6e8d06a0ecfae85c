"""Reliability diagram of the pre-uplink prediction against the chain (docs/images/prediction-reliability.png,
docs/sequence.md "The prediction scored on the route that was driven").

    python docs/scripts/prediction_reliability_plot.py OUT.png LABEL=PRED_CAMPAIGN [LABEL=PRED_CAMPAIGN ...] \
        --chains CHAIN_CAMPAIGN [CHAIN_CAMPAIGN ...]

PRED_CAMPAIGN may be several folders joined by commas (pooled). Each is scored as ``prediction_vs_chain.py`` scores it (an approach succeeds when the chain's last
hazcam answer is within 4 px of the mark); bins of width 0.1, the points sized by their counts, the Brier score
in the legend. Deterministic: the same records give the same picture.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from prediction_vs_chain import approaches  # noqa: E402


def reliability_axes():
    """``(fig, ax)``: the diagonal, the +-0.1 band of issue #15, the axes labelled."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(5.5, 5.0), dpi=110)
    ax.plot([0, 1], [0, 1], color="0.6", lw=1, ls="--", label="perfect calibration")
    ax.fill_between([0, 1], [-0.1, 0.9], [0.1, 1.1], color="0.9", label="+-0.1 (issue #15)")
    ax.set_xlim(0, 1), ax.set_ylim(0, 1)
    ax.set_xlabel("predicted P(success) (bin mean)")
    ax.set_ylabel("chain's final hazcam answer within 4 px (fraction)")
    return fig, ax


def reliability_series(ax, label: str, P, y) -> None:
    """One series: ``P`` ``(N,)`` against the outcomes ``y`` ``(N,)`` in bins of width 0.1, points sized by their
    counts, the Brier score in the label."""
    P, y = np.asarray(P, float), np.asarray(y, float)
    edges = np.linspace(0, 1, 11)
    idx = np.clip(np.digitize(P, edges) - 1, 0, 9)
    xs, ys, ns = [], [], []
    for b in range(10):
        m = idx == b
        if m.any():
            xs.append(P[m].mean()), ys.append(y[m].mean()), ns.append(int(m.sum()))
    brier = float(np.mean((P - y) ** 2))
    line, = ax.plot(xs, ys, "-", lw=1, label=f"{label}: {len(P)} approaches, Brier {brier:.3f}")
    ax.scatter(xs, ys, s=[8 + 3 * n for n in ns], color=line.get_color(), zorder=3)


def save(fig, ax, out: Path, title: str, base: float) -> None:
    ax.axhline(base, color="0.3", lw=0.8, ls=":", label=f"chain success rate {base:.2f}")
    ax.set_title(title)
    ax.legend(fontsize=7, loc="lower right")
    fig.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, metadata={"Software": None})


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out", type=Path)
    ap.add_argument("preds", nargs="+")
    ap.add_argument("--chains", nargs="+", type=Path, required=True)
    ap.add_argument("--success-px", type=float, default=4.0)
    a = ap.parse_args(argv)
    fig, ax = reliability_axes()
    for spec in a.preds:
        label, folder = spec.split("=", 1)
        rows = [r for f in folder.split(",") for r in approaches(a.chains, Path(f), a.success_px, {})]
        y = np.array([r["success"] for r in rows], float)
        reliability_series(ax, label, [r["P"] for r in rows], y)
    save(fig, ax, a.out, "Pre-uplink prediction against the chain", float(np.mean(y)))
    print(a.out)


if __name__ == "__main__":
    main()
