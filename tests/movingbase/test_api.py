"""movingbase.run / campaign (movingbase/api.py) against the command line's own results:
the same metrics and the same recorded series bit for bit, nothing written without
``out``, ``set`` overrides checked and applied exactly as the same value written in the
file, to_pandas against the arrays, and a failed run's flag and partial records."""
import importlib.util
import json
import subprocess
import sys

import numpy as np
import pytest

import movingbase
from fmu_src import catalogue
from scenarios import spec
from scenarios.cosim.records import read_records
from scenarios.runs import flags, runner
from tests.scenario_helpers import interrupt_the_second_run

NAME = "paper_manoeuvre"      # [ci]: 3 runs of 4 s at 1 ms, the shortest shipped scene with a sweep


@pytest.fixture(scope="module")
def cli(tmp_path_factory):
    """The CLI's output folder for the scene's [ci] version, CSV export included."""
    out = tmp_path_factory.mktemp("cli")
    subprocess.run([sys.executable, "-m", "movingbase", "run", NAME, "--ci", "--quiet", "--csv", "--out", str(out)],
                   check=True, capture_output=True)
    return out / NAME


@pytest.fixture(scope="module")
def result(tmp_path_factory):
    return movingbase.run(NAME, ci=True, progress=False)


def test_the_api_gives_the_cli_s_metrics_and_series_bit_for_bit(cli, result):
    summary = json.loads((cli / "metrics.json").read_text())
    assert list(result.runs) == list(summary) == ["none", "fixed_base", "moving_base"]
    for run in result:
        assert json.loads(json.dumps(run.metrics, default=float)) == summary[run.label]["metrics"]
        on_disk = read_records(cli / f"{run.label}.npz")
        assert on_disk.header == run.records.header and len(run.time) == 401
        assert on_disk.time.tobytes() == run.time.tobytes()
        assert on_disk.values.tobytes() == run.values.tobytes()
        assert run.ok and run.flags == [] and run.failure is None      # None, not '', as fmpy/scipy say nothing


def test_the_csv_export_is_the_records_exactly(cli, result, tmp_path):
    """The CLI's --csv and RunResult.to_csv write the same bytes; parsed back, every float
    is the recorded one (shortest repr round-trips)."""
    run = result["moving_base"]
    text = run.to_csv(tmp_path / "m.csv").read_text()
    assert text == (cli / "moving_base.csv").read_text()
    header, *rows = text.splitlines()
    assert header.split(",") == run.records.header
    parsed = np.array([row.split(",") for row in rows], dtype=float)
    assert parsed.tobytes() == np.column_stack([run.time, run.values]).tobytes()


def test_nothing_is_written_without_out_and_out_writes_the_cli_s_files(cli, monkeypatch, tmp_path):
    monkeypatch.chdir(tmp_path)
    movingbase.run(NAME, ci=True, progress=False, set={"stop_time": "2.1 s"})
    assert list(tmp_path.iterdir()) == []
    ran = movingbase.run(NAME, ci=True, progress=False, out=tmp_path / "out")
    written = tmp_path / "out" / NAME
    assert ran.report_path == written / "report.md"
    assert sorted(p.name for p in written.iterdir()) == sorted(p.name for p in cli.iterdir() if p.suffix != ".csv")


def test_set_is_the_value_written_in_the_file(tmp_path):
    """An FMU parameter and a top-level key set from Python give the records of the file
    with those values written in it, bit for bit."""
    text = runner.resolve(NAME).read_text()
    edited = text.replace('lever_arm = "0 m"', 'lever_arm = "3 m"').replace('stop_time = "4 s"', 'stop_time = "2.5 s"')
    assert edited.count('"3 m"') == 1 and edited.count('"2.5 s"') == 1
    (tmp_path / "edited.toml").write_text(edited)
    from_file = movingbase.run(tmp_path / "edited.toml", ci=True, progress=False)
    from_set = movingbase.run(NAME, ci=True, progress=False, set={"base.lever_arm": "3 m", "stop_time": "2.5 s"})
    plain = movingbase.run(NAME, ci=True, progress=False, set={"stop_time": "2.5 s"})
    for a, b, c in zip(from_file, from_set, plain):
        assert a.values.tobytes() == b.values.tobytes() and a.metrics == b.metrics
        assert a.time[-1] == 2.5 and not np.array_equal(a["plant.pose"], c["plant.pose"])   # it changed the run


@pytest.mark.parametrize("key, value, written", [
    ("base.lever_arm", "3 kg", ('lever_arm = "0 m"', 'lever_arm = "3 kg"')),
    ("plant.max_step", "-1 ms", ('max_step = "1 ms"', 'max_step = "-1 ms"')),
    ("stop_time", "1.0005 s", ('stop_time = "4 s"', 'stop_time = "1.0005 s"')),
])
def test_a_bad_set_value_is_refused_as_the_file_s_value_is(key, value, written, tmp_path):
    path = tmp_path / "bad.toml"
    path.write_text(runner.resolve(NAME).read_text().replace(*written))
    with pytest.raises(spec.ScenarioError) as in_file:
        movingbase.run(path, ci=True, progress=False)
    with pytest.raises(spec.ScenarioError) as from_set:
        movingbase.run(NAME, ci=True, progress=False, set={key: value})
    (_, file_key, problem), = in_file.value.problems
    (_, set_key, set_problem), = from_set.value.problems
    assert set_problem == problem       # the same check; told as set's value where set gave it
    assert set_key == f"set[{key!r}]"    # a top-level key too (it was told as the file's stop_time)


@pytest.mark.parametrize("changes, problem", [
    ({"nobody.lever_arm": "1 m"}, "set['nobody.lever_arm']: unknown FMU instance 'nobody'"),
    ({"controller.feedforward": "none"}, "is the swept parameter; every run sets it from sweep.values; to run one "
                                         "value: set={'sweep': {'parameter': 'controller.feedforward', 'values': "
                                         "['none']}}"),
])
def test_set_names_what_it_cannot_apply(changes, problem):
    with pytest.raises(spec.ScenarioError, match=problem.replace("[", r"\[").replace("]", r"\]")):
        movingbase.load_scenario(NAME, set=changes)


def test_a_scenario_object_runs_as_its_file(result):
    scenario = movingbase.load_scenario(NAME, ci=True)
    ran = movingbase.run(scenario, progress=False)
    assert scenario.parameters == spec.load(runner.resolve(NAME)).parameters   # the argument is left as it was
    for a, b in zip(ran, result):
        assert a.values.tobytes() == b.values.tobytes()
    with pytest.raises(spec.ScenarioError, match="top-level keys stop_time can be applied to a scenario file only"):
        movingbase.run(scenario, set={"stop_time": "1 s"})


def test_to_pandas_holds_the_arrays(result, tmp_path):
    pd = pytest.importorskip("pandas")
    run = result["fixed_base"]
    frame = run.to_pandas()
    assert list(frame.columns) == run.names and frame.index.name == "time"
    assert frame.to_numpy().tobytes() == run.values.tobytes() and frame.index.to_numpy().tobytes() == run.time.tobytes()
    assert frame.attrs["units"]["plant.pose[1]"] == "m" and frame.attrs["units"]["plant.pose[4]"] == "rad"
    every = result.to_pandas()
    assert every.index.names == ["run", "time"] and len(every) == sum(len(r.time) for r in result)
    assert every.loc["fixed_base"].to_numpy().tobytes() == run.values.tobytes()
    table = result.metrics_table()
    assert table.loc["moving_base", ("leg error", "rms")] == result.metrics["moving_base"]["leg error"]["rms"]
    assert table[("flags", "")].tolist() == [""] * len(table)          # none of the shipped runs went wrong
    structured = run.to_numpy()
    assert structured.dtype.names[:2] == ("time", "base.axis[1]")
    assert structured["plant.pose[3]"].tobytes() == run["plant.pose"][:, 2].tobytes()
    from_file = pd.DataFrame(dict(np.load(run.records.save(tmp_path / "r.npz"))))   # the file alone, for pandas
    assert list(from_file.columns) == run.records.header and from_file.to_numpy()[:,
                                                                                  1:].tobytes() == run.values.tobytes()


def test_to_pandas_without_pandas_says_what_to_install(result, monkeypatch):
    monkeypatch.setitem(sys.modules, "pandas", None)
    with pytest.raises(ModuleNotFoundError,
                       match=r"metrics_table, to_pandas, CampaignResult.table\) need pandas.*pip install pandas"):
        result["none"].to_pandas()


def test_a_run_that_fails_is_flagged_with_its_partial_records():
    """No feedback and no feedforward: no step is stable (the prediction refuses the run
    unless asked), the platform falls and a leg leaves its stroke within the first
    second; the other sweep values still run, and a run is cut short exactly when it
    stopped before the stop time."""
    zero = {"controller.kp": 0.0, "controller.ki": 0.0, "controller.kd": 0.0}
    with pytest.raises(spec.ScenarioError, match="allow_unstable"):
        movingbase.run(NAME, ci=True, progress=False, set=zero)
    ran = movingbase.run(NAME, ci=True, progress=False, set=zero, allow_unstable=True)
    failed = ran["none"]
    cut = [f for f in failed.flags if f.kind == "cut_short"]
    assert len(cut) == 1 and "StrokeError" in cut[0].message
    assert not failed.ok and 0 < failed.sim_time < 1.0 and "none" in ran.flags
    assert all("step_beyond_limit" in {f.kind for f in r.flags} for r in ran)
    # in Python's words too: the switch is allow_unstable=True here, --allow-unstable on the command line
    assert all(f.message.endswith("(run anyway: allow_unstable=True, --allow-unstable on the command line)")
               for r in ran for f in r.flags if f.kind == "step_beyond_limit")
    assert all(any(f.kind == "cut_short" for f in r.flags) == (r.sim_time < 4.0) for r in ran)
    assert any(r.sim_time == pytest.approx(4.0) for r in ran)
    assert failed.time[-1] <= failed.sim_time and len(failed.time) >= 2
    assert "cut_short" in repr(failed)
    if importlib.util.find_spec("pandas"):     # the table says it where the numbers stand
        said = ran.metrics_table()[("flags", "")]
        assert all("step_beyond_limit: " in said[r.label] and ("cut_short: " in said[r.label]) == (r.sim_time < 4.0)
                   for r in ran)


def test_plot_gives_the_report_s_charts_and_report_writes_them(result, tmp_path):
    figures = result.plot()
    tracked = [m for m in result.scenario.metrics if m.kind in ("leg_tracking", "pose_tracking", "tracking")]
    assert len(figures) == len(tracked) + 1          # one per tracking metric, and the summary
    assert [len(f.axes) for f in figures[:len(tracked)]] == [3, 4]   # error panels + the base motion underneath
    line = next(l for l in figures[0].axes[0].get_lines() if l.get_label() == "moving_base")
    t, values = result["moving_base"].run.series["leg error"]
    np.testing.assert_array_equal(line.get_xdata(), t)
    path = result.report(tmp_path / "rep")
    assert path.read_text().startswith(f"# {NAME}")
    # where run(out=) and the CLI's --out write: out/<file stem>/ (it once wrote into out/ itself)
    assert path == tmp_path / "rep" / NAME / "report.md"
    assert read_records(tmp_path / "rep" / NAME / "none.npz").values.tobytes() == result["none"].values.tobytes()


def test_charts_leave_the_user_s_backend_and_pyplot_figures_alone(tmp_path):
    """A notebook has its own backend and figures: running a scene with its charts and
    Result.plot() keep both (the kit once switched the backend to Agg as it was imported,
    which closed the user's pyplot figures). A fresh process, as a notebook's kernel."""
    code = ("import matplotlib; matplotlib.use('svg'); import matplotlib.pyplot as plt; plt.figure(); "
            "import movingbase; "
            f"r = movingbase.run({NAME!r}, ci=True, progress=False, out={str(tmp_path)!r}); figures = r.plot(); "
            "print(matplotlib.get_backend(), plt.get_fignums(), len(figures))")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert done.stdout.split() == ["svg", "[1]", "3"], done.stdout + done.stderr
    assert {p.name for p in (tmp_path / NAME).glob("*.png")} == {"leg_error_vs_time.png", "pose_error_vs_time.png",
                                                                "summary.png"}


def test_a_campaign_s_table_holds_the_numbers_of_its_runs_run_one_by_one(tmp_path):
    """Each row of movingbase.campaign's table has the metrics movingbase.run gives for
    the same case; a campaign that keeps no records writes none (and says so)."""
    pytest.importorskip("pandas")
    path = tmp_path / "lever.toml"
    path.write_text(f'name = "lever"\nscenario = "{NAME}"\nset = {{ stop_time = "2.5 s" }}\n'
                    '[[grid]]\n"base.lever_arm" = ["5 m", "2000 mm"]\n')
    ran = movingbase.campaign(path, out=tmp_path / "out", jobs=1, progress=False)
    table = ran.table()
    # every run is a 2.5 s cut of a slew that goes on (motion_unfinished): flagged, as run() says it, not "ok"
    assert len(ran) == len(table) == 6 and list(table["status"]) == ["flagged"] * 6
    assert repr(ran).startswith("<CampaignResult 'lever': 6 runs: 6 flagged, table in ") and not ran.ok
    assert set(ran.statuses.values()) == {"flagged"} and not (tmp_path / "out" / "lever" / ".movingbase.lock").exists()
    # the swept quantity as an SI number (a plot against it gets a number axis), its unit in attrs
    assert sorted(table["base.lever_arm"]) == [2.0] * 3 + [5.0] * 3 and table.attrs["units"]["base.lever_arm"] == "m"
    assert table.attrs["units"]["leg error rms"] == "µm" and table["leg error rms"].dtype == float
    assert '<span style="color:#b00020">6 runs: 6 flagged</span>' in ran._repr_html_()
    assert list(table["error"]) == [""] * 6 and all(f.startswith("motion_unfinished") for f in table["flags"])
    alone = movingbase.run(NAME, progress=False, set={"stop_time": "2.5 s", "base.lever_arm": "5 m"})
    for row in table[table["base.lever_arm"] == 5.0].to_dict("records"):
        run = alone[row["controller.feedforward"]]   # the scenario's sweep, crossed in by the campaign
        assert row["leg error rms"] == run.metrics["leg error"]["rms"], row
        assert row["pose error rotation_peak"] == run.metrics["pose error"]["rotation_peak"], row
    assert not list((tmp_path / "out" / "lever" / "runs").glob("*.records.npz"))
    with pytest.raises(FileNotFoundError, match="no records kept"):
        ran.records(ran.labels[0])
    t, _ = ran.series(ran.labels[0])["leg error"]
    assert t[0] >= 2.0
    # the command says it too: the summary file's status column and the exit status (3: flagged)
    from movingbase import cli
    assert cli.main(["campaign", str(path), "--out", str(tmp_path / "out"), "--jobs", "1", "--quiet"]) == 3
    summary = (tmp_path / "out" / "lever" / "summary.csv").read_text().splitlines()
    status = summary[0].split(",").index("status")
    assert [row.split(",")[status] for row in summary[1:]] == ["flagged"] * 6


@pytest.mark.parametrize("content, problem", [
    (b"time [s],x [m]\r\n0.0,1.0\r\n", "cannot read recorded data"),                  # a CSV, not npz
    ({"t": np.zeros(2)}, "not a run's records .*found t"),                              # no time column
    ({"time [s]": np.zeros(2), "plant.x": np.ones(2)}, "not a run's records .*plant.x"),  # no unit
    (b"time [s],x [m]\r\n0.0,1.0\r\n", "cannot read recorded data: not an npz archive"),  # not "pickled data"
    (np.zeros(3), r"cannot read recorded data: one array \(an .npy file\)"),             # np.save's file
    ({"time [s]": np.arange(3.0), "p.x [m]": np.zeros(2)}, "not a run's records: columns 'p.x .m.' are not floats"),
    ({"time [s]": np.array(["a", "b"]), "p.x [m]": np.zeros(2)}, "not a run's records: columns 'time"),  # text times
    ({"time [s]": np.array([0.0, np.nan]), "p.x [m]": np.zeros(2)}, "its times are not finite and increasing"),
    ({"time [s]": np.array([1.0, 0.0]), "p.x [m]": np.zeros(2)}, "its times are not finite and increasing"),
    ({"time [s]": np.array([0.0, 0.5, 0.5]), "p.x [m]": np.zeros(3)}, "its times are not finite and increasing"),
])
def test_a_file_that_is_not_records_is_refused_naming_it(content, problem, tmp_path):
    """Whatever a user hands read_records that a run did not write: one ValueError naming
    the file and what is wrong (an .npy file was a TypeError, a CSV renamed "pickled data",
    columns of other lengths numpy's concatenate error; text or NaN times were read)."""
    path = tmp_path / "bad.npz"
    if isinstance(content, bytes):
        path.write_bytes(content)
    elif isinstance(content, np.ndarray):
        with open(path, "wb") as f:
            np.save(f, content)
    else:
        np.savez(path, **content)
    with pytest.raises(ValueError, match=f"{path}: (not a run's records: )?{problem}"):
        read_records(path)


@pytest.mark.parametrize("change, key, problem", [
    ({"step": 0.0}, "step", "must be positive"),
    ({"step": -1e-3}, "step", "must be positive"),
    ({"stop_time": float("nan")}, "stop_time", "nan is not a finite number"),
    ({"stop_time": 4.0005}, "stop_time", "not a whole number of steps"),
    ({"record_interval": 0.0}, "record.interval", "must be a whole multiple of step"),
    ({"name": "../x"}, "name", "not a path"),
    ({"master": "bogus"}, "master", "unknown master 'bogus'"),
    ({"sweep": ("nope.lever_arm", ["1 m"])}, "sweep.parameter", "unknown FMU instance 'nope'"),
    ({"record": ["nope.x"]}, "record.variables", "unknown FMU instance 'nope'"),
    ({"connections": [("nope.x", ["plant.leg_force"])]}, "connections[0].from", "unknown FMU instance 'nope'"),
    ({"implementations": {"base": "rust"}}, "fmus.base.implementation", "unknown implementation 'rust'"),
    ({"parameters": {"base": 5}}, "fmus.base.parameters", "expected a table"),
])
def test_a_scenario_object_changed_in_python_is_checked_as_its_file(change, key, problem):
    """dataclasses.replace (as the docs suggest) once bypassed every check of the file:
    step 0 ended in ZeroDivisionError, a NaN stop time in ValueError, an unknown instance
    in KeyError, and a negative step or an unknown master ran."""
    import dataclasses
    scenario = dataclasses.replace(movingbase.load_scenario(NAME, ci=True), **change)
    with pytest.raises(spec.ScenarioError) as error:
        movingbase.run(scenario, progress=False)
    assert f": {key}: " in str(error.value) and problem in str(error.value), str(error.value)


def test_set_takes_numpy_values_as_the_numbers_they_hold():
    """np.float32(0.5), np.int64(1), a 0-d array or np.zeros(6) from a notebook were refused
    ("expected a number", "expected 6 values, got 1"); they bind to what Python's numbers bind to."""
    def bound(values):
        scenario = movingbase.load_scenario("telescope_slew", ci=True, set=values)
        return runner.prepare_loaded(scenario)[3]
    as_numpy = bound({"base.start_elevation": np.float32(0.5), "plant.moving_base": np.int64(1),
                      "base.lever_arm": np.array(25.0), "plant.initial_pose": np.zeros(6),
                      "stop_time": np.float64(8.0)})
    as_python = bound({"base.start_elevation": float(np.float32(0.5)), "plant.moving_base": 1,
                       "base.lever_arm": 25.0, "plant.initial_pose": [0.0] * 6, "stop_time": 8.0})
    assert as_numpy == as_python and as_numpy["base"]["start_elevation"] == float(np.float32(0.5))


@pytest.mark.parametrize("values, problem", [
    ("base.lever_arm", "expected a mapping"), ({3: 1}, "keys are text"), ({None: 1}, "keys are text"),
    ({"": 1}, "keys are text"),
])
def test_a_set_that_is_no_mapping_of_keys_is_refused(values, problem):
    with pytest.raises(spec.ScenarioError, match=problem):
        movingbase.load_scenario(NAME, set=values)


def test_report_into_a_file_or_an_empty_path_is_refused(result, tmp_path, capsys):
    """report(path) onto a file ended in FileExistsError; report("") wrote into the current
    folder; a second report into one folder replaced the first without a word."""
    result.report(tmp_path / "twice")
    assert capsys.readouterr() == ("", "")
    result.report(tmp_path / "twice")
    said = capsys.readouterr()     # on stderr, as the CLI says it and the docs tell (it went to stdout)
    assert "holds the results of an earlier run" in said.err and said.out == ""
    (tmp_path / "file").write_text("x")
    for path, problem in [(tmp_path / "file", "is a file, not a folder"), ("", "is empty"), (" ", "is empty"),
                          (123, "must be a path, got int")]:
        with pytest.raises(runner.OutputError, match=problem):
            result.report(path)


@pytest.mark.parametrize("jobs, error, problem", [
    (0, "ResourceError", "^jobs=0: the number of worker processes must be a whole number of at least 1"),
    (-1, "ResourceError", "^jobs=-1: the number"),
    (1.5, TypeError, r"^jobs must be an integer \(the number of worker processes\) or None, not float 1.5$"),
    (True, TypeError, "not bool True"), ("1", TypeError, "not str '1'")])
def test_a_campaign_s_bad_worker_count_is_refused_before_anything_runs(jobs, error, problem, tmp_path):
    """jobs=0 once ran on every core ("0 or all"), silently; the command line refused it. From
    Python the refusal names ``jobs=``, not the command line's --jobs."""
    from scenarios.runs.estimates import ResourceError
    with pytest.raises(ResourceError if error == "ResourceError" else error, match=problem):
        movingbase.campaign("slew_sizes", ci=True, jobs=jobs, out=tmp_path, progress=False)
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("scenario, problem", [
    ("telescope_slew ", "did you mean 'telescope_slew' for 'telescope_slew '?"),
    ("nope", "no scenario file or shipped scenario named 'nope'; shipped: keyhole_tracking"),
    # a path can only be a file: no list of the shipped (a long path's message stays short)
    ("no/such_scene.toml", "no scenario file or shipped scenario named 'no/such_scene.toml'\n"),
    (5, "scenario must be a shipped name, a file path or a Scenario, got int 5"),
    (None, "got NoneType None"),
])
def test_a_scenario_that_is_not_one_is_refused_naming_the_shipped_ones(scenario, problem):
    """A missing name said only "file: does not exist"; an int or None ended in os.fspath's TypeError."""
    with pytest.raises((spec.ScenarioError, TypeError)) as error:
        movingbase.load_scenario(scenario)
    assert problem in str(error.value) + "\n", str(error.value)


def test_a_run_that_failed_before_recording_says_so_where_its_series_is_asked():
    """A pose out of reach at the start: every method still answers; asking for a series
    said only "no recorded variable 'plant.pose'; recorded: " (nothing)."""
    ran = movingbase.run("telescope_slew", ci=True, progress=False, set={"plant.initial_pose": [0, 0, 0.43, 0, 0, 0]})
    run = ran["none"]
    assert not run.ok and len(run.time) == 0 and ran.to_pandas().shape[0] == 0
    with pytest.raises(KeyError, match="nothing was recorded, the run failed before its first row: .*exitInitial"):
        run["plant.pose"]


# ------------------------------------------------------------------ a failed run is plain to see
@pytest.fixture(scope="module")
def cut_short():
    """telescope_slew [ci] with a 1000 km lever arm: every run stops at 5.01 s of 8 s
    (the plant's stroke error), after saturating on the way."""
    with pytest.warns(movingbase.RunWarning) as said:
        result = movingbase.run("telescope_slew", ci=True, set={"base.lever_arm": "1e6 m"}, progress=False)
    return result, [str(w.message) for w in said]


def test_a_cut_short_run_says_failed_first_everywhere(cut_short):
    result, said = cut_short
    assert not result.ok and len(said) == len(result) == 3
    for run, message in zip(result, said):
        assert run.status == "failed" and run.failure and run.sim_time < 8.0
        assert run.flags[0].kind == "cut_short"            # the cause before the symptoms
        # the rows' share of the stroke and the plant's StrokeError tell one story
        stroke, = [f.message for f in run.flags if f.kind == "stroke"]
        assert stroke.endswith("% of its +-150 mm stroke in its recorded rows, and left it between them (cut_short)")
        assert "StrokeError" in run.failure
        assert [f.kind for f in run.flags] == sorted((f.kind for f in run.flags), key=flags.SEVERITY.index)
        # which scenario and which values warned: a loop of runs tells its iterations apart
        assert message.startswith(f"telescope_slew (set={{'base.lever_arm': '1e6 m'}}), run {run.label!r} FAILED "
                                  "(cut_short")
        assert repr(run).startswith(f"<RunResult {run.label!r}: FAILED at t = {run.sim_time:g} s: cut_short")
    assert repr(result) == "<Result 'telescope_slew': 3 runs: 3 failed; failed: none, fixed_base, moving_base>"
    table = result.metrics_table()
    assert list(table[("status", "")]) == ["failed"] * 3 and table.columns[0] == ("status", "")
    assert all(cell.startswith("FAILED (cut_short: stopped at t = 5.01 s") for cell in table[("flags", "")])


def test_tab_completion_offers_the_api():
    assert {"run", "campaign", "load_scenario", "ScenarioError"} <= set(dir(movingbase))
    assert not {"Any", "TYPE_CHECKING", "plant", "scenarios"} & set(dir(movingbase))
    assert movingbase.ScenarioError is spec.ScenarioError


def test_runs_by_position_and_key_completion(cut_short):
    result, _ = cut_short
    assert [result[i].label for i in range(len(result))] == list(result.runs) and result[-1] is result["moving_base"]
    with pytest.raises(IndexError, match="run 3 of 3"):
        result[3]
    assert result._ipython_key_completions_() == ["none", "fixed_base", "moving_base"]
    keys = result[0]._ipython_key_completions_()
    assert "plant.pose" in keys and "plant.pose[1]" in keys
    assert result[0]["plant.pose"].shape[1] == 6


def test_a_scenario_loaded_for_ci_keeps_its_short_run_when_run():
    # load_scenario(ci=True) then run(scenario): run() checked it as a full run, and the slew its
    # [ci] stop time cuts on purpose was flagged motion_unfinished (the ci path never is); a
    # copy (dataclasses.replace, a Scenario reloaded) keeps it too
    import dataclasses
    short = movingbase.load_scenario("telescope_slew", ci=True, set={"stop_time": "5.1 s"})
    assert short.short and movingbase.load_scenario(dataclasses.replace(short, step=short.step)).short
    ran = movingbase.run(short, progress=False)
    assert ran.ok and all(r.flags == [] for r in ran)
    full = movingbase.load_scenario("telescope_slew", set={"stop_time": "5.1 s"})
    with pytest.warns(movingbase.RunWarning, match="motion_unfinished"):
        assert not movingbase.run(full, progress=False).ok    # the same cut, asked as a full run


def test_a_build_is_said_as_it_starts_and_nothing_when_none_is_due(tmp_path, capsys):
    from fmu_src.native_build import ensure_native
    from fmu_src.python_build import ensure_built
    ensure_built(["leg_sensor_fmu"])      # the pythonfmu FMU it is made from: built (if due) before
    with runner.announcing_builds(False):     # a build not announced first (a run with progress off) ...
        built = ensure_native(["leg_sensor_fmu"], out=tmp_path)["leg_sensor_fmu"]
    assert capsys.readouterr().err == ""
    built.unlink()
    import logging
    assert not logging.getLogger("movingbase.build").isEnabledFor(logging.INFO)   # as a build unannounced asks
    with runner.announcing_builds():          # ... and the next announced one is said (the logger's cache)
        ensure_native(["leg_sensor_fmu"], out=tmp_path)      # missing there: built
        ensure_native(["leg_sensor_fmu"], out=tmp_path)      # up to date: nothing to say
    said = capsys.readouterr().err.splitlines()
    assert said == ["building the native FMI 2.0 FMU of leg_sensor_fmu"]


def test_the_headline_refuses_the_metrics_of_ci_runs(cli, tmp_path):
    # `movingbase headline --from` a folder of --ci runs rewrote the README's headline from
    # runs cut short on purpose (and unflagged for it); their metrics.json says they are --ci
    from scenarios.output import headline
    written = json.loads((cli / "metrics.json").read_text())
    assert all(entry["ci"] is True for entry in written.values())
    for scene in headline.SCENES:
        (tmp_path / scene).mkdir()
        (tmp_path / scene / "metrics.json").write_text(json.dumps(written))
    with pytest.raises(headline.Flagged, match=r"a --ci run \(its \[ci\] settings"):
        headline.collect(tmp_path)
    full = {run: {k: v for k, v in entry.items() if k != "ci"} for run, entry in written.items()}
    for scene in headline.SCENES:
        (tmp_path / scene / "metrics.json").write_text(json.dumps(full))
    assert set(headline.collect(tmp_path)) == set(headline.SCENES)    # the same numbers from full runs are taken


@pytest.mark.parametrize("call, argument", [
    (lambda v: movingbase.run(NAME, ci=v, progress=False), "ci"),
    (lambda v: movingbase.run(NAME, ci=True, progress=False, allow_unstable=v), "allow_unstable"),
    (lambda v: movingbase.run(NAME, ci=True, progress=v), "progress"),
    (lambda v: movingbase.load_scenario(NAME, ci=v), "ci"),
    (lambda v: movingbase.campaign("slew_sizes", ci=v), "ci")])
@pytest.mark.parametrize("value", ["false", "no", 0, None])
def test_a_switch_given_as_anything_but_true_or_false_is_refused(call, argument, value, tmp_path, monkeypatch):
    # ci="false" ran the [ci] version and allow_unstable="no" ran beyond the limit (both true)
    monkeypatch.chdir(tmp_path)
    with pytest.raises(TypeError, match=f"{argument} must be True or False, got "):
        call(value)
    assert not (tmp_path / "out").exists()       # refused before anything ran or was written


@pytest.mark.parametrize("given, told", [
    ({"base.start_elevaton": "60 deg"}, "set['base.start_elevaton']: FMU instance 'base' (telescope) has no variable "
                                        "'start_elevaton'; did you mean 'start_elevation'?"),
    ({"base.start_elevation": "60 m"}, "set['base.start_elevation']: '60 m' is in m; expected a quantity in rad"),
    ({"bsae.start_elevation": "60 deg"}, "set['bsae.start_elevation']: unknown FMU instance 'bsae'; did you mean "
                                         "'base'?")])
def test_a_bad_set_value_is_told_as_set_s_not_as_the_file_s(given, told):
    # set={"base.start_elevaton": ...} was told as the shipped file's fmus.base.parameters...
    with pytest.raises(spec.ScenarioError) as refused:
        movingbase.run("telescope_slew", ci=True, set=given, progress=False)
    assert told in str(refused.value) and "fmus.base.parameters" not in str(refused.value)
    # told as the caller's set=, not as a fault of the shipped file
    assert str(refused.value).startswith("set= for telescope_slew.toml: set['b"), str(refused.value)


@pytest.mark.parametrize("scene, given, told", [
    ("telescope_slew", {"step": "5 ms"}, "set['step']: runs 'none', 'fixed_base', 'moving_base' (sweep of "
                                         "controller.feedforward): 5 ms is beyond the predicted stability limit 2 ms"),
    ("telescope_slew", {"stop_time": "0.5 s"}, "metrics[0].from: '5 s' lies at or after stop_time (0.5 s): the "
                                               "metric would count nothing (the same at metrics[1].from, "
                                               "metrics[2].from, metrics[4].from)"),
    ("telescope_slew", {"sweep": {"parameter": "controller.kp", "values": ["1 N"]}},
     "set['sweep'].values[0]: '1 N' is in N; expected a quantity in N/m"),
    ("keyhole_tracking", {"base.declination": "-80 deg"}, "fmus.base.parameters: profile 'sidereal' with "
                                                          "right_ascension = '222.32311789485317 deg', declination = "
                                                          "'-80 deg'")])
def test_set_s_top_level_keys_sweep_and_values_are_blamed_on_set_once_each(scene, given, told):
    """Mistakes in set= beyond one parameter's own value (a top-level key, the step, the sweep,
    a declination that puts the source below the horizon) were told as the shipped file's,
    the stop time's four times over and the horizon's once per sweep value."""
    with pytest.raises(spec.ScenarioError) as refused:
        movingbase.run(scene, set=given, progress=False)
    said = str(refused.value)
    assert said.startswith(f"set= for {scene}.toml: {told}"), said
    assert len(said.splitlines()) == 1 and said.count("below the horizon") <= 1, said


# ------------------------------------------------------------------ what a notebook shows
def test_plot_gives_charts_a_notebook_draws(result):
    """A cell ending in result.plot() shows the charts: Charts renders each figure as a
    PNG in its HTML repr (a list of Figures printed reprs only)."""
    charts = result.plot()
    assert isinstance(charts, movingbase.Charts) and len(charts) == 3
    shown = charts._repr_html_()
    assert shown.count('<img src="data:image/png;base64,') == 3
    assert repr(charts).startswith(f"<Charts: 3 figures: {NAME}: leg error against time")


def test_a_run_plots_its_variables_with_their_units_and_its_status(result, cut_short, tmp_path):
    run = result["moving_base"]
    (figure,) = run.plot("plant.pose", "controller.leg_force")
    axes = figure.axes
    # the pose's components apart, named, each as its change from its start in the unit that
    # reads (z = -2.68 m once flattened x and y, and rotations were drawn in rad)
    labels = [a.get_ylabel() for a in axes]
    assert labels[:3] == ["plant.pose[1] x\n[mm, from 0 m]", "plant.pose[2] y\n[mm, from 0 m]",
                          "plant.pose[3] z\n[mm, from -2.6815 m]"], labels
    assert [label.split("\n")[0] for label in labels[3:]] == ["plant.pose[4] roll", "plant.pose[5] pitch",
                                                               "plant.pose[6] yaw", "controller.leg_force"]
    pose, scale = run["plant.pose"], {"mm": 1e-3, "µrad": 1e-6, "nrad": 1e-9}
    for k, ax in enumerate(axes[:6]):
        unit = ax.get_ylabel().split("[")[-1].split(",")[0]
        np.testing.assert_allclose(ax.get_lines()[0].get_ydata() * scale[unit], pose[:, k] - pose[0, k],
                                   rtol=1e-12, atol=0)
        assert 1 <= np.abs(ax.get_lines()[0].get_ydata()).max() < 1000      # the unit its largest change reads in
    np.testing.assert_array_equal(axes[6].get_lines()[0].get_xdata(), run.time)
    assert [l.get_label() for l in axes[6].get_lines()] == [f"[{k}]" for k in range(1, 7)]
    # without names: what the scenario's metrics read, each recorded
    default = run.plot()[0]
    assert "plant.leg_length\n[mm, from the start]" in [a.get_ylabel() for a in default.axes]
    failed = cut_short[0]["none"].plot("plant.pose")[0]
    assert failed.get_suptitle().startswith("run none: FAILED (cut_short")
    with pytest.raises(KeyError, match="no recorded variable 'pose'; did you mean 'plant.pose'"):
        run.plot("pose")
    with pytest.raises(KeyError, match="no recorded variable 'plant.leg_lenght'; did you mean 'plant.leg_length'"):
        run["plant.leg_lenght"]
    assert [p.name for p in run.plot("plant.pose").save(tmp_path / "c")] == ["moving_base_plant.pose.png"]
    assert [p.name for p in result.plot().save(tmp_path / "c")] == ["leg_error_vs_time.png", "pose_error_vs_time.png",
                                                                    "summary.png"]      # the report's names


def test_tables_hold_numbers_with_their_units(result):
    table = result.metrics_table()
    numbers = [c for c in table.columns if c not in (("status", ""), ("flags", ""))]
    assert all(table[c].dtype == float for c in numbers)
    assert table.attrs["units"][("leg error", "rms")] == "µm"
    assert table.attrs["units"][("pose error", "rotation_peak")] == "µrad"
    assert table.attrs["units"][("leg force", "peak")] == "kN"
    keys = ("rms", "peak", "path_rms", "efficiency_loss_22GHz", "efficiency_loss_43GHz")
    assert [table.attrs["units"][("pointing", k)] for k in keys] == ["arcsec"] * 2 + ["µm"] + ["%"] * 2
    assert set(table.attrs["units"]) == set(numbers)


def test_html_reprs_say_status_first(result, cut_short):
    shown = cut_short[0]._repr_html_()
    assert "3 runs: 3 failed: a flagged or failed run" in shown and shown.count("<td>failed</td>") == 3
    assert "leg error rms [µm]" in shown
    run = result["moving_base"]._repr_html_()
    assert "<b>run moving_base</b>" in run and "<td>µrad</td>" in run


def test_the_fmu_files_are_found_by_their_scenario_names():
    from fmpy import read_model_description
    found = movingbase.fmus("hexapod_plant", "telescope", fmi_version=3)
    assert [read_model_description(str(p)).fmiVersion for p in found.values()] == ["3.0", "3.0"]
    assert read_model_description(str(movingbase.fmus("wind")["wind"])).modelName == "Wind"
    assert set(movingbase.fmus(implementation="python")) == set(catalogue.KEYS)
    with pytest.raises(ValueError, match="no FMU 'hexapod'; did you mean 'hexapod_plant'"):
        movingbase.fmus("hexapod")
    with pytest.raises(ValueError, match="pythonfmu FMUs are FMI 2.0 only"):
        movingbase.fmus("wind", implementation="python", fmi_version=3)


def test_a_refusal_is_raised_from_the_public_call():
    """A notebook shows the call and the message, not the checks' 30-60 frames."""
    import traceback
    with pytest.raises(movingbase.ScenarioError) as raised:
        movingbase.run(NAME, ci=True, progress=False, set={"base.start_elevaton": "60 deg"})
    frames = traceback.extract_tb(raised.value.__traceback__)
    assert [f.name for f in frames][-1] == "public" and len(frames) <= 3, frames
    assert "did you mean 'start_elevation'" in str(raised.value)


def test_a_campaign_takes_numpy_s_integers_as_a_worker_count(tmp_path):
    """campaign(jobs=np.int64(1)) was refused: any integer type is a count."""
    result = movingbase.campaign("slew_sizes", ci=True, jobs=np.int64(1), out=tmp_path, progress=False)
    assert len(result) > 0 and set(result.table()["status"]) <= {"ok", "flagged"}


def test_an_interrupted_sweep_keeps_the_runs_that_finished(tmp_path, monkeypatch):
    """Ctrl-C during the second run of a three-run sweep: the first run's records, metrics
    and a report marked interrupted are on disk, the lock file is gone, and the message
    says what was kept and how to run the rest (it was an empty KeyboardInterrupt)."""
    interrupt_the_second_run(monkeypatch)
    with pytest.raises(KeyboardInterrupt) as stopped:
        movingbase.run(NAME, ci=True, progress=False, out=tmp_path)
    folder = tmp_path / NAME
    said = str(stopped.value)
    assert said.startswith(f"{NAME} interrupted during run 'fixed_base': runs finished: 'none': records, metrics.json "
                           f"and a report marked interrupted in {folder}")
    assert said.endswith("not run to their end: 'fixed_base', 'moving_base'; to run the rest: set={'sweep': "
                         "{'parameter': 'controller.feedforward', 'values': ['fixed_base', 'moving_base']}}")
    assert sorted(p.name for p in folder.iterdir() if p.suffix != ".png") == ["metrics.json", "none.npz", "report.md"]
    metrics = json.loads((folder / "metrics.json").read_text())
    assert list(metrics) == ["none"]
    report = (folder / "report.md").read_text()
    assert "**Interrupted** (Ctrl-C): runs `fixed_base`, `moving_base` were not run to their end" in report
    kept = stopped.value.result          # in Python too: a Result of the runs that finished
    assert list(kept.runs) == ["none"] and kept.report_path == folder / "report.md"
    # the kept run is the one an uninterrupted sweep gives (its first run), bit for bit
    monkeypatch.undo()
    whole = movingbase.run(NAME, ci=True, progress=False, set={"sweep": {"parameter": "controller.feedforward",
                                                                          "values": ["none"]}})
    assert metrics["none"]["metrics"] == json.loads(json.dumps(whole["none"].metrics, default=float))
    assert kept["none"].values.tobytes() == whole["none"].values.tobytes()
    assert read_records(folder / "none.npz").values.tobytes() == whole["none"].values.tobytes()


def test_a_slew_cut_by_its_stop_time_is_told_before_anything_runs(monkeypatch):
    """The profile is analytic: a 20 s cut of the shipped slew (it ends at 56.2 s, worked by
    hand in tests/scenarios/runs/test_flags.py) is warned of, naming the values set, before
    the first run starts (here it is stopped there)."""
    from scenarios.runs import single

    def stopped(*args, **kwargs):
        raise KeyboardInterrupt
    monkeypatch.setattr(single, "run", stopped)
    with pytest.warns(movingbase.RunWarning) as said, pytest.raises(KeyboardInterrupt):
        movingbase.run("telescope_slew", set={"stop_time": "20 s"}, progress=False)
    assert [str(w.message) for w in said] == [
        "telescope_slew (set={'stop_time': '20 s'}): runs 'none', 'fixed_base', 'moving_base' will be flagged "
        "motion_unfinished: the slew of 'base' has not ended at the stop time 20 s: the antenna still turns at "
        "0.583 deg/s; it ends at t = 56.2 s: stop_time >= 57 s"]


def test_labels_are_the_values_as_typed_but_in_file_names(tmp_path):
    """A kp sweep of "1.8e6 N/m": the runs are labelled as typed (result["1.8e6 N/m"], the
    tables, metrics.json, the legends); only the records' file name makes the '/' a '_'."""
    values = ["1.8e6 N/m", "2.2e6 N/m"]
    result = movingbase.run(NAME, ci=True, progress=False, out=tmp_path,
                            set={"sweep": {"parameter": "controller.kp", "values": values}})
    assert list(result.runs) == values and result["1.8e6 N/m"] is result[0]
    assert result["1.8e6 N/m"].run.record_path.name == "1.8e6 N_m.npz"
    folder = tmp_path / NAME
    assert list(json.loads((folder / "metrics.json").read_text())) == values
    assert sorted(p.name for p in folder.glob("*.npz")) == ["1.8e6 N_m.npz", "2.2e6 N_m.npz"]
    assert "| 1.8e6 N/m |" in (folder / "report.md").read_text()
    legend = [t.get_text() for t in result.plot()[0].legends[0].get_texts()]
    assert legend == values, legend
    if importlib.util.find_spec("pandas"):
        assert list(result.metrics_table().index) == values


def test_a_sampled_campaign_s_columns_follow_the_grid_s_unit_rule(tmp_path):
    """A sampled input's column was 'plant.payload_mass_error [kg]' while a grid column kept
    its unit in attrs: now both are named by their key, their unit in attrs; the numbers are
    the draws summary.csv holds."""
    pytest.importorskip("pandas")
    from scenarios.runs import campaign as campaigns
    path = tmp_path / "sampled.toml"
    path.write_text(f'scenario = "{campaigns.SHIPPED / "scenes" / "dynamic_budget.toml"}"\n'
                    'set = { stop_time = "1.05 s" }\n[sample]\nsamples = 2\nseed = 7\n'
                    '"plant.payload_mass_error" = { distribution = "normal", sd = "40 kg" }\n'
                    '"imu.imu_alignment" = { distribution = "uniform", half_width = "1 mrad" }\n')
    ran = movingbase.campaign(path, out=tmp_path / "out", jobs=1, progress=False)
    table = ran.table()
    sampled = ["plant.payload_mass_error"] + [f"imu.imu_alignment[{k}]" for k in (1, 2, 3)]
    assert [c for c in table.columns if c.startswith(("plant.", "imu."))] == sampled
    assert [table.attrs["units"][c] for c in sampled] == ["kg", "rad", "rad", "rad"]
    campaign = campaigns.load(path)
    for row, case in zip(table.to_dict("records"), campaign.cases):
        draws, _ = campaign.sample.draws(case.sample)
        assert row["plant.payload_mass_error"] == draws["plant.payload_mass_error"]


def test_builds_are_said_without_progress_bars_and_in_fmus(monkeypatch, capsys):
    """fmus() and run(progress=False) built for 25 s without a word (issue 39): a build's
    start is said on stderr whatever progress is (here a build stands in, logging as the
    builders do: fmu_src/python_build.py)."""
    import logging
    real = runner.BUILDS["native"]

    def building(scripts):
        logging.getLogger("movingbase.build").info("building %s", ", ".join(scripts))
        return real(scripts)
    monkeypatch.setitem(runner.BUILDS, "native", building)
    assert movingbase.fmus("telescope")["telescope"].name == "Telescope.fmu"
    assert capsys.readouterr().err == "building telescope_fmu\n"
    movingbase.load_scenario("paper_manoeuvre", ci=True)     # loading builds nothing
    movingbase.run("paper_manoeuvre", ci=True, progress=False, set={"sweep": {"parameter": "controller.feedforward",
                                                                              "values": ["none"]}})
    assert capsys.readouterr().err.splitlines() == ["building hexapod_plant_fmu, leg_controller_fmu, telescope_fmu"]


def test_every_mistake_of_set_is_told_at_once():
    """An unknown instance and the swept parameter in one set=: both told, not the first."""
    with pytest.raises(spec.ScenarioError) as refused:
        movingbase.load_scenario(NAME, set={"bsae.lever_arm": "5 m", "controller.feedforward": "none"})
    assert [(k, p[:40]) for _, k, p in refused.value.problems] == [
        ("set['bsae.lever_arm']", "unknown FMU instance 'bsae'; did you mea"),
        ("set['controller.feedforward']", "is the swept parameter; every run sets i")]
