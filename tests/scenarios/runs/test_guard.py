"""One guard for every loop (issue 27, items 1, 2 and 4): each run predicted at its own
values (sweep values, campaign cases), every limit of every loop watched (the plant's
actuator limit, the 3T sliders' limit) from the loop catalogue catalogue.CONTROL_LOOPS, and the
3T mechanism's loop predicted and refused beyond its limit."""
import numpy as np
import pytest

from fmu_src import catalogue
from scenarios import spec
from scenarios.cosim.records import run_records
from scenarios.runs import campaign, flags, runner

STROKE = (np.full(6, -0.15), np.full(6, 0.15))   # a Watched loop's ends: +-150 mm

REALISTIC = runner.SHIPPED / "telescope_slew_realistic.toml"
MECHANISM = runner.SHIPPED / "mechanism3t_paper.toml"
KP = 3726457.1097513535          # the leg controller's shipped kp (its start value)
KP4 = 14905828.439005414         # 4x: the issue's run, beyond its own limit 1.372 ms at 1.6 ms


def realistic(tmp_path, step="1.6 ms", interval="9.6 ms", sweep=(KP, KP4), stop=None):
    """The realistic slew at ``step`` with fixed-base feedforward, swept over controller.kp."""
    text = REALISTIC.read_text().replace('step = "1 ms"', f'step = "{step}"').replace(
        'interval = "10 ms"', f'interval = "{interval}"').replace(
        'parameters = { start_force = "@plant.leg_force_actual" }',
        'parameters = { start_force = "@plant.leg_force_actual", feedforward = "fixed_base" }').replace(
        'parameter = "controller.feedforward"\nvalues = ["none", "fixed_base", "moving_base"]',
        f'parameter = "controller.kp"\nvalues = [{", ".join(map(repr, sweep))}]')
    if stop:
        text = text.replace('stop_time = "60 s"', f'stop_time = "{stop}"')
    path = tmp_path / "realistic_kp.toml"
    path.write_text(text)
    return path


def mechanism(tmp_path, step, master="jacobi", stop=25.1, record=()):
    """mechanism3t_paper at ``step`` under ``master``, recorded every step (with ``record``)."""
    ms = float(step.split()[0])
    text = MECHANISM.read_text().replace('interval = "50 ms"', f'interval = "{step}"').replace(
        'step = "1 ms"', f'step = "{step}"').replace('master = "jacobi"', f'master = "{master}"').replace(
        'stop_time = "25.1 s"', f'stop_time = "{round(round(stop * 1e3 / ms) * ms, 9)!r} ms"').replace(
        'variables = ["plant.platform_position",', f'variables = [{"".join(repr(r) + ", " for r in record)}'
                                                 '"plant.platform_position",')
    path = tmp_path / f"m3t_{step.replace(' ', '')}_{master}.toml"
    path.write_text(text.replace("'", '"'))
    return path


def share_at(run, forces, limit):
    """The share of the run's recorded rows with an element of ``forces`` at ``limit`` [N]."""
    records = run_records(run)
    force = records.values[:, [k for k, n in enumerate(records.names) if n.startswith(forces + "[")]]
    return float(np.mean(np.abs(force).max(axis=1) >= limit * (1 - 1e-9)))


def pre_run(path, allow_unstable=False):
    scenario, paths, descriptions, values = runner.prepare(path)
    return runner.pre_run_flags(scenario, paths, descriptions, values, allow_unstable=allow_unstable)


# ------------------------------------------------------------------ item 1: every run predicted
def test_a_sweep_value_beyond_its_own_limit_is_refused_naming_the_run_and_its_limit(tmp_path):
    """The issue's sweep: kp 1x runs at 1.6 ms, 4x has its own limit 1.372 ms (the same
    kp written as a plain parameter is refused with it). Refused before anything runs,
    naming only the 4x run; run anyway, only the 4x run is flagged."""
    path = realistic(tmp_path)
    with pytest.raises(spec.ScenarioError) as refused:
        pre_run(path)
    text = str(refused.value)
    assert f"run '{KP4!r}'" in text and "predicted stability limit 1.372 ms" in text
    assert repr(KP) not in text
    plain = tmp_path / "plain.toml"    # the 4x kp as a plain parameter: the same limit
    plain.write_text(path.read_text().replace('feedforward = "fixed_base" }',
                                              f'feedforward = "fixed_base", kp = {KP4!r} }}').split("[sweep]")[0])
    with pytest.raises(spec.ScenarioError, match="predicted stability limit 1.372 ms"):
        pre_run(plain)
    found = pre_run(path, allow_unstable=True)
    assert {label: [f.kind for f in each] for label, each in found.items()} == {
        repr(KP): [], repr(KP4): ["step_beyond_limit"]}


def test_a_campaign_case_beyond_its_own_limit_is_refused_naming_it(tmp_path):
    """A campaign at 2 ms: the shipped kp runs (limit above 2 ms), a case at 4x kp does not
    (limit 1.372 ms): refused by its label (crossed with the scene's sweep) and limit,
    though it shares the time grid, master and extrapolation of the first case (once the
    only one predicted)."""
    path = tmp_path / "c.toml"
    path.write_text(f'name = "kp"\nscenario = "{REALISTIC}"\nset = {{ step = "2 ms", stop_time = "6 s" }}\n'
                    '[[cases]]\nlabel = "x1"\n'
                    f'[[cases]]\nlabel = "x4"\n"controller.kp" = {KP4!r}\n')
    with pytest.raises(spec.ScenarioError) as refused:
        campaign.jobs(campaign.load(path))
    text = str(refused.value)
    assert "run 'x4; controller.feedforward=none' (and 2 more" in text and "limit 1.372 ms" in text
    assert "x1" not in text


# ------------------------------------------------------------------ item 2: every limit watched
def test_the_catalogue_gives_every_loop_its_limits(tmp_path):
    """The realistic slew's loop is watched at the controller's 50 kN and the plant's
    25 kN actuator limit, and at its stroke; the 3T loop at its sliders' 1 kN."""
    for path, want in ((REALISTIC, (("controller.force_limit", 50e3), ("plant.actuator_force_limit", 25e3))),
                       (MECHANISM, (("controller.force_limit", 1e3),))):
        scenario, _, descriptions, values = runner.prepare(path)
        (watched,) = flags.Watch.for_scenario(scenario, descriptions, values).watched
        assert watched.limits == want
    assert (watched.forces, watched.lengths) == ("controller.slider_force", "plant.slider_position")
    assert np.array_equal(watched.stroke, ([-0.5, -1.0, -0.5], [0.6, 1.0, 0.5]))   # the actuator ranges


def fed(limits, force, t):
    watch = flags.Watch([flags.Watched("c", "c.f", "p.l", limits, STROKE)], window=0.5)
    watch.bind({"c.f": slice(0, 6), "p.l": slice(6, 12)})
    watch.feed(t, np.c_[np.repeat(force[:, None], 6, axis=1), np.zeros((len(t), 6))])
    return watch.flags([("c", "[WARNING] leg forces saturated at +-25000 N at t=0.06 s (legs 1)")])


def test_a_force_held_at_the_plants_limit_is_saturated_with_its_share_and_a_touch_is_not():
    """120 of 1000 rows beyond the plant's 25 kN (below the controller's 50 kN): saturated,
    12 %, said of the plant's limit, with the controller's warning; 3 rows (a stable run's
    transient, under SATURATED): no flag, and its warning no flag either. Under SATURATED,
    a stay of a window (the loop's 5 periods) on end is saturated, as many rows apart not."""
    t = np.arange(1000) * 0.01
    limits = (("c.force_limit", 50e3), ("p.actuator_force_limit", 25e3))
    (flag,) = fed(limits, np.where(t >= 8.8, 3e4, 1e3), t)
    assert flag.kind == "saturated"
    assert ("+-25 kN limit (p.actuator_force_limit) 12 % of the recorded time (from t ~ 8.5 s; at most 1.19 s on "
            "end)") in flag.message
    assert "c.force_limit" not in flag.message and "'c' logged 1 warning" in flag.message
    assert fed(limits, np.where((t > 0.05) & (t < 0.09), 3e4, 1e3), t) == []
    assert 3 / 1000 < flags.SATURATED
    # over 100 s: 61 rows (0.61 %) on end, 0.6 s, longer than the 0.5 s window, is saturated;
    # (across the Watch's blocks of 256 rows); the same 61 rows scattered (every 160th) are touches
    t = np.arange(10000) * 0.01
    (flag,) = fed(limits, np.where((t >= 30.5) & (t < 31.105), 3e4, 1e3), t)
    assert "0.61 % of the recorded time (from t ~ 30.5 s; at most 0.6 s on end)" in flag.message
    assert fed(limits, np.where(np.arange(10000) % 160 == 0, 3e4, 1e3)[:9760], t[:9760]) == []


# ------------------------------------------------------------------ items 3 and 4: the 3T loop
# the true limits, bisected with 60 s runs of mechanism3t_paper (feedforward on; the sliders'
# force oscillation decays at the lower step, grows or sits in a limit cycle at the upper):
# Jacobi 12.80-12.85 ms, Gauss-Seidel 27.7-27.9 ms
@pytest.mark.parametrize("master, true_low, true_high", [("jacobi", 12.8e-3, 12.85e-3),
                                                         ("gauss-seidel", 27.7e-3, 27.9e-3)])
def test_the_3t_limit_is_predicted_within_the_true_one(tmp_path, master, true_low, true_high):
    """The slider loop's predicted limit lies within 0.98-1x the bisected true limit's
    bounds, never above its upper bound; a step beyond it is refused for both runs of the
    sweep, naming them, one below it is not."""
    below = mechanism(tmp_path, f"{true_low * 0.9 * 1e3:g} ms", master, stop=2.0)
    assert [f for each in pre_run(below).values() for f in each] == []
    beyond = mechanism(tmp_path, f"{true_high * 1e3:g} ms", master, stop=2.0)
    with pytest.raises(spec.ScenarioError) as refused:
        pre_run(beyond)
    limit = float(str(refused.value).split("predicted stability limit ")[1].split(" ms")[0]) * 1e-3
    assert 0.98 * true_low <= limit <= true_high
    assert "runs 'off', 'on' (sweep of " in str(refused.value)     # one reason, told once for both


def test_the_3t_loop_run_beyond_its_limit_is_flagged_saturated_as_its_records_say(tmp_path):
    """14 ms (Jacobi), run anyway for 3 s: the sliders sit at +-1 kN; the flag's share is
    the share of recorded rows with a slider force at 1 kN, and both implementations log
    the same saturation warnings."""
    path = mechanism(tmp_path, "14 ms", stop=3.0, record=("controller.slider_force",))
    said = {}
    for implementation in ("native", "python"):
        scenario, paths, descriptions, values = runner.prepare(path, implementation=implementation)
        before = runner.pre_run_flags(scenario, paths, descriptions, values, allow_unstable=True)
        runs = runner.run_prepared(scenario, paths, descriptions, values, tmp_path / implementation, False,
                                   before=before)
        run = runs[0]
        share = share_at(run, "controller.slider_force", 1e3)
        (saturated,) = [f.message for f in run.flags if f.kind == "saturated"]
        assert {f.kind for f in run.flags} == {"step_beyond_limit", "saturated"}
        assert f"+-1 kN limit (controller.force_limit) {100 * share:.3g} % of the recorded time" in saturated
        assert share == pytest.approx(0.284, abs=0.005)     # 61 of 215 rows
        said[implementation] = saturated.split("'controller' logged")[1]
    assert said["native"] == said["python"] and "slider forces saturated at +-1000 N at t=" in said["native"]


@pytest.mark.slow
def test_the_issues_sweep_run_anyway_flags_the_4x_run_at_the_actuator_limit_only(tmp_path):
    """The issue's sweep at full length, run anyway: the 4x run sits in a limit cycle at the
    plant's 25 kN (the flag's share is that of the records' rows); the 1x run, which touches
    25 kN for a few steps near t = 0.06 s, is not flagged."""
    path = realistic(tmp_path)      # it records controller.leg_force
    scenario, paths, descriptions, values = runner.prepare(path)
    before = runner.pre_run_flags(scenario, paths, descriptions, values, allow_unstable=True)
    one, four = runner.run_prepared(scenario, paths, descriptions, values, tmp_path / "out", False, before=before)
    assert one.flags == []
    share = share_at(four, "controller.leg_force", 25e3)
    (saturated,) = [f.message for f in four.flags if f.kind == "saturated"]
    assert {f.kind for f in four.flags} == {"step_beyond_limit", "saturated"}
    assert f"+-25 kN limit (plant.actuator_force_limit) {100 * share:.3g} % of the recorded time" in saturated
    assert share == pytest.approx(0.767, abs=0.01)   # rows with some leg at 25 kN (the issue: 12 % of the values)


def test_a_slider_near_the_end_of_its_range_is_flagged_stroke():
    """The 3T sliders' stroke is their actuator range (x_A2: -0.5..0.6 m, its middle 0.05 m):
    at 0.52 m a slider is 85.5 % of the way to its end (no flag), at 0.56 m 92.7 % (flag)."""
    (watched,) = flags.Watch.for_scenario(*[runner.prepare(MECHANISM)[i] for i in (0, 2, 3)]).watched
    t = np.arange(100) * 0.01
    for x, want in ((0.52, []), (0.56, ["'plant.slider_position' reaches 92.7 % of its half stroke"])):
        watch = flags.Watch([watched], window=0.2)
        watch.bind({watched.forces: slice(0, 3), watched.lengths: slice(3, 6), watched.excitation: slice(6, 9)})
        watch.feed(t, np.c_[np.zeros((100, 3)), np.tile([x, 0.0, 0.0], (100, 1)), np.zeros((100, 3))])
        assert [f.message for f in watch.flags()] == want


# ------------------------------------------------------------------ the growth detector
def test_the_window_is_cycles_of_the_loops_unstable_oscillation_not_a_share_of_the_run():
    """The realistic slew's window: CYCLES periods of the pole with which its loop goes
    unstable (python-control's closed loops of its modes at the step limit: the oscillating
    pole nearest the unit circle), the same for its 8 s [ci] run and its 60 s run."""
    import control

    from controller import design
    windows = []
    for ci in (True, False):
        scenario, _, descriptions, values = runner.prepare(REALISTIC, ci)
        windows.append(flags.Watch.for_scenario(scenario, descriptions, values).window)
    (loop,) = flags.loops(scenario, descriptions, values)
    masses = flags._merge(flags.MODAL_MASSES["hexapod_plant"](scenario, None, descriptions, values, loop, None))
    limit = design.step_limit(masses, loop.gains, loop.model)
    poles = np.concatenate([control.feedback(design.mode_loop(m, loop.gains, limit, loop.model)).poles()
                            for m in masses])
    pole = poles[np.argmax(np.abs(poles) * (np.abs(np.angle(poles)) > 1e-9))]
    period = 2 * np.pi * limit / abs(np.angle(pole))
    assert windows[0] == windows[1] == pytest.approx(flags.CYCLES * period, rel=1e-3)
    assert windows[0] == pytest.approx(0.2333, abs=1e-3)


def test_a_rise_driven_by_the_references_own_excitation_is_no_growth():
    """The same 0.1 -> 2.35 µm rise of the leg-length oscillation over 2-7 s, held after: with
    the reference's excitation rising with it (a slew that starts: the reference's second
    difference from rest to its cruise) it is the loop answering; with the excitation steady
    it is a growth (unstable)."""
    t = np.arange(0, 20, 0.01)
    wiggle = (-1.0) ** np.arange(len(t))
    rise = np.interp(t, [0, 2, 7, 20], [0.1, 0.1, 2.35, 2.35]) * 1e-6
    moving = np.interp(t, [0, 2, 7, 20], [0.0, 0.0, 1e-6, 1e-6])
    def fed(excitation):
        watched = flags.Watched("c", "c.f", "p.l", (("c.force_limit", 1e9),), STROKE, "c.r")
        watch = flags.Watch([watched], window=0.5)
        watch.bind({"c.f": slice(0, 6), "p.l": slice(6, 12), "c.r": slice(12, 18)})
        reference = np.repeat(np.cumsum(np.cumsum(excitation))[:, None], 6, axis=1)   # second difference: excitation
        watch.feed(t, np.c_[np.zeros((len(t), 6)), np.repeat((wiggle * rise)[:, None], 6, axis=1), reference])
        return {f.kind for f in watch.flags()}
    assert fed(moving) == set()
    assert fed(np.full(len(t), 1e-6)) == {"unstable"}


def test_every_limit_an_fmu_declares_is_in_the_loop_catalogue():
    """A limit or stroke parameter of any of the kit's FMUs (one a future FMU declares too)
    belongs to a loop of catalogue.CONTROL_LOOPS, as the controller's limit or its plant's, so
    the guard watches it; every loop's variables exist in its FMUs."""
    paths = runner.ensure_native(sorted(catalogue.SCRIPTS))
    names = {fmu: {v.name.split("[", 1)[0]: v for v in runner.description(paths[script]).modelVariables}
             for fmu, script in ((f.key, f.script) for f in catalogue.FMUS)}
    watched = {(fmu, entry["limit"]) for fmu, entry in catalogue.CONTROL_LOOPS.items()} | {
        (entry["plant"], entry[key]) for entry in catalogue.CONTROL_LOOPS.values() for key in ("plant_limit", "stroke")}
    declared = {(fmu, name) for fmu, variables in names.items() for name, v in variables.items()
                if v.causality == "parameter" and (name.endswith("limit") or name == "stroke")}
    assert declared == watched - {(plant, None) for plant in catalogue.KEYS}
    assert declared == {("hexapod_plant", "stroke"), ("hexapod_plant", "actuator_force_limit"),
                        ("leg_controller", "force_limit"), ("slider_controller", "force_limit")}
    for fmu, entry in catalogue.CONTROL_LOOPS.items():
        own = [entry["force"], entry["measured"], entry["limit"], entry["excitation"], *entry["gains"],
               *entry["motion"]]
        plant = [entry["plant_force"], entry["plant_measured"], *entry["loop_model"].values()]
        assert set(own) <= set(names[fmu]) and set(plant) <= set(names[entry["plant"]]), fmu


def test_3t_gains_too_soft_for_gravity_are_refused_and_do_fall(tmp_path):
    """Gravity pulls the 3T sliders away at 7.35 rad/s (rate 54 /s^2, from the plant's own
    dynamics): the slider PID at 0.25x its gains (kp 2150 N/m, below the heaviest mode's
    50 kg x 54 /s^2) holds no step; refused; run anyway, both runs fall out of reach of
    the plant (cut short), while at 0.5x the feedforward run is clean."""
    def scaled(factor):
        path = mechanism(tmp_path, "1 ms", stop=4.0)
        path.write_text(path.read_text().replace(
            '[fmus.controller]\nfmu = "slider_controller"', '[fmus.controller]\nfmu = "slider_controller"\n'
            f'parameters = {{ kp = {8.6e3 * factor}, ki = {1.6e4 * factor}, kd = {890 * factor} }}'))
        return path
    scenario, _, descriptions, values = runner.prepare(scaled(0.25))
    (loop,) = flags.loops(scenario, descriptions, values)
    assert loop.model.gravity_rate == pytest.approx(53.97, abs=0.05)
    with pytest.raises(spec.ScenarioError, match="no step is stable with these gains"):
        pre_run(scaled(0.25))
    scenario, paths, descriptions, values = runner.prepare(scaled(0.25))
    before = runner.pre_run_flags(scenario, paths, descriptions, values, allow_unstable=True)
    runs = runner.run_prepared(scenario, paths, descriptions, values, None, False, before=before)
    assert [bool(r.failure) for r in runs] == [True, True]
    scenario, paths, descriptions, values = runner.prepare(scaled(0.5))
    runs = runner.run_prepared(scenario, paths, descriptions, values, None, False,
                               before=runner.pre_run_flags(scenario, paths, descriptions, values))
    assert runs[1].label == "on" and not runs[1].failure and runs[1].flags == []
