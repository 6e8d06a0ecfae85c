"""Fixtures of the prediction tests (the synthetic world's slab target on exact terrain)."""

import pytest

from scipctl.pipeline import predict as P
from tests.pipeline import scene as S


@pytest.fixture(scope="module")
def slab_case():
    world, dl = S.cached("slab")
    ter = P.Terrain(S.oracle_sources(world, dl, step=2))
    return world, dl, ter
