"""A sequence document for the format tests: a planned approach to a target 9 m ahead on given terrain, with a
given confidence (no Monte Carlo), the default handoff choice and fixed exposures and provenance."""

import numpy as np

from scipctl.pipeline import predict as P
from scipctl.pipeline import sequence as Q
from scipctl.pipeline.designate import Designation
from tests.pipeline.predict.helpers import start_pose

TARGET = np.array([9.0, 0.0, 0.0])
RECORD = Designation(id="t1", product_id="pancam_left_1_0", camera="pancam", pixel_uv=(127.5, 127.5),
                     xyz_site_m=tuple(TARGET.tolist()), range_m=9.1)


def prediction(rc, terrain, target=TARGET, confidence=0.95, approach=None, uncertainty=None):
    plan = P.plan_approach(start_pose(), target, terrain, rc, approach or P.ApproachParams(), uncertainty=uncertainty)
    return P.Prediction("t1", plan, None, None, [], {}, np.asarray(target, float), confidence, "test")


def sequence_doc(rc, terrain, rules_used=None):
    """(prediction, document) for :data:`RECORD` on ``terrain``."""
    pred = prediction(rc, terrain)
    checks = Q.check_rules(pred, rc)
    handoff = Q.choose_handoff(None)
    cmds = Q.build_commands(pred, RECORD, handoff, {"pancam": 12.5, "navcam": None, "hazcam": 4.0})
    prov = {"tool": "scipctl", "version": "test", "command": "scipctl sequence X --target t1", "inputs": {}}
    return pred, Q.sequence_document(pred, RECORD, checks, cmds, handoff, prov, mission="m", sol=3,
                                     rules_used=rules_used)
