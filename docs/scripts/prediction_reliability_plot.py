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


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out", type=Path)
    ap.add_argument("preds", nargs="+")
    ap.add_argument("--chains", nargs="+", type=Path, required=True)
    ap.add_argument("--success-px", type=float, default=4.0)
    a = ap.parse_args(argv)
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(5.5, 5.0), dpi=110)
    ax.plot([0, 1], [0, 1], color="0.6", lw=1, ls="--", label="perfect calibration")
    ax.fill_between([0, 1], [-0.1, 0.9], [0.1, 1.1], color="0.9", label="+-0.1 (issue #15)")
    for spec in a.preds:
        label, folder = spec.split("=", 1)
        rows = [r for f in folder.split(",") for r in approaches(a.chains, Path(f), a.success_px, {})]
        P = np.array([r["P"] for r in rows])
        y = np.array([r["success"] for r in rows], float)
        edges = np.linspace(0, 1, 11)
        idx = np.clip(np.digitize(P, edges) - 1, 0, 9)
        xs, ys, ns = [], [], []
        for b in range(10):
            m = idx == b
            if m.any():
                xs.append(P[m].mean()), ys.append(y[m].mean()), ns.append(int(m.sum()))
        brier = float(np.mean((P - y) ** 2))
        line, = ax.plot(xs, ys, "-", lw=1, label=f"{label}: {len(rows)} approaches, Brier {brier:.3f}")
        ax.scatter(xs, ys, s=[8 + 3 * n for n in ns], color=line.get_color(), zorder=3)
    base = float(np.mean(y))
    ax.axhline(base, color="0.3", lw=0.8, ls=":", label=f"chain success rate {base:.2f}")
    ax.set_xlim(0, 1), ax.set_ylim(0, 1)
    ax.set_xlabel("predicted P(success) (bin mean)")
    ax.set_ylabel("chain's final hazcam answer within 4 px (fraction)")
    ax.set_title("Pre-uplink prediction against the chain")
    ax.legend(fontsize=7, loc="lower right")
    fig.tight_layout()
    a.out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(a.out, metadata={"Software": None})
    print(a.out)


if __name__ == "__main__":
    main()
