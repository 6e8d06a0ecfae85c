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


def trust_model_from_text(text: str, source: str) -> TrustModel:
    """Parse a trust model; :class:`InputError` naming ``source`` when it is not one."""
    try:
        return TrustModel.from_dict(json.loads(text))
    except (ValueError, AttributeError) as e:
        raise InputError(source, "trust model", str(e)) from None


def load_trust_model(path) -> TrustModel:
    """The trust model in the JSON file ``path``."""
    p = Path(path)
    if not p.is_file():
        raise InputError(str(p), "trust model", "no such file")
    return trust_model_from_text(p.read_text(encoding="utf-8"), str(p))


def load_packaged_trust_model(name: str = PACKAGED) -> Optional[TrustModel]:
    """The packaged trust model ``scipctl/data/<name>`` (scip's by default, :data:`PACKAGED_DESIGNATION` for the
    designation's), or None when the package has none."""
    ref = resources.files("scipctl.data").joinpath(name)
    if not ref.is_file():
        return None
    return trust_model_from_text(ref.read_text(encoding="utf-8"), f"scipctl/data/{name}")


def trust_model_json(model: TrustModel) -> str:
    """Deterministic JSON text of ``model`` (same model, same bytes)."""
    return json.dumps(model.to_dict(), indent=1, sort_keys=True, allow_nan=False) + "\n"
