import pytest

from .harness import Cluster


@pytest.fixture
def cluster(tmp_path):
    c = Cluster(tmp_path, "missions/tutorial.yaml")
    c.start_server()
    yield c
    c.stop()
