"""Reading and writing the trust model of ``scip`` (JSON <-> :class:`~scipctl.core.handoff.trust_model.TrustModel`).

The packaged model is ``scipctl/data/trust_model.json`` (package data; made by ``scipctl fit-trust``,
docs/handoff.md "Trust: scip"). JSON rather than a generated Python module: the file is data with its
provenance (tool version, command, input hashes, training families and counts), diffable, and read without
executing anything; the core receives the parsed dataclass in ``HandoffParams.scip.model``.
"""

from __future__ import annotations

import json
from importlib import resources
from pathlib import Path
from typing import Optional

from ..core.handoff.trust_model import TrustModel
from ..errors import InputError

PACKAGED = "trust_model.json"
PACKAGED_DESIGNATION = "designation_model.json"  # the designation's (pipeline/designation_trust.py), same form


def model_from_text(cls, text: str, source: str, what: str = "trust model"):
    """Parse a fitted model of class ``cls`` (any with ``from_dict``: :class:`TrustModel`, the chain's
    ``StepTrustModel``); :class:`InputError` naming ``source`` and ``what`` when it is not one."""
    try:
        return cls.from_dict(json.loads(text))
    except (ValueError, AttributeError) as e:
        raise InputError(source, what, str(e)) from None


def load_packaged_model(name: str, cls, what: str):
    """The packaged model ``scipctl/data/<name>`` parsed as ``cls``, or None when the package has none."""
    ref = resources.files("scipctl.data").joinpath(name)
    if not ref.is_file():
        return None
    return model_from_text(cls, ref.read_text(encoding="utf-8"), f"scipctl/data/{name}", what)


def trust_model_from_text(text: str, source: str) -> TrustModel:
    """Parse a trust model; :class:`InputError` naming ``source`` when it is not one."""
    return model_from_text(TrustModel, text, source)


def load_trust_model(path) -> TrustModel:
    """The trust model in the JSON file ``path``."""
    p = Path(path)
    if not p.is_file():
        raise InputError(str(p), "trust model", "no such file")
    return trust_model_from_text(p.read_text(encoding="utf-8"), str(p))


def load_packaged_trust_model(name: str = PACKAGED) -> Optional[TrustModel]:
    """The packaged trust model ``scipctl/data/<name>`` (scip's by default, :data:`PACKAGED_DESIGNATION` for the
    designation's), or None when the package has none."""
    return load_packaged_model(name, TrustModel, "trust model")


def trust_model_json(model) -> str:
    """Deterministic JSON text of a fitted model (anything with ``to_dict``; same model, same bytes)."""
    return json.dumps(model.to_dict(), indent=1, sort_keys=True, allow_nan=False) + "\n"
