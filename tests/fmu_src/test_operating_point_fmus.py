"""The FMUs' operating point (issue 41), native and pythonfmu: the plant's start_equilibrium
sets its leg forces to those that hold the platform still against its start inputs (the
platform stays put when they are held), and the controller's start_force starts its
integral or observer holding what its feedforward lacks (its first command is start_force).
Both twins give the same numbers bit for bit."""
import numpy as np
import pytest

from fmu_src.operating_point import STATIC_LEG_FORCES
from tests.fmu_helpers import opened, reals, step

OK = 0
WRENCH = {"platform_wrench[1]": 1219.0, "platform_wrench[2]": -2112.0, "platform_wrench[4]": 2112.0}
ACTUATOR = {"actuator_bandwidth": 50.0, "reflected_mass": 758.0, "coulomb_friction": 200.0,
            "viscous_friction": 2000.0, "friction_velocity": 1e-4, "actuator_force_limit": 25e3, "max_step": 1e-4}
FORCES = [f"leg_force_actual[{i}]" for i in range(1, 7)]
POSE = [f"pose[{i}]" for i in range(1, 7)]


def _plant(path, equilibrium, steps=200):
    """(leg forces at the start, the pose's largest drift [m, rad] over ``steps`` ms with
    those forces and the wrench held)."""
    inst, status = opened(path, start_equilibrium=equilibrium, **ACTUATOR, **WRENCH)
    assert status == OK
    start, pose = reals(inst, FORCES), reals(inst, POSE)
    for k in range(steps):
        for i, f in enumerate(start, 1):
            inst.set(f"leg_force[{i}]", f)
        assert step(inst, k * 1e-3, 1e-3) == OK
    return start, np.abs(reals(inst, POSE) - pose).max()


def test_the_plant_starts_holding_itself_still_against_the_wind(fmus, native):
    """With start_equilibrium the held start forces keep the platform within 1e-9 of its
    pose for 0.2 s (rounding and the friction's smoothing); they differ from the calm static
    forces by the wind's share (hundreds of N). Without it the start forces are the calm
    ones, and held against the wind the platform moves off by micrometres in 0.2 s."""
    runs = {(twin, eq): _plant(paths["hexapod_plant_fmu"], eq)
            for twin, paths in (("python", fmus), ("native", native)) for eq in (0, 1)}
    held, drift = runs[("native", 1)]
    assert drift < 1e-9
    assert np.abs(held - STATIC_LEG_FORCES).max() > 300
    calm, moved = runs[("native", 0)]
    assert np.array_equal(calm, STATIC_LEG_FORCES) and moved > 1e-6
    for eq in (0, 1):
        assert np.array_equal(runs[("python", eq)][0], runs[("native", eq)][0])
        assert runs[("python", eq)][1] == runs[("native", eq)][1]


START = STATIC_LEG_FORCES + np.array([150.0, -80.0, 1220.0, -40.0, 30.0, -1100.0])


def _controller(path, bandwidth):
    values = {f"start_force[{i}]": f for i, f in enumerate(START, 1)}
    inst, status = opened(path, observer_bandwidth=bandwidth, **values)
    assert status == OK
    names = ("leg_force", "feedforward_force", "integral", "disturbance_estimate")
    return {n: reals(inst, [f"{n}[{i}]" for i in range(1, 7)]) for n in names}, inst


@pytest.mark.parametrize("bandwidth", [0.0, 20.0])
def test_the_controller_starts_holding_what_its_feedforward_lacks(fmus, native, bandwidth):
    """The start command is start_force; the part beyond the feedforward is in the integral
    (ki times it) with the observer off, in the observer's estimate (its negative, the
    integral 0) with it on; the twins agree bit for bit, and the first step keeps it."""
    (python, _), (c, inst) = (_controller(paths["leg_controller_fmu"], bandwidth) for paths in (fmus, native))
    for name in python:
        assert np.array_equal(python[name], c[name]), name
    assert np.array_equal(c["leg_force"], START)
    hold = START - c["feedforward_force"]
    ki = inst.get_real("ki")
    if bandwidth:
        assert np.array_equal(c["disturbance_estimate"], -hold) and not c["integral"].any()
    else:
        assert c["integral"] * ki == pytest.approx(hold, rel=1e-12) and not c["disturbance_estimate"].any()
    for i, f in enumerate(START, 1):
        inst.set(f"leg_force_measured[{i}]", f)
    assert step(inst, 0.0, 1e-3) == OK
    assert reals(inst, [f"leg_force[{i}]" for i in range(1, 7)]) == pytest.approx(START, abs=1.0)


def test_start_force_without_integral_or_observer_is_refused(native):
    inst, status = opened(native["leg_controller_fmu"], ki=0.0, **{"start_force[1]": 1e4})
    assert status != OK
    assert any("start_force needs an integral gain ki > 0" in line for line in inst.log)


def test_an_observer_switched_on_later_is_at_rest_until_then(native):
    """observer_on_time 0.02 s: no estimate and nothing subtracted over the first 20 steps
    (the start's hold in the integral), the estimate moving from the 21st."""
    inst, status = opened(native["leg_controller_fmu"], observer_bandwidth=20.0, observer_on_time=0.02,
                          **{f"start_force[{i}]": f for i, f in enumerate(START, 1)})
    assert status == OK
    assert inst.get_real("integral[3]") != 0.0 and inst.get_real("disturbance_estimate[3]") == 0.0
    estimates = []
    for k in range(30):
        for i in range(1, 7):
            inst.set(f"leg_force_measured[{i}]", START[i - 1])
        assert step(inst, k * 1e-3, 1e-3) == OK
        estimates.append(inst.get_real("disturbance_estimate[3]"))
    assert estimates[:20] == [0.0] * 20 and estimates[-1] != 0.0
