"""Which saved chain a report may take instead of running it again: a chain's key and the keyed chains of a
``handoff.json``.

``simulate-handoff --chain`` saves each marked target's chain in ``handoff.json`` (``chains``) with its key; the
report, about to run a target's chain, takes the saved chain of the same key instead. The key is a SHA-256 of all
that the chain reads and is: the downlink (its source SHA-256, and every product's camera model as the command
had it, the stereo self-calibration applied), the start (product and pixel), the target id, the chain's
parameters, and the code (:func:`~scipctl.pipeline.code_identity.code_identity` of the whole package). The same key
is the same computation; what the report shows is then what ``simulate-handoff`` printed.
"""

from __future__ import annotations

import hashlib
import json
from typing import Optional

from ..errors import InputError
from ..model import Downlink
from .code_identity import code_identity

__all__ = ["chain_key", "keyed_chains_from_doc"]


def chain_key(dl: Downlink, start_product_id: str, start_uv, target_id: Optional[str], params) -> Optional[str]:
    """The key (hex SHA-256) of ``run_chain(dl, dl.product(start_product_id), start_uv, target_id, params=params)``
    with the packaged trust models; None when ``dl`` has no source SHA-256 (an in-memory downlink: nothing names
    it, so nothing is taken back)."""
    if not dl.source_sha256:
        return None
    doc = {"code": code_identity((".",)), "downlink": dl.source_sha256,
           "models": [[im.product_id, im.camera_model.to_dict()] for im in dl.images],
           "start": [start_product_id, [float(x) for x in start_uv]], "target": target_id, "params": repr(params)}
    return hashlib.sha256(json.dumps(doc, sort_keys=True).encode()).hexdigest()


def keyed_chains_from_doc(doc, product: str = "handoff.json") -> dict:
    """``{key: [ChainStep, ...]}`` of the chains a ``handoff.json`` document saved with a key (``chains[i].key``);
    entries without one (saved before keys, or a chain that stopped on bad input) are left out. InputError naming
    the product and the field on a malformed entry."""
    from .chain import ChainStep

    chains = doc.get("chains") if isinstance(doc, dict) else None
    if chains is None:
        return {}
    if not isinstance(chains, list):
        raise InputError(product, "chains", f"expected a list, got {type(chains).__name__}")
    out = {}
    for i, c in enumerate(chains):
        if not isinstance(c, dict):
            raise InputError(product, f"chains[{i}]", f"expected a chain record (JSON object), got {type(c).__name__}")
        key, steps = c.get("key"), c.get("steps")
        if key is None:
            continue
        if not isinstance(key, str) or not isinstance(steps, list) or not steps:
            raise InputError(product, f"chains[{i}].key", "expected a key (string) and its steps (a list)")
        out[key] = [ChainStep.from_dict(s, f"{product}: chains[{i}]", j) for j, s in enumerate(steps)]
    return out
