"""The leg controller's wind feedforward (fmu_src/leg_controller_fmu.py and its native twin,
plant/c/wind.c mb_wind_feedforward): the leg forces it adds hold the drag of the measured
speed, written out in numpy (0.5 rho Cd A V|V| along the wind, turned into {B}, moment
arm, F = -J^-T w with plant.hexapod.model's Jacobian at the reference pose); both twins give
the same numbers; off (the default) it changes nothing; a NaN speed is a Discard that says so."""
import math

import numpy as np
import pytest

from plant.hexapod.model import StewartParams, jacobian
from tests.fmu_helpers import _stepping_failure, opened, reals, step
from tests.plant.test_anemometer import drag_wrench

OK = 0
FF = [f"feedforward_force[{k}]" for k in range(1, 7)]
BASE = (0.0, 0.0, 0.0, 0.01, -0.6, 0.4)   # an antenna tilted 0.6 rad and turned 0.4 rad
WIND = {"wind_drag": 20.0, "wind_moment_arm": 1.5, "wind_direction": 0.9}


def forces(path, speed=None, **values):
    """feedforward_force after one step with the model feedforward off, the base at BASE."""
    inst, status = opened(path, feedforward=0, **values)
    assert status == OK, inst.log
    for k, v in enumerate(BASE):
        inst.set(f"base_pose[{k + 1}]", v)
    if speed is not None:
        inst.set("wind_speed", speed)
    assert step(inst, 0.0, 1e-3) == OK, inst.log
    return reals(inst, FF), np.array([inst.get_real(f"reference_pose[{k}]") for k in range(1, 7)])


@pytest.mark.parametrize("speed, gain", [(12.0, 1.0), (-4.0, 0.7)])
def test_feedforward_holds_the_predicted_drag(fmus, native, speed, gain):
    got = {}
    for name, paths in (("python", fmus), ("native", native)):
        got[name], pose = forces(paths["leg_controller_fmu"], speed, wind_feedforward=gain, **WIND)
    w = gain * drag_wrench(WIND["wind_drag"], WIND["wind_moment_arm"], WIND["wind_direction"], speed, np.array(BASE))
    expected = -np.linalg.solve(jacobian(StewartParams.paper(), pose).T, w)
    assert np.allclose(got["python"], expected, rtol=1e-9, atol=1e-9)
    assert np.allclose(got["native"], got["python"], rtol=1e-12, atol=1e-9)
    assert np.abs(expected).max() > 10.0   # a real load: N per leg


def test_off_by_default_whatever_the_speed(fmus, native):
    for paths in (fmus, native):
        quiet, _ = forces(paths["leg_controller_fmu"])
        ignored, _ = forces(paths["leg_controller_fmu"], 15.0, **WIND)
        assert np.array_equal(quiet, ignored) and not quiet.any()


def test_nan_wind_speed_discards(fmus, native):
    text = _stepping_failure(fmus, native, "leg_controller_fmu", {"wind_feedforward": 1.0}, {"wind_speed": math.nan})
    assert text == "InvalidInputError at t=0 s: wind_speed input contains NaN or inf"


def test_low_pass_follows_a_speed_step_as_the_first_order_response(fmus, native):
    """wind_cutoff: the speed steps from 12 to 6 m/s after initialization; n steps later the
    forces are those of 6 + 6 exp(-2 pi f_c n h) m/s (exact for a speed held over each step)."""
    cutoff, h, n = 2.0, 1e-3, 40
    got = []
    for paths in (fmus, native):
        inst, status = opened(paths["leg_controller_fmu"], feedforward=0, wind_feedforward=1.0, wind_cutoff=cutoff,
                              wind_speed=12.0, **WIND)
        assert status == OK, inst.log
        for k, v in enumerate(BASE):
            inst.set(f"base_pose[{k + 1}]", v)
        inst.set("wind_speed", 6.0)
        for k in range(n):
            assert step(inst, k * h, h) == OK, inst.log
        got.append(reals(inst, FF))
        pose = np.array([inst.get_real(f"reference_pose[{k}]") for k in range(1, 7)])
    speed = 6.0 + 6.0 * np.exp(-2 * np.pi * cutoff * n * h)
    w = drag_wrench(WIND["wind_drag"], WIND["wind_moment_arm"], WIND["wind_direction"], speed, np.array(BASE))
    expected = -np.linalg.solve(jacobian(StewartParams.paper(), pose).T, w)
    assert np.allclose(got[0], expected, rtol=1e-9)
    assert np.allclose(got[1], got[0], rtol=1e-12, atol=1e-9)
