"""Bad scenario input, each fed exactly as a user would write it: refused before anything
runs with a message naming file, key, value and what was expected, or (a run that fails
mid-way) one clear line, a non-zero exit and nothing lost. Also the master's linear
extrapolation against a ramp. The README's "bad input -> what the user sees" table is
backed by these tests."""
import copy
import dataclasses
import json
import math
import pathlib
import subprocess
import sys

import numpy as np
import pytest

from scenarios import spec
from scenarios.cosim import master
from scenarios.cosim.fmi import unpack
from scenarios.cosim.records import read_records
from scenarios.output import report
from scenarios.runs import metrics, runner, single
from tests.scenario_helpers import SLEW, edited, refused

ROOT = pathlib.Path(__file__).resolve().parents[3]
KEYHOLE = runner.resolve("keyhole_tracking").read_text()
SCRIPTS = {"base": "telescope_fmu", "plant": "hexapod_plant_fmu", "controller": "leg_controller_fmu"}


def cli(tmp_path, *args):
    """python -m scenarios in a fresh process: (exit status, stdout, stderr)."""
    done = subprocess.run([sys.executable, "-m", "movingbase", "run", *map(str, args), "--quiet", "--out",
                           tmp_path / "out"],
                          capture_output=True, text=True, cwd=ROOT, timeout=600)
    assert "Traceback" not in done.stderr, done.stderr
    return done.returncode, done.stdout, done.stderr


@pytest.fixture(scope="module")
def descriptions(fmus):
    return {inst: unpack(fmus[script])[0] for inst, script in SCRIPTS.items()}


@pytest.fixture(scope="module")
def bare(descriptions):
    """The model descriptions without any min/max: the checks min/max cannot say, alone."""
    return with_range(descriptions, None, None, None, None)


def with_range(descriptions, inst, name, low, high):
    """A copy of the model descriptions in which inst's variable declares FMI min/max
    (inst None: no variable declares any)."""
    changed = copy.deepcopy(descriptions)
    if inst is None:
        for var in (v for md in changed.values() for v in md.modelVariables):
            var.min = var.max = None
        return changed
    var = next(v for v in changed[inst].modelVariables if v.name == name)
    var.min, var.max = low, high
    return changed


# ------------------------------------------------------- runs that would succeed wrongly
def test_two_sources_into_one_input_are_refused_naming_both(descriptions):
    text = SLEW + '[[connections]]\nfrom = "base.base_pose"\nto = "controller.reference_pose"\n'
    refused(text, "connections[9]", "two sources connected into one input",
            "connections[3] (base.reference_pose -> controller.reference_pose)",
            "connections[9] (base.base_pose -> controller.reference_pose)", "controller.reference_pose[1]",
            descriptions=descriptions)


def test_an_identical_duplicate_connection_is_refused(descriptions):
    text = SLEW + '[[connections]]\nfrom = "controller.leg_force"\nto = "plant.leg_force"\n'
    refused(text, "connections[9]", "duplicate connection", "connections[8] (controller.leg_force -> plant.leg_force)",
            "connections[9] (controller.leg_force -> plant.leg_force)", descriptions=descriptions)


def test_one_connection_listing_a_target_twice_is_refused(descriptions):
    text = edited(SLEW, ('to = "controller.reference_acc"',
                         'to = ["controller.reference_acc", "controller.reference_acc"]'))
    refused(text, "connections[5]", "duplicate connection", "both feed controller.reference_acc[1]",
            descriptions=descriptions)


def test_an_input_both_set_and_connected_is_refused(descriptions):
    text = edited(SLEW, ("[fmus.controller]\nfmu = \"leg_controller\"",
                         "[fmus.controller]\nfmu = \"leg_controller\"\nparameters = { leg_rate = [0, 0, 0, 0, 0, 0] }"))
    refused(text, "connections[7]", "plant.leg_rate -> controller.leg_rate feeds controller.leg_rate[1]",
            "fmus.controller.parameters also sets", descriptions=descriptions)


def test_the_cli_refuses_two_sources_before_anything_runs(tmp_path):
    path = tmp_path / "two_sources.toml"
    path.write_text(SLEW + '[[connections]]\nfrom = "base.base_pose"\nto = "controller.reference_pose"\n')
    status, out, err = cli(tmp_path, path)
    assert status == 1
    assert err.strip() == (f"scenario error: {path}: connections[9]: two sources connected into one input: "
                           "connections[3] (base.reference_pose -> controller.reference_pose) and connections[9] "
                           "(base.base_pose -> controller.reference_pose) both feed controller.reference_pose[1]; "
                           "keep one")
    assert not (tmp_path / "out" / "two_sources").exists()   # nothing ran


@pytest.mark.parametrize("stop, nearest", [("8.0005 s", "8 s and 8.001 s"), ("0.5 ms", "0.001 s"),
                                           ("59.9999 s", "59.999 s and 60 s")])
def test_stop_time_off_the_step_grid_is_refused_naming_the_nearest_valid_ones(stop, nearest):
    text = edited(SLEW, ('stop_time = "60 s"', f'stop_time = "{stop}"'))
    refused(text, "stop_time", f"'{stop}' is not a whole number of steps of '1 ms'",
            f"nearest valid stop times: {nearest}")


def test_a_ci_stop_time_off_the_grid_is_refused_too():
    refused(SLEW, "stop_time", "nearest valid stop times: 8 s and 8.001 s", overrides={"stop_time": "8.0005 s"})


def test_stop_time_on_the_grid_passes():
    assert spec.parse(edited(SLEW, ('stop_time = "60 s"', 'stop_time = "8.001 s"')), "ok.toml").stop_time == 8.001


@pytest.mark.parametrize("start, where", [("60 s", "at or after stop_time (60 s)"),
                                          ("75 s", "at or after stop_time (60 s)")])
def test_a_metric_from_at_or_after_the_stop_time_is_refused(start, where):
    text = edited(SLEW, ('from = "5 s"\nmeasured = "plant.pose"', f'from = "{start}"\nmeasured = "plant.pose"'))
    refused(text, "metrics[1].from", f"'{start}' lies {where}: the metric would count nothing")


def test_a_metric_from_after_the_ci_stop_time_is_refused():
    refused(SLEW, "metrics[0].from", "'5 s' lies at or after stop_time (4 s)", overrides={"stop_time": "4 s"})


def test_a_metric_from_after_the_last_recorded_time_is_refused():
    text = edited(SLEW, ('stop_time = "60 s"', 'stop_time = "60.005 s"'),
                  ('from = "5 s"\nmeasured = "plant.pose"', 'from = "60.002 s"\nmeasured = "plant.pose"'))
    refused(text, "metrics[1].from", "lies after the last recorded time (60 s)")


# ---------------------------------------------------------------- out-of-range values
CONTROLLER = '[fmus.controller]\nfmu = "leg_controller"'


@pytest.mark.parametrize("inst, name, low, high, change, parts", [
    ("base", "target_elevation", "0", str(math.pi / 2), ('"45 deg"', '"95 deg"'),
     ["'95 deg' = 1.65806 rad is outside the range of target_elevation declared by the FMU: "
      "[0, 90] deg = [0, 1.5708] rad"]),
    ("base", "target_elevation", "0", str(math.pi / 2), ('"45 deg"', '"1e300 deg"'),
     ["'1e300 deg' = 1.74533e+298 rad is outside"]),
    ("controller", "force_limit", "1", None, (CONTROLLER, CONTROLLER + "\nparameters = { force_limit = 0.0 }"),
     ["0.0 is outside the range of force_limit declared by the FMU: [1, inf] N"]),
    ("controller", "force_limit", "1", None, (CONTROLLER, CONTROLLER + '\nparameters = { force_limit = "-2 kN" }'),
     ["'-2 kN' = -2000 N is outside", "[0.001, inf] kN = [1, inf] N"]),
    ("controller", "kp", "0", None, (CONTROLLER, CONTROLLER + "\nparameters = { kp = -1e6 }"),
     ["-1000000.0 is outside the range of kp declared by the FMU: [0, inf] N/m"]),
    ("plant", "max_step", "1e-06", "0.01", ('max_step = "1 ms"', 'max_step = "0 ms"'),
     ["'0 ms' = 0 s is outside", "[0.001, 10] ms = [1e-06, 0.01] s"]),
    ("plant", "stroke", "0.001", "0.3", ("moving_base = 1,", 'moving_base = 1, stroke = "1 um",'),
     ["'1 um' = 1e-06 m is outside", "[1000, 300000] um = [0.001, 0.3] m"]),
    ("base", "lever_arm", "0", None, ('"25 m"', '"-1 m"'),
     ["'-1 m' is outside the range of lever_arm declared by the FMU: [0, inf] m"]),
    ("plant", "moving_base", "0", "1", ("moving_base = 1", "moving_base = 2"),
     ["2 is outside the range of moving_base declared by the FMU: [0, 1]"]),
])
def test_values_outside_the_declared_min_max_are_refused(descriptions, inst, name, low, high, change, parts):
    """Against model descriptions that declare FMI min/max (a copy with them added)."""
    ranged = with_range(descriptions, inst, name, low, high)
    refused(edited(SLEW, change), f"fmus.{inst}.parameters.{name}", *parts, descriptions=ranged)


def test_a_value_inside_the_declared_range_passes(descriptions):
    ranged = with_range(descriptions, "base", "target_elevation", "0", str(math.pi / 2))
    values = spec.bind(spec.parse(SLEW, "ok.toml"), ranged)
    assert values["base"]["target_elevation"] == pytest.approx(math.radians(45))


def test_a_sweep_value_outside_the_declared_range_is_refused(descriptions):
    ranged = with_range(descriptions, "base", "lever_arm", "0", "100")
    text = edited(SLEW, ('parameter = "controller.feedforward"\nvalues = ["none", "fixed_base", "moving_base"]',
                         'parameter = "base.lever_arm"\nvalues = ["25 m", "1e6 m"]'))
    refused(text, "sweep.values[1]", "'1e6 m' is outside the range of lever_arm declared by the FMU: "
            "[0, 100] m", descriptions=ranged)


def test_moving_base_yes_lists_the_allowed_values(descriptions, bare):
    """moving_base is an integer, not an enumeration: its description ("1: ...; 0: ...")
    has no "<index> <name>" pairs, so the list of names was empty."""
    text = edited(SLEW, ("moving_base = 1", 'moving_base = "yes"'))
    refused(text, "fmus.plant.parameters.moving_base", "'yes' is not one of the allowed values: an integer",
            "1: the base moves as the base_* inputs say; 0: fixed base", descriptions=bare)
    ranged = with_range(descriptions, "plant", "moving_base", "0", "1")
    refused(text, "fmus.plant.parameters.moving_base", "'yes' is not one of the allowed values: [0, 1] (moving_base:",
            descriptions=ranged)


def test_an_enumeration_index_out_of_range_is_refused(descriptions):
    text = edited(SLEW, ('fidelity = "full"', "fidelity = 9"))
    refused(text, "fmus.plant.parameters.fidelity", "9 is not one of full, massless_legs, base_gravity, no_base",
            "0 full, 1 massless_legs", descriptions=descriptions)


def test_infinite_and_nan_values_are_refused(descriptions):
    refused(edited(SLEW, ('lever_arm = "25 m"', "lever_arm = inf")), "fmus.base.parameters.lever_arm",
            "inf is not a finite number", descriptions=descriptions)
    refused(edited(SLEW, ('step = "1 ms"', "step = nan")), "step", "nan is not a finite number")


@pytest.mark.parametrize(
    "change, parts",
    [
        (
            ('target_elevation = "45 deg"', 'target_elevation = "95 deg"'),
            [
                "profile 'slew' with start_azimuth = '0 deg', start_elevation = '30 deg', target_azimuth = '20 deg', "
                "target_elevation = '95 deg': plant.telescope refuses it: "
                "slew elevation must lie in [0, 90] deg, got 30..95 deg"
            ],
        ),
        (
            ('start_elevation = "30 deg"', 'start_elevation = "-5 deg"'),
            ["start_elevation = '-5 deg'", "slew elevation must lie in [0, 90] deg, got -5..45 deg"],
        ),
        (('lever_arm = "25 m"', 'lever_arm = "-1 m"'), ["lever_arm = '-1 m'", "lever_arm must be >= 0"]),
    ],
)
def test_slew_settings_the_telescope_model_refuses_are_refused_before_anything_runs(bare, change, parts):
    refused(edited(SLEW, change), "fmus.base.parameters", *parts, descriptions=bare)


def test_a_sweep_value_the_telescope_model_refuses_is_refused(bare):
    text = edited(SLEW, ('parameter = "controller.feedforward"\nvalues = ["none", "fixed_base", "moving_base"]',
                         'parameter = "base.target_elevation"\nvalues = ["45 deg", "91 deg"]'))
    refused(text, "sweep.values[1]", "target_elevation = '91 deg'", "slew elevation must lie in [0, 90] deg",
            descriptions=bare)


def test_the_profile_and_every_sweep_value_are_told_together(bare):
    """The model checks (the telescope's profile) and each sweep value are told in one
    error, not the first alone: a user fixes the file in one go."""
    text = edited(SLEW, ('target_elevation = "45 deg"', 'target_elevation = "95 deg"'),
                  ('parameter = "controller.feedforward"\nvalues = ["none", "fixed_base", "moving_base"]',
                   'parameter = "base.start_elevation"\nvalues = ["30 deg", "-5 deg", "-6 deg"]'))
    with pytest.raises(spec.ScenarioError) as error:
        spec.bind(spec.parse(text, "bad.toml"), bare)
    keys = [key for _, key, _ in error.value.problems]
    # sweep.values[0] (30 deg, the file's own start) fails as the file does: told once, naming both
    assert keys == ["fmus.base.parameters", "sweep.values[1]", "sweep.values[2]"], keys
    assert error.value.problems[0][2].endswith(" (the same at sweep.values[0])")
    assert "got -6..95 deg" in str(error.value)


def test_a_sidereal_source_below_the_horizon_is_refused(descriptions):
    text = edited(KEYHOLE, ('declination = "30.89 deg"', 'declination = "-80 deg"'))
    refused(text, "fmus.base.parameters", "profile 'sidereal' with right_ascension = '222.32311789485317 deg', "
            "declination = '-80 deg'", "the source is below the horizon at t = ", descriptions=descriptions)


# --------------------------------------------------------------- what the file is
def test_an_empty_file_says_what_a_scenario_needs(tmp_path):
    path = tmp_path / "empty.toml"
    path.write_text("")
    status, _, err = cli(tmp_path, path)
    assert status == 1
    assert err.strip() == (f"scenario error: {path}: file: empty (no TOML keys): a scenario needs stop_time, step, "
                           "one [fmus.<instance>] table per FMU and [[connections]] (example: "
                           "scenarios/files/telescope_slew.toml)")


def test_a_missing_key_says_what_a_scenario_needs():
    refused('step = "1 ms"\n', "stop_time", "missing; a scenario needs stop_time, step, one [fmus.<instance>]")


def test_a_binary_file_is_refused(tmp_path):
    path = tmp_path / "scene.toml"
    path.write_bytes(b"PK\x03\x04\x00\x00binary")
    status, _, err = cli(tmp_path, path)
    assert status == 1
    assert err.strip() == f"scenario error: {path}: file: is a binary file (NUL byte at offset 4), not a TOML scenario"


def test_a_non_utf8_file_is_refused(tmp_path):
    path = tmp_path / "latin1.toml"
    path.write_bytes('name = "Tianma 65 m, 30°"\n'.encode("latin-1"))
    status, _, err = cli(tmp_path, path)
    assert status == 1
    assert err.strip() == (f"scenario error: {path}: file: is not UTF-8 text (byte 0xb0 at offset 23); a scenario "
                           "is a TOML file in UTF-8")


def test_a_directory_is_refused_naming_what_it_holds(tmp_path):
    status, _, err = cli(tmp_path, "scenarios/files")
    assert status == 1
    assert err.strip().startswith("scenario error: scenarios/files: file: is a directory, not a scenario file "
                                  "(.toml); it holds keyhole_tracking.toml, ")


def test_a_missing_file_is_refused(tmp_path):
    with pytest.raises(spec.ScenarioError, match=r"nothere\.toml: file: does not exist$"):
        spec.load(runner.resolve(tmp_path / "nothere.toml"))


def test_a_path_without_toml_resolves_to_the_file(tmp_path, monkeypatch):
    monkeypatch.chdir(ROOT)
    assert runner.resolve("scenarios/files/telescope_slew") == pathlib.Path("scenarios/files/telescope_slew.toml")
    assert spec.load(runner.resolve("scenarios/files/telescope_slew")).name == "telescope_slew"
    assert runner.resolve("telescope_slew") == runner.SHIPPED / "telescope_slew.toml"
    (tmp_path / "mine.toml").write_text(SLEW)
    assert runner.resolve(tmp_path / "mine") == tmp_path / "mine.toml"


@pytest.mark.parametrize("change, key, parts", [
    (('target_azimuth = "20 deg"', 'target_azimuth = "3 lb"'), "fmus.base.parameters.target_azimuth",
     ["unknown unit 'lb' in '3 lb'; expected a quantity in rad (rad, deg, mrad, urad, arcsec, arcmin)"]),
    (('target_azimuth = "20 deg"', 'target_azimuth = "3 mm"'), "fmus.base.parameters.target_azimuth",
     ["'3 mm' is in m; expected a quantity in rad (rad, deg, mrad, urad, arcsec, arcmin)"]),
    (('target_azimuth = "20 deg"', 'target_azimuth = "3 kg"'), "fmus.base.parameters.target_azimuth",
     ["'3 kg' is in kg; expected a quantity in rad"]),
    (('measured = "plant.leg_length"', 'measured = "plant.leg_lenght"'), "metrics[0].measured",
     ["FMU instance 'plant' (hexapod_plant) has no variable 'leg_lenght'"]),
    (('reference = "base"', 'reference = "base"\n[[metrics]]\nkind = "tracking"\nmeasured = "plant.pose"\n'
      'reference = "base.axis"'), "metrics[4]", ["measured plant.pose has 6 values, reference base.axis 2"]),
    (('measured = "plant.pose"', 'measured = "base.axis"'), "metrics[1].measured",
     ["base.axis has 2 values; a pose_tracking metric needs 6"]),
    (('"base.axis", "base.axis_rate"', '"base.axes", "base.axis_rate"'), "record.variables",
     ["has no variable 'axes'"]),
    (('initial_pose = "@base.reference_pose"', 'initial_pose = "@base.reference_pose", "initial_pose[3]" = "0.1 m"'),
     "fmus.plant.parameters.initial_pose[3]",       # the vector and one element: the later silently won
     ["sets initial_pose[3], which fmus.plant.parameters.initial_pose sets too: set each value once"]),
])
def test_unit_and_variable_mistakes_name_what_was_expected(descriptions, change, key, parts):
    refused(edited(SLEW, change), key, *parts, descriptions=descriptions)


@pytest.mark.parametrize("change, key, parts", [
    (('reference_pose = "base.reference_pose"', 'reference_pose = "controller.leg_force"'),
     "metrics[0].reference_pose", ["controller.leg_force is in N; a leg_tracking metric's reference_pose must be in "
                                   "m, m, m, rad, rad, rad (its result is in µm)"]),
    (('measured = "plant.leg_length"', 'measured = "plant.leg_rate"'), "metrics[0].measured",
     ["plant.leg_rate is in m/s; a leg_tracking metric's measured must be in m"]),
    (('measured = "plant.pose"', 'measured = "base.base_rate"'), "metrics[1].measured",
     ["base.base_rate is in m/s, m/s, m/s, rad/s, rad/s, rad/s; a pose_tracking metric's measured must be in m, m, m, "
      "rad, rad, rad (its result is in µm and µrad)"]),
    (('variable = "controller.leg_force"', 'variable = "plant.leg_length"'), "metrics[2].variable",
     ["plant.leg_length is in m; a peak metric's variable must be in N (its result is in kN)"]),
    (('reference = "base"', 'reference = "base"\n[[metrics]]\nkind = "tracking"\nmeasured = "base.axis"\n'
      'reference = "base.axis_rate"'), "metrics[4].measured", ["base.axis is in rad; a tracking metric's measured "
                                                               "must be in m (its result is in µm)"]),
])
def test_a_metric_of_variables_in_other_units_than_its_kind_reads_is_refused(descriptions, change, key, parts):
    """A metric's result carries its kind's unit (µm, µrad, kN): a variable of another
    quantity gave numbers in no unit at all (leg forces as a leg_tracking reference pose:
    2.6e10 "µm" in the report). Refused, naming the variable's units and those needed."""
    refused(edited(SLEW, change), key, *parts, descriptions=descriptions)


# ------------------------------------------------------------ a run that fails mid-way
def test_a_run_failing_mid_way_is_one_line_and_the_sweep_and_report_go_on(tmp_path):
    """A 16 ms step is past the controller's predicted 3.36 ms stability limit: with the
    fixed-base feedforward a leg leaves its stroke at 1.264 s (the moving-base one stays
    within it for the 8 s). The CLI says so in one line, the other sweep value still runs,
    and the report and metrics.json mark the failed run with its partial results."""
    path = tmp_path / "step16.toml"
    path.write_text(edited(SLEW, ('step = "1 ms"', 'step = "16 ms"'), ('interval = "10 ms"', 'interval = "16 ms"'),
                           ('"5 s"\nmeasured = "plant.leg_length"', '"1 s"\nmeasured = "plant.leg_length"'),
                           ('values = ["none", "fixed_base", "moving_base"]',
                            'values = ["fixed_base", "moving_base"]')))
    status, out, err = cli(tmp_path, path, "--ci", "--allow-unstable")   # beyond the predicted limit, on purpose
    assert status == 1
    line, = err.strip().splitlines()
    assert line.startswith(f"run error: {path}: scene telescope_slew, run fixed_base: FMU instance 'plant' failed "
                           "in doStep at t = 1.264 s (status DISCARD): [DISCARD] StrokeError at t=1.264 s: leg "), line
    assert "outside its stroke" in line
    assert "  fixed_base: FAILED after 79 steps (1.264 s); partial results kept" in out
    assert "  moving_base: 500 steps in" in out
    folder = tmp_path / "out" / "step16"         # the folder follows the file run, not the name it copies
    summary = json.loads((folder / "metrics.json").read_text())
    assert summary["fixed_base"]["failed"] == line.removeprefix("run error: ")
    assert summary["fixed_base"]["steps"] == 79
    assert "failed" not in summary["moving_base"] and summary["moving_base"]["steps"] == 500
    partial = summary["fixed_base"]["metrics"]["leg error"]     # counted from 1 s to the failure
    assert partial["rms"] > 0 and partial["peak"] >= partial["rms"]
    assert summary["fixed_base"]["metrics"]["pose error"]["rms"] is None   # from 5 s: nothing counted: null, not 0
    report = (folder / "report.md").read_text()
    assert "| fixed_base **failed at t = 1.264 s, partial: 1.264 of 8 s** **FLAGGED** | rms " in report
    assert (f"- **run fixed_base failed at t = 1.264 s, partial: 1.264 of 8 s**; its row covers the run up to then: "
            f"{summary['fixed_base']['failed']}") in report
    assert read_records(folder / "fixed_base.npz").time[-1] == pytest.approx(1.264)


def test_a_lever_arm_failing_mid_way_keeps_the_other_sweep_values(tmp_path):
    """A 1e6 m lever arm drives a leg past its stroke as the slew starts (5 s); the sweep
    values before and after it still run to the end."""
    path = tmp_path / "lever.toml"
    path.write_text(edited(SLEW, ('stop_time = "8 s"', 'stop_time = "5.5 s"'),
                           ('parameter = "controller.feedforward"\nvalues = ["none", "fixed_base", "moving_base"]',
                            'parameter = "base.lever_arm"\nvalues = ["25 m", "1e6 m", "30 m"]')))
    scenario, runs, report = runner.run_scenario(path, tmp_path, ci=True, progress=False)
    assert [(r.label, r.steps) for r in runs] == [("25 m", 5500), ("1e6 m", 5010), ("30 m", 5500)]
    assert [bool(r.failure) for r in runs] == [False, True, False]
    assert runs[1].failure.startswith(f"{path}: scene telescope_slew, run 1e6 m: FMU instance 'plant' failed in "
                                      "doStep at t = 5.01 s")
    assert runs[0].metrics["leg error"]["rms"] > 0 and runs[2].metrics["leg error"]["rms"] > 0


def test_a_run_refused_at_initialisation_is_reported_with_no_rows(descriptions, fmus, tmp_path):
    """A plant started far outside its workspace fails in initialisation (refused in
    exitInitializationMode, or at the first doStep): no rows past t0, a marked report,
    NaN metrics (nothing counted), not zeros."""
    text = edited(SLEW, ('initial_pose = "@base.reference_pose"', "initial_pose = [0, 0, -1, 0, 0, 0]"),
                  ('stop_time = "60 s"', 'stop_time = "6 s"'))
    scenario = spec.parse(text, "far.toml")
    values = spec.bind(scenario, descriptions)
    paths = {inst: fmus[script] for inst, script in SCRIPTS.items()}
    with pytest.raises(master.RunFailed) as failed:
        single.run(scenario, paths, values, tmp_path, "far", [metrics.make(m) for m in scenario.metrics])
    run = failed.value.run
    assert run.steps == 0 and "FMU instance 'plant' failed in" in run.failure
    assert "[ERROR] StrokeError in initialization: leg 1 length 1.882430 m outside its stroke" in run.failure
    assert "\n" not in run.failure
    assert run.record_path is None or len(read_records(run.record_path).time) <= 1
    assert math.isnan(run.metrics["leg error"]["rms"]) and math.isnan(run.metrics["pose error"]["rotation_peak"])
    text = report.write(scenario, [run], tmp_path).read_text()
    assert "| far **failed at t = 0 s, partial: 0 of 6 s** | rms n/a, peak n/a |" in text


# ------------------------------------------------- the master's linear extrapolation
def test_linear_extrapolation_against_a_ramp(descriptions, fmus, tmp_path):
    """Azimuth only, at its rate limit from 2 s on: the base yaw (= the mount angle
    180 deg - azimuth) is a ramp at -0.5 deg/s. Jacobi holds the input one step (controller input at t_k+1 = output at
    t_k); linear extrapolation adds half a step of the ramp, +0.5 h rate (the ramp's mean
    over the coming step); Gauss-Seidel, base stepped first, sees t_k+1 itself."""
    text = edited(SLEW, ('start_elevation = "30 deg"', 'start_elevation = "45 deg"'),
                  ('start_delay = "5 s"', 'start_delay = "0 s", az_rate_max = "0.5 deg/s", az_acc_max = "0.25 deg/s2"'),
                  ('stop_time = "60 s"', 'stop_time = "3 s"'), ('interval = "10 ms"', 'interval = "1 ms"'),
                  ('"base.axis_rate", "plant.pose"',
                   '"base.axis_rate", "base.base_pose", "controller.base_pose", "plant.pose"'),
                  ('from = "5 s"', 'from = "1 s"'), ('from = "5 s"', 'from = "1 s"'), ('from = "5 s"', 'from = "1 s"'),
                  ('from = "5 s"', 'from = "1 s"'))
    scenario = spec.parse(text, "ramp.toml")
    values = spec.bind(scenario, descriptions)
    paths = {inst: fmus[script] for inst, script in SCRIPTS.items()}
    yaw = {}
    for label, changes in {"held": {"extrapolation": "none"}, "linear": {"extrapolation": "linear"},
                           "gauss-seidel": {"extrapolation": "linear", "master": "gauss-seidel"}}.items():
        run = single.run(dataclasses.replace(scenario, **changes), paths, values, tmp_path, label)
        yaw[label] = np.column_stack([run.records["base.base_pose[6]"], run.records["controller.base_pose[6]"]])
        t = run.records.time
    h, rate = 1e-3, -math.radians(0.5)   # yaw = A = 180 deg - Az falls as the azimuth rises
    cruise = np.flatnonzero((t > 2.05) & (t < 2.95))
    out, held = yaw["held"][cruise - 1, 0], yaw["held"][cruise, 1]
    assert np.all(np.abs(np.diff(yaw["held"][cruise, 0]) - rate * h) < 1e-12)   # it is a ramp
    np.testing.assert_array_equal(held, out)                                      # one step held
    lead = yaw["linear"][cruise, 1] - yaw["linear"][cruise - 1, 0]
    np.testing.assert_allclose(lead, 0.5 * h * rate, rtol=0, atol=1e-12)          # +h/2 of the ramp
    np.testing.assert_allclose(yaw["gauss-seidel"][cruise, 1], yaw["gauss-seidel"][cruise, 0], rtol=0, atol=0)


def test_an_integer_parameter_s_description_gives_no_names():
    # the 3T plant's mode ('assembly mode, +1 or -1: ...'): its documented -1 was refused with
    # "-1 is not one of or (or their numbers: 1 or)", the description's words read as names;
    # names come from an Enumeration's declared items only
    import movingbase
    here = ["20 mm", "-144.36 mm", "-47.68 mm"]         # x_A2 = 20 mm: both modes assemble (eq. 11)
    for value in (-1, 1):
        scenario = movingbase.load_scenario("mechanism3t_paper", set={
            "plant.mode": value, "plant.initial_position": here, "controller.initial_position": here})
        assert runner.prepare_loaded(scenario)[3]["plant"]["mode"] == value
    with pytest.raises(spec.ScenarioError, match=r"'two' is not one of the allowed values: .*an integer|\[-1, 1\]") \
            as refusal:
        runner.prepare_loaded(movingbase.load_scenario("mechanism3t_paper", set={"plant.mode": "two"}))
    assert "not one of or" not in str(refusal.value)
    scenario = movingbase.load_scenario("keyhole_tracking")         # profile = "sidereal"
    assert runner.prepare_loaded(scenario)[3]["base"]["profile"] == 1     # an Enumeration's names still count


def test_a_campaign_file_run_as_a_scenario_and_the_reverse_are_told_which_file_they_are():
    # each was a wall of unknown and missing keys (8 lines), naming neither kind of file
    import movingbase
    from scenarios.runs import campaign
    shipped_campaign = runner.SHIPPED.parent / "campaigns" / "slew_sizes.toml"
    with pytest.raises(spec.ScenarioError) as as_scenario:
        movingbase.load_scenario(shipped_campaign)
    assert [p for _, _, p in as_scenario.value.problems] == [
        "this is a campaign file (it names a scenario and has no [fmus]), not a scenario: run it with "
        "`movingbase campaign FILE` (movingbase.campaign)"]
    with pytest.raises(campaign.CampaignError) as as_campaign:
        campaign.load(runner.resolve("telescope_slew"))
    assert len(as_campaign.value.problems) == 1 and "this is a scenario file" in str(as_campaign.value)
