"""Print the derivation of the Mars 2020 rules file's rover-specific values (scipctl/data/rules-m2020.yaml).

    python docs/scripts/derive_m2020_rules.py [FOLDER]

FOLDER: the nasa-jpl/m2020-urdf-models files (m2020.urdf, m2020-camera-models.json); default shared/real/12_*
(``$SCIPCTL_SHARED_REAL`` or beside the checkout). Prints JSON: the arm workspace, the footprint, the arm's reach
straight ahead per instrument, the ground interval inside both hazcam images, the hazcam legs carried over from
the default file, and the SHA-256 of the inputs. The target keep-out and the hazcam margin are the rules files'
(the m2020 file gives neither: the default's). tests/io/test_m2020_rules.py checks the file against the same
derivation.
"""

from __future__ import annotations

import json
import os
import sys
from pathlib import Path


def _folder(argv) -> Path:
    if len(argv) > 1:
        return Path(argv[1])
    root = Path(__file__).resolve().parents[2]
    cands = [Path(os.environ["SCIPCTL_SHARED_REAL"])] if os.environ.get("SCIPCTL_SHARED_REAL") else []
    cands += [root / ".." / "shared" / "real", root / ".." / ".." / "shared" / "real"]
    for c in cands:
        hits = sorted(c.glob("12_*")) if c.is_dir() else []
        if hits:
            return hits[0]
    sys.exit("no shared/real/12_* folder: give FOLDER or set SCIPCTL_SHARED_REAL")


def main(argv) -> int:
    from scipctl.io.m2020_rules import derive_m2020
    from scipctl.pipeline.rules import load_rules

    default = load_rules("default").values
    m2020 = load_rules("m2020").values
    fr = m2020["flight_rules"]
    d = derive_m2020(_folder(argv), fr["target_keep_out_m"], fr["hazcam_fov_margin_px"])
    out = d.to_dict()
    # the hazcam legs: the default file's distances beyond its workspace centre, beyond the derived centre
    c_default = 0.5 * (default["arm_workspace"]["r_min_m"] + default["arm_workspace"]["r_max_m"])
    c_m2020 = 0.5 * (d.arm_workspace.r_min_m + d.arm_workspace.r_max_m)
    out["approach"] = {
        "workspace_centre_m": round(c_m2020, 4),
        "hazcam_handoff_m": round(default["approach"]["hazcam_handoff_m"] - c_default + c_m2020, 4),
        "hazcam_stops_m": [round(s - c_default + c_m2020, 4) for s in default["approach"]["hazcam_stops_m"]],
    }
    out["flight_rules"] = {"min_standoff_m": d.arm_workspace.r_min_m}
    print(json.dumps(out, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
