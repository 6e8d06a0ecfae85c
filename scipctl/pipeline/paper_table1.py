"""The paper's Table 1: handoff accuracy of each method on Rocky 8 (18 targets), as printed there.

Each entry is the text of one cell: success rate, then mean ± std (range) in hazcam pixels; for the refined
methods, successes / failures. Shown beside our own Table 1 (``scipctl simulate-handoff``, the HTML report).
"""

from __future__ import annotations

# (method, navcam) -> the paper's cell text
PAPER_TABLE1 = {
    ("pure-kinematic", "near"): "100%  13±3 (9-23)",
    ("pure-kinematic", "far"): "100%  107±58 (63-182)",
    ("alt-pure-kinematic", "near"): "100%  22±5 (15-35)",
    ("alt-pure-kinematic", "far"): "83%  102±27 (68-152)",
    ("refined-kinematic", "near"): "55%  1±1 / 99±76 (0-3 / 18-214)",
    ("refined-kinematic", "far"): "67%  2±1 / 83±52 (0-4 / 16-166)",
    ("pure-geometric", "near"): "100%  9±6 (1-22)",
    ("pure-geometric", "far"): "100%  54±21 (20-95)",
    ("refined-geometric", "near"): "50%  1±1 / 109±77 (0-3 / 8-261)",
    ("refined-geometric", "far"): "17%  2±1 / 52±55 (1-3 / 19-231)",
    ("mesh-registration", "near"): "100%  28±11 (8-58)",
    ("mesh-registration", "far"): "100%  124±57 (36-226)",
}
