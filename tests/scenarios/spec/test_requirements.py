"""[requirements]: absolute specs a run must meet, parsed with clear errors, judged in every
run, shown in metrics.json, the report and the API, failing `movingbase run --require`
and `movingbase regress` through the exit code."""
import json
import math
import subprocess
import sys

import pytest

from scenarios import spec
from scenarios.runs import regress, runner
from scenarios.runs.metrics import key_unit

SLEW = runner.resolve("telescope_slew").read_text()


def _with(requirements, text=SLEW):
    return text + "\n[requirements]\n" + requirements + "\n"


def test_every_metric_number_and_its_unit_is_one_a_requirement_can_name(tmp_path):
    """METRIC_NUMBERS against what the metrics give: the keys and units of a run's results
    (every kind but tracking, which the kit's scenes do not use, shares a class with leg_tracking)."""
    scenario, paths, descriptions, values = runner.prepare(runner.resolve("telescope_slew"), True)
    scenario.sweep = None
    run = runner.run_prepared(scenario, paths, descriptions, values, None, False)[0]
    for metric in scenario.metrics:
        result = run.metrics[metric.name]
        assert {k: key_unit(result, k) for k in result if k != "unit"} == spec.keys.METRIC_NUMBERS[metric.kind]


@pytest.mark.parametrize("written, problem", [
    ('"pose eror peak" = "< 10 µm"', "requirements.'pose eror peak': no metric number 'pose eror peak'; did you "
                                     "mean 'pose error peak'?"),
    ('"pose error peak" = "< 10 kN"', "requirements.'pose error peak': '10 kN': a unit of another dimension 'kN'; "
                                      "expected a quantity in µm (m, mm, um)"),
    ('"pose error peak" = "< 10 parsec"', "unknown unit 'parsec'"),
    ('"pose error peak" = "10 µm"', 'expected a relation and a limit such as "< 10 µm"'),
    ('"pose error peak" = 10', 'expected a relation and a limit such as "< 10 µm"'),
    ('"pointing peak" = { limit = "< 1 arcsec", runs = ["moving"] }',
     "requirements.'pointing peak'.runs: no run 'moving'; the runs: none, fixed_base, moving_base"),
    ('"pointing peak" = { limt = "< 1 arcsec" }', "requirements.'pointing peak'.limt: unknown key"),
    ('requirements = 3', "requirements: expected"),
])
def test_a_bad_requirement_is_refused_naming_it(written, problem):
    text = _with(written) if not written.startswith("requirements =") else SLEW.replace(
        'name = "telescope_slew"', 'name = "telescope_slew"\nrequirements = 3')
    with pytest.raises(spec.ScenarioError) as error:
        spec.parse(text, "x.toml")
    assert problem in str(error.value), str(error.value)


def test_a_limit_is_read_in_the_numbers_unit_and_judged_at_its_edge():
    scenario = spec.parse(_with('"pose error peak" = "< 0.1 mm"\n"pointing peak" = { limit = ">= 0.5 arcsec", '
                                'runs = ["none"] }\n"pose error rotation_peak" = "<= 1 arcsec"'), "x.toml")
    peak, pointing, rotation = scenario.requirements
    assert (peak.metric, peak.key, peak.relation, peak.unit) == ("pose error", "peak", "<", "µm")
    assert peak.limit == pytest.approx(100.0) and rotation.limit == pytest.approx(4.84813681109536)   # µrad
    assert peak.met(99.99) and not peak.met(peak.limit) and not peak.met(math.nan) and not peak.met(None)
    assert rotation.met(rotation.limit) and pointing.met(0.5) and not pointing.met(0.49)
    judged = spec.judge(scenario.requirements, "fixed_base", {"pose error": {"peak": 120.0, "rotation_peak": 1.0}})
    assert [(j["requirement"], j["met"]) for j in judged] == [("pose error peak < 100 µm", False),
                                                             ("pose error rotation_peak <= 4.84814 µrad", True)]
    assert spec.unmet(judged) == "pose error peak < 100 µm NOT MET (120 µm)"
    again = spec.parse_data(spec.as_data(scenario), "x.toml")    # a Scenario copied (load_scenario) keeps them
    assert again.requirements == scenario.requirements


def test_run_require_fails_through_the_exit_code_and_metrics_json_holds_the_verdict(tmp_path):
    (tmp_path / "slew.toml").write_text(_with('"pose error peak" = "< 10 µm"\n'
                                              '"pointing peak" = { limit = "< 0.3 arcsec", runs = ["moving_base"] }'))
    command = [sys.executable, "-m", "movingbase", "run", str(tmp_path / "slew.toml"), "--ci", "--quiet", "--charts",
               "none", "--out", str(tmp_path / "out")]
    plain = subprocess.run(command, capture_output=True, text=True)
    assert plain.returncode == 0     # judged and shown, not failed unless asked
    assert "  none: requirement pose error peak < 10 µm: NOT MET (106 µm)" in plain.stdout
    assert "  moving_base: requirement pose error peak < 10 µm: met (0.953 µm)" in plain.stdout
    required = subprocess.run(command + ["--require"], capture_output=True, text=True)
    assert required.returncode == 1
    assert "requirement error: telescope_slew, run fixed_base: pose error peak < 10 µm NOT MET (106 µm)" in \
        required.stderr
    summary = json.loads((tmp_path / "out" / "slew" / "metrics.json").read_text())
    assert [j["met"] for j in summary["moving_base"]["requirements"]] == [True, True]
    assert summary["none"]["requirements"][0]["value"] == pytest.approx(106.46, abs=0.01)
    assert "| none | pose error peak < 10 µm | 106 µm | **NOT MET** |" in \
        (tmp_path / "out" / "slew" / "report.md").read_text()


def test_the_api_shows_the_requirements(tmp_path):
    import movingbase
    (tmp_path / "slew.toml").write_text(_with('"pose error peak" = "< 10 µm"').replace(
        'values = ["none", "fixed_base", "moving_base"]', 'values = ["none", "moving_base"]'))
    result = movingbase.run(tmp_path / "slew.toml", ci=True, progress=False)
    assert not result.requirements_met and result["moving_base"].requirements_met
    assert repr(result).endswith("requirements NOT MET: none>")
    assert "requirements NOT MET: pose error peak < 10 µm NOT MET (106 µm)" in repr(result["none"])
    table = result.metrics_table()
    assert table[("requirements", "")].tolist() == ["pose error peak < 10 µm NOT MET (106 µm)", "met"]
    assert "NOT MET" in result._repr_html_() and "NOT MET" in result["none"]._repr_html_()


def test_a_requirement_not_met_fails_regress_though_the_baseline_passes(tmp_path):
    (tmp_path / "slew.toml").write_text(_with('"pose error peak" = { limit = "< 10 µm", runs = ["fixed_base"] }')
                                        .replace('values = ["none", "fixed_base", "moving_base"]',
                                                 'values = ["fixed_base"]'))
    made = regress.regress([tmp_path / "slew.toml"], tmp_path / "base", update=True, ci=True)
    assert made.exit_code == 1 and "baselines updated; REQUIREMENTS NOT MET" in made.summary()
    again = regress.regress([tmp_path / "slew.toml"], tmp_path / "base", ci=True)
    assert again.exit_code == 1
    assert [(f.kind, f.text) for _, _, f in again.findings()] == [
        ("requirement", "requirement pose error peak < 10 µm NOT MET: 106.5 µm")]


def test_the_wind_scenes_ship_the_10_um_of_the_wind_rejection_page():
    for name in ("telescope_slew_observer", "keyhole_tracking_observer"):
        (requirement,) = spec.load(runner.resolve(name)).requirements
        assert (requirement.text, requirement.runs) == ("pose error peak < 10 µm", ("32 Hz",))


def test_a_requirement_of_runs_a_set_sweep_replaced_is_kept_for_those_left():
    """A requirement for the 8 Hz run refused a set= sweep of other bandwidths ("no run '8 Hz'"):
    the file named its own runs right; with the sweep replaced, it holds for those it names that
    are left (none here), while a run the file's own sweep lacks is still refused."""
    text = _with('"pose error peak" = { limit = "< 10 µm", runs = ["moving_base"] }')
    replaced = spec.parse(text, "slew.toml", {"sweep": {"parameter": "controller.feedforward", "values": ["none"]}})
    assert [r.runs for r in replaced.requirements] == [("moving_base",)]
    assert spec.judge(replaced.requirements, "none", {}) == []      # not a run it holds for
    with pytest.raises(spec.ScenarioError, match=r"no run 'moving'"):
        spec.parse(_with('"pose error peak" = { limit = "< 10 µm", runs = ["moving"] }'), "slew.toml")
