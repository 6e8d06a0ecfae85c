"""Fixtures of the campaign tests: a Dask scheduler and two workers on 127.0.0.1 (subprocesses), shared by the
tests of this folder."""

import pytest

from tests.campaign.dask_cluster import DaskTestCluster


@pytest.fixture(scope="package")
def dask_cluster(tmp_path_factory):
    with DaskTestCluster(tmp_path_factory.mktemp("dask"), n_workers=2) as cluster:
        yield cluster
