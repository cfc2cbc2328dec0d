"""Shared fixtures: the FMUs are built once per test session into a temporary folder."""
import pytest

from movingbase.fmu_src import builder
from tests.fmu_helpers import free_all


@pytest.fixture(autouse=True)
def _free_fmu_instances():
    yield
    free_all()


@pytest.fixture(scope="session")
def fmus(tmp_path_factory):
    """Paths of every FMU, built once per session into a temporary folder, by script name."""
    return builder.ensure_built(builder.available(), tmp_path_factory.mktemp("fmu"))
