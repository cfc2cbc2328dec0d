"""Shared fixtures: the FMUs are built once per test session into a temporary folder."""
import os

import pytest

from fmu_src import native_build
from fmu_src import python_build as builder
from scenarios.cosim import fmi
from tests.fmu_helpers import free_all


@pytest.fixture(autouse=True)
def _free_fmu_instances():
    yield
    free_all()


def _shared(tmp_path_factory, name):
    """A session folder every pytest-xdist worker of this run shares (the workers' common
    base), so the FMUs are built once per run: the builds lock it (fmu_src.atomic.building)."""
    base = tmp_path_factory.getbasetemp()
    return (base.parent if os.environ.get("PYTEST_XDIST_WORKER") else base) / name


@pytest.fixture(scope="session", autouse=True)
def _fmu_cache(tmp_path_factory):
    """The session's unpacked FMUs in a cache of its own (scenarios.cosim.fmi.cache_folder),
    its subprocesses' too: each session builds its FMUs anew, and they would pile up in the
    user's cache (a week) otherwise."""
    os.environ.setdefault(fmi.CACHE, str(_shared(tmp_path_factory, "fmu-cache")))


@pytest.fixture(scope="session")
def fmus(tmp_path_factory):
    """Paths of every FMU, built once per session into a temporary folder, by script name."""
    return builder.ensure_built(builder.available(), _shared(tmp_path_factory, "fmu"))


@pytest.fixture(scope="session")
def native_fmus(fmus, tmp_path_factory):
    """The native twin of every FMU by script name, built once per session from the
    session's pythonfmu FMUs (each build compiles the kernels: seconds a file, on every core)."""
    return native_build.ensure_native(sorted(fmus), _shared(tmp_path_factory, "native"), python=fmus)


def pytest_sessionfinish(session, exitstatus):
    session.config.movingbase_status = int(exitstatus)


@pytest.hookimpl(trylast=True)
def pytest_unconfigure(config):
    """End the test process without the interpreter's teardown, after the exit handlers
    (our temp folders) ran: with pythonfmu FMUs loaded into this interpreter (fmpy runs
    them in-process), Py_Finalize ended in SIGSEGV in 2 of 6 full runs after every test had
    passed and the summary was printed; the cause is not found yet (docs/development.md)."""
    from movingbase.cli import exit_now
    exit_now(getattr(config, "movingbase_status", 0))


@pytest.fixture(scope="session")
def native(native_fmus):
    """Native FMU paths by script name, built from the session's pythonfmu FMUs."""
    return native_fmus
