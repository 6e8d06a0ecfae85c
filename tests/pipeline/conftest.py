"""Fixtures shared by the prediction and sequence tests."""

import pytest

from scipctl.pipeline import predict as P
from tests.pipeline import scene as S
from tests.pipeline.predict.helpers import flat, heightfield_source


@pytest.fixture(scope="module")
def rc():
    return S.rover_config()


@pytest.fixture(scope="module")
def flat_terrain():
    return P.Terrain([heightfield_source(flat)], smooth_sigma_px=0)
