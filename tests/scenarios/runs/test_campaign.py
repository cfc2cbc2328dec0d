"""Campaign files: the grid and the cases expand to the runs they say, bad input is
refused before anything runs with file, key and problem, a campaign runs through the
engine to the same numbers as the scenario run directly, and the shipped sky-coverage
study runs in its [ci] version with its charts and worst-case table."""
import csv

import pytest

from scenarios import spec
from scenarios.runs import campaign, engine, flags, metrics, runner, single
from scenarios.spec.units import to_si

HEAD = 'name = "t"\nscenario = "telescope_slew"\n'


def _parse(text, tmp_path, ci=False):
    path = tmp_path / "c.toml"
    path.write_text(text)
    return campaign.load(path, ci)


def test_grid_axes_zip_and_cross_with_cases(tmp_path):
    c = _parse(HEAD + '''set = { stop_time = "6 s" }
[[grid]]
"base.start_elevation" = ["20 deg", "50 deg", "70 deg"]
base.target_elevation = ["25 deg", "55 deg", "75 deg"]
[[grid]]
"controller.feedforward" = ["fixed_base", "moving_base"]
[[cases]]
label = "north"
"base.start_azimuth" = "0 deg"
[[cases]]
label = "east"
"base.start_azimuth" = "90 deg"
[ci]
grid = [{ "controller.feedforward" = ["none"] }]
''', tmp_path)
    assert len(c.cases) == 2 * 3 * 2                   # cases x zipped elevations x modes
    pairs = {(r.values["base.start_elevation"], r.values["base.target_elevation"]) for r in c.cases}
    assert pairs == {("20 deg", "25 deg"), ("50 deg", "55 deg"), ("70 deg", "75 deg")}
    assert all(r.values["stop_time"] == "6 s" for r in c.cases)
    assert c.cases[0].label.startswith("north; ")
    assert set(c.varying) == {"base.start_azimuth", "base.start_elevation", "base.target_elevation",
                              "controller.feedforward"}
    small = _parse((tmp_path / "c.toml").read_text(), tmp_path, ci=True)
    assert len(small.cases) == 2 and {r.values["controller.feedforward"] for r in small.cases} == {"none"}


def test_base_sweep_is_an_axis_unless_the_campaign_sets_it(tmp_path):
    c = _parse(HEAD + '[grid]\n"base.lever_arm" = ["0 m", "25 m"]\n', tmp_path)
    assert [r.values["controller.feedforward"] for r in c.cases] == ["none", "fixed_base", "moving_base"] * 2
    c = _parse(HEAD + 'set = { "controller.feedforward" = "moving_base" }\n', tmp_path)
    assert len(c.cases) == 1


@pytest.mark.parametrize("body, key, problem", [
    ('name = "t"\n', "scenario", "missing"),
    (HEAD + 'grid = 3\n', "grid", "expected a table or an array"),
    (HEAD + 'colour = "red"\n', "colour", "unknown key"),
    ('name = "t"\nscenario = "no_such_scene"\n', "scenario", "neither a shipped scenario nor a file"),
    (HEAD + '[grid]\n"base.start_azimuth" = []\n', "grid[0].base.start_azimuth", "non-empty list"),
    (HEAD + '[[grid]]\n"base.start_azimuth" = ["1 deg"]\n"base.target_azimuth" = ["1 deg", "2 deg"]\n',
     "grid[0]", "lists of one length"),
    (HEAD + '[grid]\n"base.start_azimuth" = ["10 deg", "3 kg"]\n', "grid[0].base.start_azimuth[1]", "kg"),
    (HEAD + '[grid]\n"telescope.start_azimuth" = ["10 deg"]\n', "grid[0].telescope.start_azimuth[0]",
     "unknown key 'telescope.start_azimuth'"),
    (HEAD + 'set = { "base.colour" = 1 }\n', "set.base.colour", "has no parameter 'colour'"),
    (HEAD + 'set = { step = "-1 ms" }\n', "set.step", "must be positive"),
    (HEAD + '[[cases]]\n"controller.feedforward" = "sometimes"\n', "cases[0].controller.feedforward",
     "'sometimes' is not one of"),
    (HEAD + '[[cases]]\nlabel = 3\n', "cases[0].label", "expected a string"),
    (HEAD + 'keep_records = "yes"\n', "keep_records", "expected true or false"),
    (HEAD + 'grid = [\n', "TOML", ""),
])
def test_bad_campaign_files_name_file_key_and_problem(tmp_path, body, key, problem):
    with pytest.raises(campaign.CampaignError) as info:
        _parse(body, tmp_path)
    message = str(info.value)
    assert message.startswith(f"{tmp_path / 'c.toml'}: {key}: ") and problem in message


def test_missing_and_binary_files(tmp_path):
    with pytest.raises(campaign.CampaignError, match="does not exist"):
        campaign.load(tmp_path / "none.toml")
    (tmp_path / "b.toml").write_bytes(b"\xff\xfe\x00binary")
    with pytest.raises(campaign.CampaignError, match="is a binary file"):
        campaign.load(tmp_path / "b.toml")
    with pytest.raises(campaign.CampaignError, match="is a directory"):
        campaign.load(tmp_path)


def test_campaign_runs_equal_the_scenario_run_directly(tmp_path):
    path = tmp_path / "c.toml"
    path.write_text(HEAD + '''set = { stop_time = "5.3 s", "controller.feedforward" = "fixed_base" }
[grid]
"base.start_elevation" = ["20 deg", "60 deg"]
''')
    camp, jobs, store, outcome, summary = campaign.run_campaign(path, tmp_path / "out", jobs_=2, progress=False)
    assert len(outcome.computed) == 2 and not outcome.failed
    with open(summary) as f:
        table = list(csv.DictReader(f))
    assert [r["base.start_elevation"] for r in table] == ["20 deg", "60 deg"]
    scenario, paths, descriptions, values = runner.prepare(runner.SHIPPED / "telescope_slew.toml")
    scenario = spec.load(scenario.source, overrides={"stop_time": "5.3 s"})
    for row, el in zip(table, (20, 60)):   # the same run set up by hand, in this process
        params = {inst: dict(v) for inst, v in values.items()}
        params["controller"]["feedforward"] = 1
        params["base"]["start_elevation"] = to_si(f"{el} deg", "rad")
        before = runner.pre_run_flags(scenario, paths, descriptions,
                                      params)["fixed_base"]   # what `movingbase run` flags
        run = single.run(scenario, paths, params, tmp_path, "direct", [metrics.make(m) for m in scenario.metrics],
                         flags=before)
        # the slew begins at 5 s: at 5.3 s it has not ended, a run of it says so wherever its numbers are
        assert [f.kind for f in before] == ["motion_unfinished"]
        assert row["flags"] == flags.summary(run.flags) and "motion_unfinished" in row["flags"]
        assert float(row["pose error peak"]) == run.metrics["pose error"]["peak"]
        assert float(row["leg error rms"]) == run.metrics["leg error"]["rms"]
        assert 0 < run.cpu_time <= run.wall_time + 1e-3   # one thread's CPU time: never above the wall time it spans
    again = campaign.run_campaign(path, tmp_path / "out", jobs_=2, progress=False)[3]
    assert not again.computed and len(again.skipped) == 2


def test_sky_coverage_ci_charts_and_worst_cases(tmp_path):
    from studies import sky_coverage
    results = sky_coverage.run(tmp_path, ci=True, jobs=2, progress=False)
    assert all(not o.failed and len(o.computed) == len(j) for _, j, _, o in results.values())
    path, charts = sky_coverage.report(results, tmp_path / "report")
    assert all(c.stat().st_size > 10_000 for c in charts)
    text = path.read_text()
    table = [line for line in text.splitlines() if line.startswith("| sky_") or line.startswith("| slew_")
             or line.startswith("| keyhole_")]
    fixed = [float(line.split("|")[4]) for line in table if "| fixed_base |" in line]
    moving = [float(line.split("|")[4]) for line in table if "| moving_base |" in line]
    assert fixed == sorted(fixed, reverse=True) and moving == sorted(moving, reverse=True)
    rows = sky_coverage.rows(*results["sky_slews"][:3])
    by = {(r["values"]["base.start_azimuth"], r["values"]["base.start_elevation"], r["mode"]): r["peak"] for r in rows}
    for el in ("20 deg", "70 deg"):          # gravity is along the azimuth axis: azimuth cannot matter
        for mode in sky_coverage.MODES:
            assert by[("0 deg", el, mode)] == pytest.approx(by[("180 deg", el, mode)], rel=1e-6)
    assert max(fixed) > 100 > 10 > max(moving)   # the headline: fixed-base past 0.1 mm, moving-base under 10 µm


def _implementation(path):
    """What an FMU file is, read from its own model description (not from how it was found)."""
    from scenarios.cosim.fmi import unpack
    return "native" if "native_build" in unpack(path)[0].generationTool else "python"


def test_every_path_runs_the_implementation_the_scenario_names(tmp_path):
    """Issue 21: campaigns ran the pythonfmu FMUs whatever the scenario said. The CLI's
    prepare, the sweep's jobs and a campaign's jobs each run each instance's choice."""
    text = (runner.SHIPPED / "telescope_slew.toml").read_text()
    scene = tmp_path / "mixed.toml"
    scene.write_text(text.replace('implementation = "native"', 'implementation = "python"', 1))
    chosen = spec.load(scene).implementations
    assert set(chosen.values()) == {"python", "native"}
    scenario, paths, descriptions, values = runner.prepare(scene)
    assert {inst: _implementation(p) for inst, p in paths.items()} == chosen
    path = tmp_path / "c.toml"
    path.write_text(f'name = "t"\nscenario = "{scene}"\nset = {{ stop_time = "5.4 s" }}\n')
    job_list, files = campaign.jobs(campaign.load(path))
    job = next(iter(job_list))
    assert {inst: _implementation(files[digest]) for inst, digest in job.fmus.items()} == chosen
    sweep_jobs, sweep_files = engine.prepared_jobs(scenario, paths, values, [("run", {})])
    assert {inst: _implementation(sweep_files[d]) for inst, d in sweep_jobs[0].fmus.items()} == chosen


@pytest.mark.parametrize("body, key, problem", [
    # one value written twice: the same run twice under two labels
    (HEAD + '[[grid]]\n"base.lever_arm" = ["1 m", "1000 mm"]\n', "grid[0].base.lever_arm[1]",
     "'1000 mm' is already value [0] of this axis (base.lever_arm = '1 m')"),
    (HEAD + '[[grid]]\n"base.lever_arm" = [1, 1.0]\n', "grid[0].base.lever_arm[1]", "already value [0]"),
    (HEAD + '[[grid]]\nstop_time = ["8 s", "8000 ms"]\n', "grid[0].stop_time[1]", "already value [0]"),
    (HEAD + '[[grid]]\n"base.start_elevation" = ["30 deg", "30 deg"]\n"base.target_elevation" = ["35 deg", '
     '"0.6108652381980153"]\n', "grid[0][1]", "already value [0]"),
    # two cases whose runs share labels: the table's rows and CampaignResult.series(label) mix them
    (HEAD + '[[cases]]\nlabel = "a"\n"base.lever_arm" = "1 m"\n[[cases]]\nlabel = "a"\n"base.lever_arm" = "2 m"\n',
     "cases[1].label", "would have the labels of cases[0]'s"),
    (HEAD + '[[cases]]\n"base.lever_arm" = "1 m"\n[[cases]]\n"base.lever_arm" = "1 m"\n', "cases[1]",
     "give each case its own label"),
    # a link is the scenario file's; once told "expected 6 values, got 1"
    (HEAD + 'set = { "plant.initial_pose" = "@base.reference_pose" }\n', "set.plant.initial_pose",
     "a link to another FMU's output at the start time is written in the scenario file"),
])
def test_campaign_values_that_would_run_twice_or_mislabel_are_refused(tmp_path, body, key, problem):
    with pytest.raises(campaign.CampaignError) as info:
        _parse(body, tmp_path)
    message = str(info.value)
    assert message.startswith(f"{tmp_path / 'c.toml'}: {key}: ") and problem in message, message


def test_a_zipped_axis_may_repeat_a_value_of_one_key(tmp_path):
    """Two slews from one start elevation are two runs (the per-key check refused them)."""
    c = _parse(HEAD + '[[grid]]\n"base.start_elevation" = ["30 deg", "30 deg"]\n"base.target_elevation" = '
               '["35 deg", "40 deg"]\n', tmp_path)
    assert len(c.cases) == 6


@pytest.mark.parametrize("body, problem", [
    # the telescope model refuses the combination (a scenario file with it is refused before it runs)
    ('name = "k"\nscenario = "keyhole_tracking"\n[[grid]]\n"base.declination" = ["30.89 deg", "-80 deg"]\n',
     "run 'base.declination=-80 deg; controller.feedforward=none' (and 2 more: "),
    # beyond the predicted stability limit (2 ms for the slew's Jacobi with linear extrapolation)
    (HEAD + 'set = { step = "2.5 ms" }\n', "step: 2.5 ms is beyond the predicted stability limit 2 ms"),
])
def test_runs_the_models_or_the_stability_limit_refuse_are_refused_before_any_runs(tmp_path, body, problem):
    """Campaign values were checked one by one, never as a run: a source below the horizon
    and a step beyond the stability limit ran (the scenario file with them is refused)."""
    c = _parse(body, tmp_path)
    with pytest.raises(campaign.CampaignError) as info:
        campaign.jobs(c)
    message = str(info.value)
    assert message.startswith(f"{tmp_path / 'c.toml'}: run ") and problem in message, message
    assert "--allow-unstable" not in message and len(message.splitlines()) == 1, message
    good = _parse(body.replace('"-80 deg"', '"31.59 deg"').replace('"2.5 ms"', '"2 ms"'), tmp_path)
    assert len(list(campaign.jobs(good)[0])) == len(good.cases)


def test_a_campaign_that_is_not_one_names_the_shipped_ones():
    with pytest.raises(campaign.CampaignError, match="sky_slew: file: does not exist; did you mean 'sky_slews'"):
        campaign.load("sky_slew")
    with pytest.raises(TypeError, match="a campaign is a file path or a shipped name, got int 5"):
        campaign.load(5)


def test_set_s_top_level_keys_are_checked_together_and_bind_errors_are_the_campaign_s(tmp_path):
    """set's start_time was checked against the scenario's own stop_time ("stop_time must be
    after start_time"), and a setting refused when binding was told of the scenario file."""
    c = _parse(HEAD + 'set = { start_time = "100 s", stop_time = "108 s" }\n', tmp_path)
    assert {case.values["start_time"] for case in c.cases} == {"100 s"}
    c = _parse(HEAD + 'set = { extrapolation = "derivatives" }\n', tmp_path)
    with pytest.raises(campaign.CampaignError) as info:
        campaign.jobs(c)
    message = str(info.value)
    assert message.startswith(f"{tmp_path / 'c.toml'}: runs of extrapolation = 'derivatives': ") and \
        'extrapolation: "derivatives" takes the output derivatives of FMI 3 FMUs' in message, message


def test_the_scenario_is_found_beside_the_campaign_file_first(tmp_path, monkeypatch):
    """A scenario path is relative to the campaign file (docs/campaigns.md); a file of that
    name in the current folder was taken instead, silently."""
    (tmp_path / "mine").mkdir()
    (tmp_path / "mine" / "slew.toml").write_text(runner.resolve("telescope_slew").read_text())
    (tmp_path / "slew.toml").write_text(runner.resolve("paper_manoeuvre").read_text())
    (tmp_path / "mine" / "c.toml").write_text('scenario = "slew"\n')
    monkeypatch.chdir(tmp_path)
    assert campaign.load(tmp_path / "mine" / "c.toml").scenario_path == tmp_path / "mine" / "slew.toml"
    (tmp_path / "mine" / "shipped.toml").write_text('scenario = "telescope_slew"\n')
    assert campaign.load(tmp_path / "mine" / "shipped.toml").scenario_path == runner.resolve("telescope_slew")


def test_a_ci_campaign_keeps_its_short_runs_unflagged(tmp_path):
    """A [ci] campaign cuts the slew on purpose (its [ci] set: 8 s of a 60 s slew); its
    runs must not be flagged motion_unfinished, as `movingbase run --ci` is not.
    Campaign(...) once was built without its ci setting, and no test saw it."""
    path = tmp_path / "c.toml"
    path.write_text(HEAD + '[grid]\n"base.lever_arm" = ["20 m"]\n[ci]\nset = { stop_time = "8 s" }\n')
    assert campaign.load(path, ci=True).ci and not campaign.load(path).ci
    camp, jobs, store, outcome, summary = campaign.run_campaign(path, tmp_path / "out", ci=True, jobs_=1,
                                                                progress=False)
    with open(summary) as f:
        table = list(csv.DictReader(f))
    assert len(table) == 3 and all(r["status"] == "ok" and r["flags"] == "" for r in table), table   # x the sweep
    # the [ci] stop time, 8 s: the slew (from 5 s to ~56 s) is cut
    assert [store.read(job.key)["sim_time_s"] for job in jobs] == pytest.approx([8.0] * 3)


def test_a_mistyped_key_is_told_once_with_a_did_you_mean_and_every_other_problem_too(tmp_path):
    """A grid key typo gave one identical line per value, no did-you-mean, and hid the
    second mistake behind the first (issue 39)."""
    path = tmp_path / "typo.toml"
    path.write_text('name = "typo"\nscenario = "paper_manoeuvre"\n[[grid]]\n"base.lever_arn" = ["1 m", "2 m"]\n'
                    '[[grid]]\n"controller.kq" = [1.0, 2.0, 3.0]\n')
    with pytest.raises(campaign.CampaignError) as refused:
        campaign.load(path)
    assert [line.split(": ", 1)[1] for line in str(refused.value).splitlines()] == [
        "grid[0].base.lever_arn[0]: base (telescope) has no parameter 'lever_arn'; did you mean 'lever_arm'? "
        "(the same at grid[0].base.lever_arn[1])",
        "grid[1].controller.kq[0]: controller (leg_controller) has no parameter 'kq' (the same at "
        "grid[1].controller.kq[1], grid[1].controller.kq[2])"]
