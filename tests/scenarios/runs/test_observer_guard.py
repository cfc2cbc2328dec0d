"""The disturbance observer in the guard (issue 29): the loop model knows it, a scene beyond
its predicted bandwidth limit is refused naming the limit, and co-simulation confirms the
prediction (a run just beyond grows, one within stays bounded)."""
import dataclasses
import re

import numpy as np
import pytest

from controller import design
from plant.hexapod.model import StewartParams
from scenarios import spec
from scenarios.runs import flags, runner
from studies import wind_rejection

PARAMS = StewartParams.paper()
SHIPPED = ("telescope_slew_observer", "keyhole_tracking_observer")


def _scene(tmp_path, bandwidth, stop, coulomb=True):
    """The shipped observer slew at ``bandwidth`` Hz, one run to ``stop``; ``coulomb``
    False: without the screws' Coulomb friction."""
    text = runner.resolve("telescope_slew_observer").read_text()
    text = text.replace('observer_bandwidth = "8 Hz"', f'observer_bandwidth = "{bandwidth:g} Hz"')
    text = text.replace('values = ["0 Hz", "8 Hz"]', f'values = ["{bandwidth:g} Hz"]')
    text = text.replace('stop_time = "60 s"', f'stop_time = "{stop}"').replace('from = "5 s"', 'from = "1 s"')
    if not coulomb:
        text = text.replace('coulomb_friction = "200 N"', 'coulomb_friction = "0 N"')
    path = tmp_path / f"observer_{bandwidth:g}.toml"
    path.write_text(text)
    return path


@pytest.fixture(scope="module")
def prediction():
    """The observer loop of the shipped slew as the guard reads it, and its bandwidth limit."""
    scenario, paths, descriptions, values = runner.prepare(runner.resolve("telescope_slew_observer"))
    (loop,) = flags.loops(scenario, descriptions, values)
    masses = design.modal_masses(PARAMS, loop.model)
    return loop, design.observer_limit(masses, loop.gains, scenario.step, loop.model)


def test_the_guard_reads_the_observer_and_its_load_cell(prediction):
    """Every field of the LoopModel from the scene: the study's REALISTIC loop plus the
    observer of its scheme table (the two are written once each)."""
    loop, _ = prediction
    expected = dataclasses.replace(design.REALISTIC, observer_bandwidth=wind_rejection.OBSERVER_BANDWIDTH,
                                   observer_mass=wind_rejection.OBSERVER_MASS, load_cell=True,
                                   load_cell_bandwidth=200.0, load_cell_delay_steps=0)
    assert loop.model == expected


def test_the_observer_loop_without_observer_is_the_pid_loop():
    """At a vanishing bandwidth the observer's path adds nothing: the poles python-control
    finds for the loop with it agree with the closed-form polynomial's without it, except
    the observer's own two (at z = exp(-w h) -> 1, its filter at rest) and the delays' at 0."""
    gains = design.default_gains(PARAMS)
    mass = design.modal_masses(PARAMS, design.REALISTIC)[0]
    loop = dataclasses.replace(design.REALISTIC, observer_bandwidth=1e-6, observer_mass=2000.0, load_cell=True)
    import control
    poles = control.feedback(design.mode_loop(mass, gains, 1e-3, loop)).poles()
    plain = 1 + 1e-3 * np.roots(design.closed_loop_polynomial(mass, gains, 1e-3, design.REALISTIC))
    rest = sorted(p for p in np.abs(poles) if 1e-4 < p < 1 - 1e-6)   # the delays' poles at 0 apart
    assert rest == pytest.approx(sorted(p for p in np.abs(plain) if p > 1e-4), abs=1e-6)


def test_the_shipped_bandwidth_is_within_its_predicted_limit(prediction):
    loop, limit = prediction
    assert 2 * loop.model.observer_bandwidth < limit < 40.0


@pytest.mark.parametrize("name", SHIPPED)
def test_the_observer_scenes_pass_the_guard_unflagged(name):
    scenario, paths, descriptions, values = runner.prepare(runner.resolve(name))
    assert all(f == [] for f in runner.pre_run_flags(scenario, paths, descriptions, values).values())


def test_a_bandwidth_beyond_the_limit_is_refused_naming_it(prediction, tmp_path):
    _, limit = prediction
    path = _scene(tmp_path, round(1.3 * limit), "6 s")
    with pytest.raises(spec.ScenarioError) as refused:
        runner.pre_run_flags(*runner.prepare(path))
    message = str(refused.value)   # the guard's limit is taken along the motion, the fixture's at home
    said = re.search(rf"observer at {round(1.3 * limit):g} Hz is beyond its predicted limit ([0-9.]+) Hz", message)
    assert said and float(said[1]) == pytest.approx(limit, rel=0.05)
    assert f"observer_bandwidth below {said[1]} Hz" in message


def _jitter(tmp_path, bandwidth):
    """The largest change of a leg force command between records [N] over the last of 3 s
    held in calm air without Coulomb friction (the prediction leaves it out: below its
    smoothing velocity it is a stiff damper that hides a growth)."""
    path = _scene(tmp_path, bandwidth, "3 s", coulomb=False)
    path.write_text(path.read_text().replace('mean_speed = "10 m/s"', 'mean_speed = "0 m/s"'))
    _, (run,), _ = runner.run_scenario(path, tmp_path / "out", progress=False, allow_unstable=True, charts="none")
    t = run.records.time
    force = np.array([run.records[f"controller.leg_force[{i}]"] for i in range(1, 7)]).T
    return np.abs(np.diff(force[t >= 2.0], axis=0)).max()


@pytest.mark.slow
def test_cosimulation_confirms_the_limit(prediction, tmp_path):
    """Just beyond the predicted limit the loop's forces oscillate and grow to kN; just
    within it they stay at the load cells' noise."""
    _, limit = prediction
    beyond, within = _jitter(tmp_path, 1.15 * limit), _jitter(tmp_path, 0.85 * limit)
    assert beyond > 1e3 and beyond > 20 * within, (beyond, within)

