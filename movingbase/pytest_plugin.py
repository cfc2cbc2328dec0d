"""A pytest plugin (registered as ``pytest11``): the ``scene_regression`` fixture holds a
user's scenario files in their own test suite as ``movingbase regress`` does.

    def test_my_slew(scene_regression):
        scene_regression.check("scenes/my_slew.toml", ci=True)

The baselines live beside the test file, in ``<test file's folder>/baselines/`` (or
``--regress-baseline DIR``); ``pytest --regress-update`` stores them (as pytest-regressions'
``--force-regen``), and a missing baseline is stored and the test fails once, saying so.
``--regress-report DIR`` writes a report with a chart per failure (DIR/<file stem>/). Imports of the kit
wait until a test asks for the fixture: a test session that does not use it pays nothing.
"""
import pathlib

import pytest


def pytest_addoption(parser):
    group = parser.getgroup("movingbase", "movingbase scene regression")
    group.addoption("--regress-update", action="store_true",
                    help="store the baselines of the scenes scene_regression checks, replacing those there")
    group.addoption("--regress-baseline", metavar="DIR", help="folder of the baselines (default: baselines/ "
                    "beside each test file)")
    group.addoption("--regress-report", metavar="DIR", help="write a regression report (Markdown, a chart per "
                    "failure) of each failing check into DIR")


class SceneRegression:
    """What ``scene_regression`` gives a test: ``check(scenario, ...)`` runs the scenario
    file and compares it with its baseline (stores it with ``--regress-update``); the test
    fails with the summary of what left its tolerance."""

    def __init__(self, baseline, update, report):
        self.baseline, self.update, self.report = baseline, update, report

    def check(self, scenario, *, ci=False, tolerances=None, time_tolerance=0.0, jobs=None, fmi_version=None):
        """Hold ``scenario`` (a file path or a shipped name) against its baseline; the
        Regression (scenarios.runs.regress) if it passed, else the test fails."""
        from movingbase import api
        stored = pathlib.Path(self.baseline) / pathlib.Path(str(scenario)).stem / "baseline.json"
        first = not self.update and not stored.is_file()
        outcome = api.regress(scenario, baseline=self.baseline, update=self.update or first, ci=ci,
                              tolerances=tolerances, time_tolerance=time_tolerance, jobs=jobs,
                              fmi_version=fmi_version, progress=False, report=None if self.update or first or
                              not self.report else pathlib.Path(self.report) / stored.parent.name)
        if outcome.exit_code:
            pytest.fail(outcome.summary(), pytrace=False)
        if first:
            pytest.fail(f"no baseline of {scenario} was in {self.baseline}: stored it now ({stored.parent}); "
                        "commit it, and the next run compares with it", pytrace=False)
        return outcome


@pytest.fixture
def scene_regression(request):
    """Hold scenario files against baselines beside the test file (see the module)."""
    option = request.config.getoption
    baseline = option("--regress-baseline") or pathlib.Path(request.path).parent / "baselines"
    return SceneRegression(baseline, option("--regress-update"), option("--regress-report"))
