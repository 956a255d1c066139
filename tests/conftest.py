import os
import sys

# tests import their helpers (scene_builders, stats_util) as top-level modules
sys.path.insert(0, os.path.dirname(__file__))


import pytest  # noqa: E402


@pytest.fixture(scope="session")
def dask_cluster():
    """A real Dask LocalCluster for the farm tests: two worker processes with one thread each,
    scheduler on localhost only, dashboard on a free port (never the default 8787)."""
    distributed = pytest.importorskip("distributed")
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1",
                                  dashboard_address=":0", silence_logs=50) as c:
        yield c
