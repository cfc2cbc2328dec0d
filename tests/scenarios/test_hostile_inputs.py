"""Issue 17 sections 2-3: inputs a user can produce that once ran with wrong results,
ended in a traceback or ran out of resources. Each class of defect is fed here and must
end in one clear error that names the file, the key and the problem (or, where the input
is valid, be accepted). The tables hold many inputs of each class."""
import os
import pathlib
import subprocess
import sys
import zipfile

import pytest

from movingbase import api
from scenarios import spec
from scenarios.cosim import fmi
from scenarios.cosim.fmi import unpack
from scenarios.runs import campaign, runner
from scenarios.runs import estimates as resources
from scenarios.spec import units
from scenarios.spec.units import to_si
from tests.scenario_helpers import SLEW, edited, refused

ROOT = pathlib.Path(__file__).resolve().parents[2]
HEAD = 'name = "t"\nscenario = "telescope_slew"\n'
SCRIPTS = {"base": "telescope_fmu", "plant": "hexapod_plant_fmu", "controller": "leg_controller_fmu"}


@pytest.fixture(scope="module")
def descriptions(fmus):
    return {inst: unpack(fmus[script])[0] for inst, script in SCRIPTS.items()}


def _cli(tmp_path, *args, command="run"):
    done = subprocess.run([sys.executable, "-m", "movingbase", command, *map(str, args)], capture_output=True,
                          text=True, cwd=tmp_path, timeout=600)
    assert "Traceback" not in done.stderr, done.stderr
    return done.returncode, done.stdout, done.stderr


# --------------------------------------------- scenario files: parse and bind refuse, naming
@pytest.mark.parametrize("changes, key, parts", [
    # a table, a number or a path where text belongs
    ([('name = "telescope_slew"', 'name = { a = 1 }')], "name", ("expected", "table")),
    ([('name = "telescope_slew"', 'name = 5')], "name", ("expected", "integer")),
    ([('name = "telescope_slew"', 'name = "../../etc/x"')], "name", ("'/'", "not a path")),
    ([('name = "telescope_slew"', f'name = "{"x" * 300}"')], "name", ("300 characters",)),
    ([('name = "telescope_slew"', 'name = ".hidden"')], "name", ("starts with .",)),
    ([('master = "jacobi"', 'master = { a = 1 }')], "master", ('expected "jacobi" or', "table")),
    ([('fmu = "leg_controller"', 'fmu = { x = 1 }')], "fmus.controller.fmu", ("expected text", "table")),
    ([('name = "leg error"', 'name = ["a"]')], "metrics[0].name", ("expected text", "array")),
    # the same metric name twice: the results' columns would collide after all runs
    ([('name = "pose error"', 'name = "leg error"')], "metrics[1].name", ("also the name of metrics[0]",)),
    # TOML nesting and integer literals beyond any setting
    ([("[ci]", "deep = " + "[" * 40 + "]" * 40 + "\n[ci]")], "deep" + "[0]" * 8, ("nested 9 levels", "at most 8")),
    ([("[ci]", "deep = " + "[" * 5000 + "]" * 5000 + "\n[ci]")], "TOML", ("nested deeper",)),
    ([('moving_base = 1', 'moving_base = ' + "9" * 5000)], "TOML", ("cannot be read", "digits")),
    ([('moving_base = 1', 'moving_base = ' + "9" * 30)], "fmus.plant.parameters.moving_base", ("too large",)),
    # an instance name that is not one, said so (not "expected 'instance.variable'")
    ([("[fmus.controller]", '[fmus."contrôleur"]'), ('"controller.', '"contrôleur.')],
     "fmus.contrôleur", ("'ô'", "ASCII letters")),
    # a sweep value that is a table
    ([('values = ["none", "fixed_base", "moving_base"]', 'values = ["none", { a = 1 }]')], "sweep.values[1]",
     ("expected a number or a quantity", "table")),
    # duplicate sweep values: as written, and the same value in two units
    ([('values = ["none", "fixed_base", "moving_base"]', 'values = ["none", "none"]')], "sweep.values[1]",
     ("repeats sweep.values[0]",)),
    # an unknown key in [ci] (the full run would run)
    ([("stop_time = \"8 s\"", "stop_tme = \"8 s\"")], "ci.stop_tme", ("did you mean 'stop_time'",)),
])
def test_bad_scenarios_are_refused_naming_key_and_problem(descriptions, changes, key, parts):
    refused(edited(SLEW, *changes), key, *parts, descriptions=descriptions)


def test_every_problem_of_a_file_is_reported_at_once_with_the_nearest_key(descriptions):
    text = edited(SLEW, ('step = "1 ms"', 'stpe = "1 ms"'), ('master = "jacobi"', 'master = "jacoby"'),
                  ('fmu = "leg_controller"', 'fmu = "leg_controler"'))
    with pytest.raises(spec.ScenarioError) as error:
        spec.parse(text, "bad.toml")
    message = str(error.value)
    assert "stpe: unknown key; did you mean 'step'?" in message
    assert "bad.toml: step: missing" in message
    text = edited(SLEW, ('master = "jacobi"', 'master = "jacoby"'), ('fmu = "leg_controller"', 'fmu = "leg_controler"'),
                  ('interval = "10 ms"', 'interval = "10 ms"\nevery = 2'))
    with pytest.raises(spec.ScenarioError) as error:
        spec.parse(text, "bad.toml")
    lines = str(error.value).splitlines()
    assert len(lines) == 3, lines
    assert any("master: unknown master 'jacoby'" in line for line in lines)
    assert any("fmus.controller.fmu" in line and "did you mean 'leg_controller'" in line for line in lines)
    assert any("record.every: unknown key" in line for line in lines)


def test_a_cutoff_above_the_nyquist_frequency_is_refused(fmus):
    """A filter's cut-off above 1/(2 step) cannot be run by a sampled filter: the sensor
    would run a different filter than the one asked for."""
    text = (ROOT / "scenarios/files/telescope_slew_base_sources.toml").read_text()
    scenario = spec.parse(text, "bad.toml")
    paths = runner.fmu_paths(scenario)
    md = {inst: unpack(p)[0] for inst, p in paths.items()}
    sensor = next(i for i, f in scenario.fmus.items() if f == "base_sensor")
    nyquist = 0.5 / scenario.step
    below = spec.parse(text, "ok.toml")
    below.parameters[sensor]["rate_cutoff"] = f"{0.9 * nyquist} Hz"
    spec.bind(below, md)
    above = spec.parse(text, "bad.toml")
    above.parameters[sensor]["rate_cutoff"] = f"{1.1 * nyquist} Hz"
    with pytest.raises(spec.ScenarioError, match=f"fmus.{sensor}.parameters.rate_cutoff: .* above the Nyquist"):
        spec.bind(above, md)


def test_parameter_links_that_form_a_cycle_are_refused():
    values = {"a": {"x": spec.Link("b", "y")}, "b": {"z": spec.Link("c", "w")}, "c": {"v": spec.Link("a", "u")}}
    with pytest.raises(spec.ScenarioError, match=r"parameter links form a cycle: a <- b <- c <- a"):
        spec.check_links("bad.toml", values)
    spec.check_links("ok.toml", {"a": {"x": spec.Link("b", "y")}, "b": {}, "c": {"v": spec.Link("b", "w")}})


def test_the_same_sweep_value_in_two_units_is_refused(descriptions):
    text = edited(SLEW, ('parameter = "controller.feedforward"', 'parameter = "base.lever_arm"'),
                  ('values = ["none", "fixed_base", "moving_base"]', 'values = ["25 m", "25000 mm"]'))
    refused(text, "sweep.values[1]", "same value as sweep.values[0]", descriptions=descriptions)


def test_sweep_values_become_plain_file_names():
    assert spec.file_label("10 N/m") == "10 N_m"
    assert spec.file_label("../../x") == ".._.._x"
    assert spec.file_label(0.5) == "0.5"
    for label in map(spec.file_label, ("a/b", "c\\d", "x\0y", "é", "a" * 500)):
        assert "/" not in label and "\0" not in label and len(label) <= 100 and label.isascii()


# ------------------------------------------------------------------ files that are not scenarios
def test_files_that_are_not_scenarios_are_refused_naming_what_they_are(tmp_path):
    cases = {"/dev/zero": "not a regular file"}
    (tmp_path / "utf16.toml").write_text('name = "x"\n', encoding="utf-16")
    cases[tmp_path / "utf16.toml"] = "is UTF-16 text; save it as UTF-8"
    (tmp_path / "utf16le.toml").write_bytes('name = "x"\n'.encode("utf-16-le"))
    cases[tmp_path / "utf16le.toml"] = "is UTF-16 text"
    (tmp_path / "huge.toml").write_bytes(b"# " + b"x" * (spec.MAX_FILE_BYTES + 10))
    cases[tmp_path / "huge.toml"] = "larger than 1 MiB"
    for path, part in cases.items():
        with pytest.raises(spec.ScenarioError, match=part):
            spec.load(path)
        with pytest.raises(campaign.CampaignError, match=part):
            campaign.load(path)


def test_a_partial_ci_table_changes_only_its_instance(descriptions):
    """[ci.fmus.plant.parameters] once replaced every [fmus] table, and the error then
    spoke of another instance; it now merges key by key."""
    text = edited(SLEW, ('stop_time = "8 s"', 'stop_time = "8 s"\n[ci.fmus.plant.parameters]\nmoving_base = 0'))
    scenario = spec.parse(text, "ok.toml")
    short = spec.parse(text, "ok.toml", overrides=scenario.ci)
    assert short.parameters["plant"]["moving_base"] == 0 and set(short.fmus) == set(scenario.fmus)
    assert short.parameters["plant"]["integrator"] == "rk4" and short.stop_time == 8.0
    bad = edited(SLEW, ('stop_time = "8 s"', 'stop_time = "8 s"\n[ci.fmus.plant.parameters]\nmoving_bse = 0'))
    refused(bad, "fmus.plant.parameters.moving_bse", "no variable", descriptions=descriptions,
            overrides=spec.parse(bad, "bad.toml").ci)


# ------------------------------------------------------------------ valid input accepted
def test_the_variables_own_unit_and_micro_prefixes_are_accepted(fmus):
    wind = {v.name: v for v in unpack(fmus["wind_fmu"])[0].modelVariables}
    assert wind["air_density"].unit == "kg/m3"
    assert spec._value("ok.toml", "k", wind["air_density"], "1.225 kg/m3") == 1.225
    for written in ("100 µs", "100 μs", "100 us"):
        assert to_si(written, "s") == pytest.approx(1e-4, rel=1e-15)
    scenario = spec.parse(edited(SLEW, ('step = "1 ms"', 'step = "100 µs"')), "ok.toml")
    assert scenario.step == pytest.approx(1e-4) and round(scenario.record_interval / scenario.step) == 100


# ------------------------------------------------------------------ resources
def test_resources_are_estimated_and_what_cannot_finish_is_refused(tmp_path):
    slew = spec.parse(SLEW, "slew.toml")
    cost = resources.estimate(slew)
    assert cost.steps == 60_000 and cost.rows == 6001       # (60 s / 1 ms) steps, every 10 ms plus t = 0
    # the time itself, pinned: 3 native instances at 4.7 us per step each (issue 21's 30 s slew at
    # 1 ms: 0.42 s), 35 us per recorded row: 60,000 x 14.1 us + 6,001 x 35 us = 1.056 s; a factor
    # off (1000x too small was reached only through the disk estimate) fails here
    assert cost.seconds == pytest.approx(60_000 * 3 * 4.7e-6 + 6001 * 35e-6, rel=1e-12)
    assert cost.seconds == pytest.approx(1.056, abs=1e-3)
    python = dataclass_copy(slew, implementations={"plant": "python"})
    assert resources.estimate(python).seconds == pytest.approx(60_000 * (2 * 4.7e-6 + 30e-6) + 6001 * 35e-6)
    assert resources.check(cost, tmp_path, "slew.toml") == ""
    long = spec.parse(edited(SLEW, ('stop_time = "60 s"', 'stop_time = "1e9 s"')), "long.toml")
    with pytest.raises(resources.ResourceError, match=r"1e\+12|1,000,000,000,000 steps"):
        resources.check(resources.estimate(long), tmp_path, "long.toml")
    fine = spec.parse(edited(SLEW, ('step = "1 ms"', 'step = "1e-9 s"'), ('interval = "10 ms"', 'interval = "1 s"')),
                      "fine.toml")
    assert "large" in resources.check(resources.estimate(fine), tmp_path, "fine.toml")
    small = dataclass_copy(cost, disk_bytes=2 * resources.free_bytes(tmp_path))
    with pytest.raises(resources.ResourceError, match="free under"):
        resources.check(small, tmp_path, "x")


def test_a_campaign_s_cost_is_its_runs_at_their_own_stop_time(tmp_path):
    """A campaign's estimate once ignored its own set.stop_time: it refused a small valid
    campaign for disk and passed one that ran out of memory in a worker."""
    path = tmp_path / "c.toml"
    path.write_text('name = "c"\nscenario = "telescope_slew"\nset = { stop_time = "12 s" }\n'
                    '[[grid]]\n"base.lever_arm" = ["5 m", "10 m"]\n')
    made = campaign.CampaignJobs(campaign.load(path))
    cost = made.cost()
    one = resources.estimate(spec.parse(edited(SLEW, ('stop_time = "60 s"', 'stop_time = "12 s"')), "x.toml"),
                             made._bind({})[2])
    assert (cost.runs, cost.steps, cost.rows) == (6, 12_000, 1201)     # 2 lever arms x the 3-mode sweep
    assert cost.seconds == pytest.approx(6 * one.seconds, rel=1e-12)
    assert cost.disk_bytes == 0 and cost.run_bytes == one.run_bytes   # keeps no records; one run's memory


def dataclass_copy(obj, **changes):
    import dataclasses
    return dataclasses.replace(obj, **changes)


def test_a_long_run_is_refused_quickly_by_the_cli(tmp_path):
    """stop_time = "1e9 s": once, the check itself allocated 7 GiB."""
    path = tmp_path / "long.toml"
    path.write_text(edited(SLEW, ('stop_time = "60 s"', 'stop_time = "1e9 s"')))
    status, _, err = _cli(tmp_path, path, "--quiet", "--out", tmp_path / "out")
    assert status != 0 and "would not finish" in err or "free under" in err, err


@pytest.mark.parametrize("jobs, part", [(0, "at least 1"), (-2, "at least 1"), (10 ** 6, "of memory")])
def test_bad_worker_counts_are_refused(jobs, part):
    with pytest.raises(resources.ResourceError, match=part):
        resources.check_jobs(jobs)


def test_a_huge_grid_is_refused_before_its_runs_are_made(tmp_path):
    axes = "".join(f'[[grid]]\n"base.lever_arm" = [{", ".join(f"{i + 1}" for i in range(20))}]\n' for _ in range(1))
    axes += "".join(f'[[grid]]\n"base.start_delay{k}" = [{", ".join(str(i) for i in range(10))}]\n'
                    for k in range(6))
    path = tmp_path / "c.toml"
    path.write_text(HEAD + axes)
    with pytest.raises(campaign.CampaignError, match="20,000,000 runs"):
        campaign.load(path)


# ------------------------------------------------------------------ campaigns: silent wrong results
@pytest.mark.parametrize("body, key, problem", [
    ('[[grid]]\n"base.lever_arm" = ["20 m", "30 m"]\n[[grid]]\n"base.lever_arm" = ["40 m", "50 m"]\n',
     "grid[1].base.lever_arm", "also set in grid[0]"),
    ('set = { "base.lever_arm" = "20 m" }\n[grid]\n"base.lever_arm" = ["40 m", "50 m"]\n',
     "grid[0].base.lever_arm", "also set in set"),
    ('[grid]\n"base.lever_arm" = ["40 m", "50 m"]\n[[cases]]\n"base.lever_arm" = "20 m"\n',
     "cases[0].base.lever_arm", "also set in grid[0]"),
    ('[grid]\n"base.lever_arm" = ["40 m", "50 m", "40 m"]\n', "grid[0].base.lever_arm[2]", "already value [0]"),
    ('set = { "controller.leg_length" = [2.6, 2.6, 2.6, 2.6, 2.6, 2.6] }\n', "set.controller.leg_length",
     "an input that telescope_slew.toml connects"),
    ('[ci]\nstop_time = "8 s"\n', "ci.stop_time", "unknown key"),
    ('nmae = "x"\n', "nmae", "did you mean 'name'"),
    ('name = "a/b"\n', "name", "not a path"),
    ('name = 7\n', "name", "expected text"),
])
def test_campaign_inputs_that_ran_wrongly_are_refused(tmp_path, body, key, problem):
    path = tmp_path / "c.toml"
    path.write_text(HEAD.replace('name = "t"\n', "") + body if body.startswith("name") else HEAD + body)
    with pytest.raises(campaign.CampaignError) as info:
        campaign.load(path)
    message = str(info.value)
    assert message.startswith(f"{path}: {key}: ") and problem in message, message


# ------------------------------------------------------------------ command line and output folders
def test_command_line_inputs_are_refused_before_anything_runs(tmp_path):
    (tmp_path / "file").write_text("x")
    for args, part in [(("--jobs", "0"), "at least 1"), (("--jobs", "-3"), "at least 1"),
                       (("--dask", "tcp://127.0.0.1:9"), "no scheduler answers"),
                       (("--dask", "nonsense"), "tcp://HOST:PORT"),
                       (("--ssp", tmp_path), "is a folder"),
                       (("telescope_slew",), "named more than once")]:
        status, _, err = _cli(tmp_path, "telescope_slew", *args)
        assert status != 0 and part in err, (args, err)
    status, _, err = _cli(tmp_path, "telescope_slew", "--ci", "--quiet", "--out", tmp_path / "file")
    assert status != 0 and "is a file, not a folder" in err, err
    status, _, err = _cli(tmp_path, "sky_slews", "--jobs", "0", command="campaign")
    assert status != 0 and "at least 1" in err, err


def test_output_folders_follow_the_file_run_and_say_what_they_replace(tmp_path, capsys):
    mine = tmp_path / "my_slew.toml"
    mine.write_text(SLEW)           # a copy: its name is still "telescope_slew"
    assert runner.output_folder(tmp_path / "out", runner.resolve(str(mine))) == tmp_path / "out" / "my_slew"
    folder = runner.output_folder(tmp_path / "out", runner.SHIPPED / "telescope_slew.toml")
    assert folder == tmp_path / "out" / "telescope_slew" and runner.replaced(folder) == ""
    (folder / "report.md").write_text("earlier")
    assert "report.md" in runner.replaced(folder) and "replaces" in runner.replaced(folder)
    other = tmp_path / "sub" / "telescope_slew.toml"
    other.parent.mkdir()
    other.write_text(SLEW)
    status, _, err = _cli(tmp_path, "telescope_slew", other, "--out", tmp_path / "o")
    assert status != 0 and "would all write to" in err, err


@pytest.mark.skipif(os.geteuid() == 0, reason="root writes anywhere")
def test_a_read_only_output_folder_is_refused(tmp_path):
    (tmp_path / "ro").mkdir(mode=0o555)
    with pytest.raises(runner.OutputError, match="not writable|cannot be created"):
        runner.output_folder(tmp_path / "ro", "x.toml")


# ------------------------------------------------------------------ FMU files
def test_fmu_paths_that_are_not_fmus_are_refused_naming_the_problem(fmus, tmp_path, monkeypatch):
    good = pathlib.Path(fmus["leg_sensor_fmu"])
    truncated = tmp_path / "truncated.fmu"
    truncated.write_bytes(good.read_bytes()[: good.stat().st_size // 2])
    (tmp_path / "text.fmu").write_text("not a zip")
    with zipfile.ZipFile(tmp_path / "empty.fmu", "w") as archive:
        archive.writestr("other.txt", "x")
    for path, part in [(tmp_path, "is a folder"), (tmp_path / "none.fmu", "does not exist"),
                       (tmp_path / "text.fmu", "not a readable zip"), (truncated, "not a readable zip"),
                       (tmp_path / "empty.fmu", "no modelDescription.xml")]:
        with pytest.raises(fmi.FmuFileError, match=part):
            fmi.unpack(path)
    monkeypatch.setattr(fmi, "MAX_MEMBER_BYTES", 1000)    # the size the listing declares, not extracted
    with pytest.raises(fmi.FmuFileError, match="unpacks to .* GiB"):
        fmi.check_file(good)


def test_unpacked_fmus_are_removed_when_the_process_ends(fmus, tmp_path):
    """Without the cache of unpacked FMUs (MOVINGBASE_FMU_CACHE=off), or when it cannot be
    written, a process unpacks into a folder of its own, which goes when it ends."""
    import os
    code = ("import sys; from scenarios.cosim.fmi import unpack; "
            f"print(unpack({str(fmus['leg_sensor_fmu'])!r})[1])")
    folder = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True,
                            env={**os.environ, "MOVINGBASE_FMU_CACHE": "off"}).stdout.strip()
    assert folder and not pathlib.Path(folder).exists()


# ------------------------------------------------------------------ Ctrl-C
def _interrupted(tmp_path, args, ready):
    """The command's (exit status, stderr) after Ctrl-C (SIGINT to its whole process
    group, as a terminal sends it) once its stderr shows ``ready``."""
    import signal
    import threading
    import time
    # SIGINT at its default in the child: a test run started in the background (`cmd &`, nohup)
    # ignores SIGINT, the child would inherit that, and Python then installs no Ctrl-C handler
    command = args if args[0] == sys.executable else [sys.executable, "-m", "movingbase", *map(str, args)]
    process = subprocess.Popen(command, cwd=tmp_path,
                               stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, start_new_session=True,
                               preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    chunks = []
    reader = threading.Thread(target=lambda: chunks.extend(iter(lambda: process.stderr.read1(4096), b"")))
    reader.start()
    deadline = time.monotonic() + 300
    while ready not in b"".join(chunks) and process.poll() is None and time.monotonic() < deadline:
        time.sleep(0.1)
    time.sleep(1.0)
    os.killpg(process.pid, signal.SIGINT)
    process.wait(timeout=120)
    reader.join()
    return process.returncode, b"".join(chunks).decode(errors="replace")


def test_ctrl_c_on_a_sweep_and_a_campaign_ends_in_one_clear_line(tmp_path):
    long_slew = tmp_path / "long_slew.toml"    # 10 min of slew: each run lasts seconds, so the Ctrl-C lands in one
    long_slew.write_text((runner.SHIPPED / "telescope_slew.toml").read_text().replace('stop_time = "60 s"',
                                                                                      'stop_time = "600 s"', 1))
    status, err = _interrupted(tmp_path, ["run", long_slew, "--out", tmp_path / "o"], b"[fixed_base]")
    assert status != 0 and "Traceback" not in err and "KeyboardInterrupt" not in err, err
    assert err.strip().splitlines()[-1].startswith("interrupted:"), err
    status, err = _interrupted(tmp_path, ["campaign", "sky_slews", "--jobs", "2", "--out", tmp_path / "c"],
                               b"on disk)")     # the progress bar: the workers are up
    assert status != 0 and "Traceback" not in err and "KeyboardInterrupt" not in err, err
    assert [line for line in err.splitlines() if "interrupted" in line] == [
        "interrupted: the runs finished so far are on disk; run the same command again to resume"], err


def test_ctrl_c_on_a_campaign_from_python_raises_keyboard_interrupt(tmp_path):
    """movingbase.campaign() interrupted once returned normally, its runs 'not run'; now it
    raises KeyboardInterrupt (as Python's own calls do) saying where the finished runs are."""
    script = tmp_path / "script.py"
    script.write_text("import movingbase\nif __name__ == '__main__':\n"
                      f"    movingbase.campaign('sky_slews', jobs=2, out={str(tmp_path / 'c')!r})\n"
                      "    print('returned normally')\n")
    status, err = _interrupted(tmp_path, [sys.executable, str(script)], b"on disk)")
    assert status != 0 and "returned normally" not in err, err
    last = err.strip().splitlines()[-1]
    assert last.startswith("KeyboardInterrupt: campaign sky_slews interrupted: ") and "call it again to resume" in last


def test_a_campaign_from_a_script_without_a_main_guard_says_the_rule(tmp_path):
    """The workers import the script and start the campaign again: 'Nanny failed to start'
    after a hundred lines of the workers' tracebacks. Now the rule, in a few lines."""
    (tmp_path / "c.toml").write_text('name = "ng"\nscenario = "paper_manoeuvre"\nset = { stop_time = "2.5 s" }\n'
                                     '[[grid]]\n"base.lever_arm" = ["0 m", "5 m"]\n')
    (tmp_path / "script.py").write_text("import movingbase\nmovingbase.campaign('c.toml', jobs=2, progress=False)\n")
    done = subprocess.run([sys.executable, "script.py"], cwd=tmp_path, capture_output=True, text=True, timeout=300)
    assert done.returncode != 0
    assert 'call the campaign under `if __name__ == "__main__":`' in done.stderr.splitlines()[-1], done.stderr
    assert "Nanny failed to start" not in done.stderr.splitlines()[0] and len(done.stderr.splitlines()) < 40


def test_every_bad_value_of_a_campaign_is_reported_at_once(tmp_path):
    path = tmp_path / "c.toml"
    path.write_text(HEAD + 'set = { "base.colour" = 1 }\n[grid]\n"base.start_azimuth" = ["10 deg", "3 kg"]\n'
                    '[[cases]]\n"controller.feedforward" = "sometimes"\n')
    with pytest.raises(campaign.CampaignError) as info:
        campaign.load(path)
    lines = str(info.value).splitlines()
    assert [line.split(": ", 2)[1] for line in lines] == [
        "set.base.colour", "grid[0].base.start_azimuth[1]", "cases[0].controller.feedforward"], lines


# ------------------------------------------------------------------ hunted later (branch hostile3)
@pytest.mark.parametrize("link", ["@", "@base", "@.x", "@base.", "@ base.axis", "@@base.axis", "@nope.axis"])
def test_a_link_that_is_no_instance_output_is_refused_naming_it(descriptions, link):
    """'@base', '@' and '@nope.x' once ended in a ValueError or KeyError traceback."""
    refused(edited(SLEW, ('lever_arm = "25 m"', f'lever_arm = "{link}"')), "fmus.base.parameters.lever_arm",
            "'@instance.output'" if link != "@nope.axis" else "unknown FMU instance 'nope'", descriptions=descriptions)


@pytest.mark.parametrize("stop", ["1e-300 s", "1e-13 s"])
def test_a_stop_time_within_one_step_of_the_start_is_refused(stop):
    """1e-300 s at 1 ms passed the whole-number check (1e-297 steps rounds to 0): a run of
    no step, refused by the telescope model as 't must be strictly increasing'."""
    text = edited(SLEW, ('stop_time = "60 s"', f'stop_time = "{stop}"'))
    refused(text, "stop_time", f"'{stop}' is less than one step ('1 ms')", "first valid stop time is 0.001 s")


@pytest.mark.parametrize("changes, key", [
    ([('step = "1 ms"', 'step = "1 ms"\nstart_time = "1e12 s"'), ('stop_time = "60 s"',
                                                                  'stop_time = "1000000000060 s"')],
     "stop_time"),
    ([('step = "1 ms"', 'step = "1 ms"\nstart_time = "-1e10 s"')], "start_time"),
    ([('stop_time = "60 s"', 'stop_time = "1e20 s"')], "stop_time"),
])
def test_times_beyond_what_a_double_resolves_at_the_step_are_refused(changes, key):
    """At t = 1e12 s a double resolves 0.12 ms: a 1 ms grid there is uneven by 12 %, silently."""
    message = refused(edited(SLEW, *changes), key, "is resolved only to", "too coarse for step '1 ms'")
    start = spec.parse(edited(SLEW, ('step = "1 ms"', 'step = "1 ms"\nstart_time = "1e6 s"'),
                              ('stop_time = "60 s"', 'stop_time = "1000060 s"')), "ok.toml").start_time
    assert start == 1e6 and "8.59e+09 s" in message     # within the limit runs; the limit is said


@pytest.mark.parametrize("values, what", [
    ('["a", "A"]', "would write the same files (A.npz)"),                       # one file on macOS and Windows
    (f'["{"x" * 100}1", "{"x" * 100}2"]', "would write the same files"),        # labels are cut at 100
    ('["a/b", "a_b"]', "would write the same files (a_b.npz)"),
])
def test_sweep_values_whose_files_would_collide_are_refused(values, what):
    text = edited(SLEW, ('values = ["none", "fixed_base", "moving_base"]', f"values = {values}"))
    refused(text, "sweep.values[1]", what, "sweep.values[0]")


def test_a_column_recorded_twice_and_a_metric_of_a_parameter_are_refused(descriptions):
    R = 'variables = ["base.axis", "base.axis_rate"'
    refused(edited(SLEW, (R, 'variables = ["base.axis", "base.axis[1]"')), "record.variables",
            "base.axis[1] is recorded twice ('base.axis' and 'base.axis[1]')", descriptions=descriptions)
    refused(edited(SLEW, ('variable = "controller.leg_force"', 'variable = "base.lever_arm"')), "metrics[2].variable",
            "base.lever_arm is a parameter (fixed for the run)", descriptions=descriptions)
    refused(edited(SLEW, ('measured = "plant.pose"', 'measured = "plant.initial_pose"')), "metrics[1].measured",
            "plant.initial_pose is a parameter", descriptions=descriptions)


def test_ci_values_are_told_as_the_ci_table_s(tmp_path):
    """A bad value in [ci] was told as if the file's top-level key held it ("stop_time: ..."
    where the file says 60 s), and a [ci.fmus.<typo>] table added an FMU instance to the CI run."""
    for ci, key, part in [('step = "x"', "step", "cannot read quantity 'x'"),
                          ('name = "../x"', "name", "not a path"),
                          ('[ci.fmus.base.parameters]\nlever_arm = "-1 m"', "fmus.base.parameters.lever_arm",
                           "outside the range"),
                          ('[ci.sweep]\nvalues = ["bogus"]', "sweep.values[0]", "'bogus' is not one of"),
                          ('[ci.fmus.bsae]\nfmu = "telescope"', "ci.fmus.bsae", "did you mean 'base'")]:
        path = tmp_path / "x.toml"
        path.write_text(edited(SLEW, ('[ci]', f'[ci]\n{ci}\n' if not ci.startswith("[") else f'{ci}\n[ci]')))
        with pytest.raises(spec.ScenarioError) as error:
            runner.prepare(path, ci=True)
        message = str(error.value)
        assert message.startswith(f"{path}: {key}: ") and part in message, message
        assert key.startswith("ci.") or message.endswith("(the value of [ci], for --ci)"), message


def test_odd_scenario_names_and_output_folders_are_refused_naming_them(tmp_path):
    """"", "." and "/" once ended in a pathlib traceback; a file named "...toml" wrote its
    results into the parent of --out, "..toml" into --out itself; --out "" into the
    current folder; --ssp under a file said its folder "does not exist"."""
    dots = tmp_path / "d"
    dots.mkdir()
    (dots / "...toml").write_text(SLEW)
    (tmp_path / "file").write_text("x")
    for args, part in [(("",), "an empty scenario name"), ((".",), "is a directory"), (("/",), "is a directory"),
                       ((dots / "...toml", "--ci", "--out", dots / "o"), "cannot name its output folder"),
                       (("telescope_slew", "--ci", "--out", ""), "output folder (--out, out=, report()) is empty"),
                       (("telescope_slew", "--ssp", tmp_path / "file" / "x.ssp"), "file is a file, not a folder"),
                       (("telescope_slew", "--dask", ""), "expected a scheduler address")]:   # ran locally
        status, _, err = _cli(tmp_path, *args, "--quiet", "--charts", "none")
        assert status != 0 and part in err, (args, err)
    assert sorted(p.name for p in dots.iterdir()) == ["...toml"] and not (tmp_path / "telescope_slew").exists()
    (tmp_path / "A.toml").write_text(SLEW)     # one folder on a case-insensitive disk
    (tmp_path / "a.toml").write_text(SLEW)
    status, _, err = _cli(tmp_path, "A.toml", "a.toml", "--quiet")
    assert status != 0 and "would all write to" in err, err


def test_a_file_name_of_spaces_and_accents_names_its_scenario(tmp_path):
    """The output folder follows the file, so its name needs no check: 'my slew.toml' without
    a name key was refused ("holds ' '") though the same file with one ran into 'out/my slew'."""
    text = edited(SLEW, ('name = "telescope_slew"\n', ''))
    for stem in ("my slew", "élan"):
        assert spec.parse(text, f"{stem}.toml").name == stem
        assert runner.output_folder(tmp_path, f"{stem}.toml") == tmp_path / stem
        (tmp_path / f"{stem}.toml").write_text(text)       # and as a Scenario object in Python
        assert api.load_scenario(api.load_scenario(tmp_path / f"{stem}.toml")).name == stem
    refused(edited(SLEW, ('name = "telescope_slew"', 'name = "my/slew"')), "name", "not a path")


@pytest.mark.parametrize("value, problem", [
    ("−1 ms", "the minus sign '−' is not '-'"), ("1,5 ms", "a decimal point"), ("1_000 us", "digits without '_'"),
    ("nan s", "'nan s' is not a finite number"), ("-inf ms", "is not a finite number"),
])
def test_quantities_with_look_alike_characters_say_which(value, problem):
    with pytest.raises(units.UnitError, match=problem):
        to_si(value, "s")


def test_a_huge_step_count_is_told_in_few_digits():
    text = resources.Estimate(3, 10 ** 300, 10, 5, 1e300, 1e300).text()
    assert "1e+300 steps" in text and len(text) < 200, text


@pytest.mark.parametrize("parameter, values, problem", [
    # a connected input: the connection set it in every run, the runs were labelled by values that did not run
    ("controller.leg_length[1]", '["2.6 m", "2.7 m"]', "is an input that connections[6] (plant.leg_length -> "
                                                     "controller.leg_length) feeds"),
    ("plant.leg_length[1]", '["2.6 m", "2.7 m"]', "is an output, not a parameter or input"),
    # a vector: only its first element was set
    ("plant.initial_pose", '["0 m", "0.1 m"]', "has 6 values; a sweep sets one: name an element"),
])
def test_a_sweep_of_what_no_value_can_set_is_refused(descriptions, parameter, values, problem):
    text = edited(SLEW, ('parameter = "controller.feedforward"', f'parameter = "{parameter}"'),
                  ('values = ["none", "fixed_base", "moving_base"]', f"values = {values}"))
    refused(text, "sweep.parameter", problem, descriptions=descriptions)
    unconnected = edited(SLEW, ('parameter = "controller.feedforward"', 'parameter = "plant.platform_wrench[1]"'),
                         ('values = ["none", "fixed_base", "moving_base"]', 'values = ["0 N", "1 N"]'))
    assert spec.bind(spec.parse(unconnected, "ok.toml"), descriptions)      # an input nothing feeds: its start value


def test_a_scenario_of_no_fmu_and_an_instance_without_fmu_are_refused():
    refused('stop_time = "1 s"\nstep = "1 ms"\nconnections = []\nfmus = {}\n', "fmus", "no FMU instance")
    refused('stop_time = "1 s"\nstep = "1 ms"\nconnections = []\n[fmus.x]\n', "fmus.x.fmu",
            "missing: which of the kit's FMUs this instance is")


def test_an_unknown_variable_suggests_the_nearest(descriptions):
    refused(edited(SLEW, ('lever_arm = "25 m"', 'lever_arn = "25 m"')), "fmus.base.parameters.lever_arn",
            "has no variable 'lever_arn'; did you mean 'lever_arm'?", descriptions=descriptions)
    refused(edited(SLEW, ('measured = "plant.leg_length"', 'measured = "plant.leg_lenght"')), "metrics[0].measured",
            "did you mean 'leg_length'?", descriptions=descriptions)


@pytest.mark.parametrize("name, problem", [
    ("../../evil", "holds '/'"),            # its chart was written two folders above the run's folder, outside --out
    ("a|b", "holds '|'"), ("", "is empty"), (".x", "starts with ."),
    ("pose_error", "'pose error' would write the chart file of metrics[0] ('pose_error')"),   # pose_error_vs_time.png
    ("Pose Error", "would write the chart file of metrics[0] ('Pose Error')"),                # on macOS and Windows
])
def test_a_metric_name_that_is_no_file_name_of_its_own_is_refused(name, problem):
    key = "metrics[1].name" if "chart file" in problem else "metrics[0].name"
    refused(edited(SLEW, ('name = "leg error"', f'name = "{name}"')), key, problem)


def test_a_negative_fidelity_tolerance_is_refused():
    """fidelity = "auto" with a negative tolerance ended in StopIteration (no level within it)."""
    text = edited(SLEW, ('fidelity = "full"', 'fidelity = "auto"'), ('step = "1 ms"',
                                                                     'step = "1 ms"\nfidelity_tolerance = "-1 N"'))
    message = refused(text, "fidelity_tolerance", "'-1 N' is negative")
    assert len(message.splitlines()) == 1, message      # not also "auto needs a fidelity_tolerance"


def test_build_and_headline_folders_that_are_none_are_refused_naming_them(tmp_path):
    """`movingbase build --out FILE` and `movingbase headline --from DIR` without the full
    runs ended in tracebacks (FileExistsError, FileNotFoundError)."""
    (tmp_path / "file").write_text("x")
    status, _, err = _cli(tmp_path, "--out", tmp_path / "file", command="build")
    assert status == 1 and f"build error: {tmp_path / 'file'}: is a file, not a folder" in err, err
    status, _, err = _cli(tmp_path, "--from", tmp_path / "nope", command="headline")
    assert status == 1 and "headline error: " in err and "No such file or directory" in err, err


def test_files_an_earlier_run_left_that_this_one_did_not_rewrite_are_named(tmp_path):
    """A run with --charts none into the folder of one with charts said "this run replaces
    them" and left the earlier run's charts beside its own report, unsaid."""
    status, _, err = _cli(tmp_path, "paper_manoeuvre", "--ci", "--quiet", "--out", tmp_path / "o")
    assert status == 0 and "not this run's" not in err, err
    charts = sorted(p.name for p in (tmp_path / "o" / "paper_manoeuvre").glob("*.png"))
    status, _, err = _cli(tmp_path, "paper_manoeuvre", "--ci", "--quiet", "--charts", "none", "--out", tmp_path / "o")
    assert status == 0 and charts and all(name in err for name in charts) and "are not this run's" in err, err
    assert "metrics.json" not in err.splitlines()[-1] and "report.md" not in err.splitlines()[-1], err


@pytest.mark.parametrize("make, said", [
    (lambda d: (d / "out").symlink_to(d / "nowhere"), "out is a symbolic link to "),
    (lambda d: (d / "out").symlink_to(d / "out"), "out is a symbolic link in a loop, not a folder"),
    (lambda d: (d / "out").write_text(""), "out is a file, not a folder")])
def test_an_output_folder_behind_a_dangling_link_or_a_loop_is_refused_naming_it(make, said, tmp_path):
    # --out or report() onto a dangling symlink or a symlink loop ended in a bare StopIteration
    make(tmp_path)
    for folder in (tmp_path / "out", tmp_path / "out" / "deeper"):
        with pytest.raises(runner.OutputError, match=f"output folder {folder}: {tmp_path / said}"):
            runner.make_folder(folder)


def test_a_very_long_path_is_shortened_in_messages_and_kept_whole_in_the_error(tmp_path):
    # a 4,000-character path was echoed back whole (twice per line): 7,290 characters
    path = "/tmp/" + "a" * 250 + "/" + ("c" * 200 + "/") * 19 + "x.toml"
    with pytest.raises(spec.ScenarioError) as refused:
        api.load_scenario(path)
    text = str(refused.value)
    assert len(path) > 4000 and len(text) < 700 and "..." in text and text.count("x.toml") == 2
    assert refused.value.problems[0][0] == path     # the whole path, for code that reads it
    assert spec.shown("/short/path.toml") == "/short/path.toml" and len(spec.shown(path)) == 160
    # an output folder's too: under a file (the blocker named), and not writable
    blocker = tmp_path / ("b" * 250)
    blocker.write_text("a file")
    with pytest.raises(runner.OutputError) as refused:
        runner.make_folder(blocker / ("d" * 250) / ("e" * 250) / "out")
    assert len(str(refused.value)) < 400 and str(refused.value).endswith("bbb is a file, not a folder; choose "
                                                                         "another folder")


def test_a_locale_that_cannot_encode_a_file_name_runs_and_writes_it(tmp_path):
    """In an ASCII (or Latin-1) locale a scenario named 'σ_slew.toml' ended in a
    UnicodeEncodeError writing the folder's lock; printed names could end the same way.
    Now names the locale cannot encode are printed escaped and written as given."""
    import os
    (tmp_path / "σ_slew.toml").write_text((runner.SHIPPED / "telescope_slew.toml").read_text(), encoding="utf-8")
    env = {**os.environ, "LC_ALL": "C", "LANG": "C", "PYTHONCOERCECLOCALE": "0", "PYTHONUTF8": "0"}
    done = subprocess.run([sys.executable, "-m", "movingbase", "run", "σ_slew.toml", "--ci", "--quiet", "--out", "o"],
                          cwd=tmp_path, env=env, capture_output=True)
    assert done.returncode == 0, done.stderr.decode(errors="replace")[-2000:]
    assert b"o/\\udccf\\udc83_slew/report.md" in done.stdout    # the locale's bytes of 'σ', escaped
    assert (tmp_path / "o" / "σ_slew" / "report.md").read_text(encoding="utf-8").startswith("# telescope_slew")


def test_sigterm_leaves_no_unpacked_fmu_behind(tmp_path):
    """SIGTERM to a campaign (kill, a batch system's time limit) left 11 unpacked FMU
    folders in TMPDIR: the command ran no exit handler, nor did its killed workers. Now the
    command ends through its cleanup and removes the workers' folders too."""
    import os
    import signal
    import time
    scratch = tmp_path / "tmp"
    scratch.mkdir()
    process = subprocess.Popen([sys.executable, "-m", "movingbase", "campaign", "sky_slews", "--jobs", "2", "--out",
                                str(tmp_path / "c")], cwd=tmp_path,
                               env={**os.environ, "TMPDIR": str(scratch), "MOVINGBASE_FMU_CACHE": "off"},
                               stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    deadline = time.monotonic() + 300
    while time.monotonic() < deadline and not list(scratch.glob("movingbase-workers-*/movingbase-fmu-*")):
        time.sleep(0.2)      # the workers have unpacked their FMUs
    assert list(scratch.glob("movingbase-workers-*/movingbase-fmu-*")), "the workers unpacked nothing"
    process.send_signal(signal.SIGTERM)
    assert process.wait(timeout=120) == 143, process.stderr.read().decode(errors="replace")[-2000:]
    time.sleep(1.0)          # the workers' processes end after the command
    assert [p.name for p in scratch.iterdir()] == []


def test_an_fmu_that_cannot_be_unpacked_leaves_nothing_behind(tmp_path, monkeypatch):
    """A full TMPDIR (ENOSPC part-way) left the half-unpacked FMU behind (189 kB)."""
    import errno
    import tempfile

    from fmu_src.native_build import ensure_native
    from scenarios.cosim import fmi
    path = ensure_native(["leg_sensor_fmu"])["leg_sensor_fmu"]

    def full(filename, unzipdir):
        (pathlib.Path(unzipdir) / "binaries").mkdir()
        (pathlib.Path(unzipdir) / "binaries" / "part.so").write_bytes(b"x" * 1000)
        raise OSError(errno.ENOSPC, "No space left on device")
    monkeypatch.setattr(fmi, "extract", full)
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    monkeypatch.setenv(fmi.CACHE, "off")   # unpacked per process, into TMPDIR (a cached entry would be served)
    fmi.unpack.cache_clear()
    try:
        with pytest.raises(fmi.FmuFileError, match=r"no space left to unpack it in .* \(TMPDIR\)"):
            fmi.unpack(path)
    finally:
        fmi.unpack.cache_clear()
    assert list(tmp_path.iterdir()) == []
