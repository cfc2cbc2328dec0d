"""Fixtures of the host tests: the FMUs extracted for a C host, FMI 2 and 3, native and pythonfmu."""
import os
import pathlib

import pytest

from fmu_src import native_build
from fmu_src import python_build as builder
from tests.hosts.c_host import MISUSE3, MODELS, Fmu, extract, pythonfmu_env


@pytest.fixture(scope="session")
def python_fmus(fmus, tmp_path_factory):
    """The pythonfmu FMUs, extracted, with the environment a C host needs for them."""
    out = tmp_path_factory.mktemp("misuse-python")
    env = pythonfmu_env()
    return {path.stem: Fmu(extract(path, out / path.stem), env) for path in fmus.values()}


@pytest.fixture(scope="session")
def native3(tmp_path_factory):
    """The FMI 3.0 native FMUs, extracted, by model identifier: build/fmu/native3 (built
    when stale), or those of MOVINGBASE_MISUSE_FMUS3 (sanitizer builds of .ci/sanitize.sh)."""
    given = os.environ.get("MOVINGBASE_MISUSE_FMUS3")
    if given:
        return {model: Fmu(pathlib.Path(given) / model, host=MISUSE3) for model in MODELS}
    out = tmp_path_factory.mktemp("misuse3")
    return {path.stem: Fmu(extract(path, out / path.stem), host=MISUSE3)
            for path in native_build.ensure_native3(builder.available()).values()}


@pytest.fixture(scope="session")
def extracted(request, tmp_path_factory):
    """The native FMUs, extracted, by model identifier: built from the session's pythonfmu
    FMUs, or those of MOVINGBASE_MISUSE_FMUS (sanitizer builds of .ci/sanitize.sh)."""
    given = os.environ.get("MOVINGBASE_MISUSE_FMUS")
    if given:
        return {model: Fmu(pathlib.Path(given) / model) for model in MODELS}
    out = tmp_path_factory.mktemp("misuse")
    found = {}
    for fmu in request.getfixturevalue("native_fmus").values():
        model = fmu.stem
        found[model] = Fmu(extract(fmu, out / model))
    return found
