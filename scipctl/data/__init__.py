"""Package data: the fitted trust model of ``scip`` (``trust_model.json``)."""
