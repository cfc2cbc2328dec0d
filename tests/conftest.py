"""Shared fixtures: the FMUs are built once per test session into a temporary folder."""
import sys

import pytest

import build


@pytest.fixture(scope="session")
def fmus(tmp_path_factory):
    """Paths of every built FMU, by script name."""
    out = tmp_path_factory.mktemp("fmu")
    sys.path.insert(0, str(build.ROOT / "fmu_src"))
    return {name: build.build(name, out) for name in build.available()}
