"""The leg controller with its disturbance observer on, and the load cell: the native FMU
and its pythonfmu twin give the same numbers bit for bit (the shipped observer scenes'
own twin runs are in the slow set)."""
import numpy as np
import pytest

from controller import design
from plant.hexapod.model import StewartParams
from tests.fmu_helpers import opened, reals, step

OK = 0


def _run(path, values, inputs, watch, n=60):
    inst, status = opened(path, **values)
    assert status == OK
    rows = []
    for k in range(n):
        for name, value in inputs.items():
            inst.set(name, value * (1 + 1e-3 * np.sin(0.3 * k)))
        assert step(inst, k * 1e-3, 1e-3) == OK
        rows.append(reals(inst, watch))
    return np.array(rows)


@pytest.mark.parametrize("script, values, inputs, watch", [
    ("leg_controller_fmu", {"observer_bandwidth": 20.0, "observer_mass": 2600.0},
     {"leg_length[2]": 3.0, "leg_force_measured[2]": 5e3, "leg_force_measured[5]": -2e3},
     ["leg_force[2]", "leg_force[5]", "disturbance_estimate[2]", "disturbance_estimate[5]", "observer_state[5]"]),
    ("leg_controller_fmu", {"observer_bandwidth": 32.0, "observer_mass": 2606.0, "observer_model": 1},
     {"leg_length[2]": 3.0, "leg_force_measured[2]": 5e3, "leg_force_measured[5]": -2e3},
     ["leg_force[2]", "leg_force[5]", "disturbance_estimate[1]", "disturbance_estimate[5]", "observer_state[5]"]),
    ("leg_controller_fmu", {"observer_bandwidth": 20.0, "observer_mass": 2000.0, "observer_on_time": 0.03},
     {"leg_length[2]": 3.0, "leg_force_measured[2]": 5e3, "leg_force_measured[5]": -2e3},
     ["leg_force[5]", "disturbance_estimate[2]", "disturbance_estimate[5]", "observer_state[5]"]),
    ("load_cell_fmu", {"noise": 5.0, "resolution": 0.5, "bandwidth": 200.0, "delay_steps": 1},
     {"leg_force[1]": 5e3, "leg_force[6]": -1e3}, ["measured_force[1]", "measured_force[6]"]),
])
def test_native_and_python_agree_bit_for_bit(fmus, native, script, values, inputs, watch):
    python, c = (_run(paths[script], values, inputs, watch) for paths in (fmus, native))
    assert np.array_equal(python, c)
    assert np.ptp(python, axis=0).min() > 0   # every watched output moves


def test_the_leg_space_matrix_couples_the_legs_in_the_fmu(native):
    """observer_model set in initialization mode reaches the kernel: a length wobble on leg 2
    alone moves leg 1's estimate through the model matrix's off-diagonal term with leg_space,
    and not with one scalar. Both legs' estimates pass the same Q, so their ratio is the
    shifted matrix's M_o[0, 1] / M_o[1, 1], from the Python model (controller.design); at home
    the legs' diagonal terms are equal, so leg 2's own estimate is the scalar's (within
    rounding: whether it differs in the last bit depends on the machine's FMA, so only that)."""
    values = {"observer_bandwidth": 32.0, "observer_mass": 2606.0}
    inputs = {"leg_length[2]": 3.0}
    watch = ["disturbance_estimate[1]", "disturbance_estimate[2]"]
    scalar = _run(native["leg_controller_fmu"], values, inputs, watch)
    matrix = _run(native["leg_controller_fmu"], {**values, "observer_model": 1}, inputs, watch)
    assert np.ptp(scalar[:, 0]) == 0 and np.ptp(matrix[:, 0]) > 0
    m_leg = design.leg_mass_matrix(StewartParams.paper())
    m_o = m_leg + (values["observer_mass"] - np.trace(m_leg) / 6) * np.eye(6)
    moved = np.abs(matrix[:, 1]) > 1e-6 * np.abs(matrix[:, 1]).max()
    assert moved.sum() > 10
    np.testing.assert_allclose(matrix[moved, 0] / matrix[moved, 1], m_o[0, 1] / m_o[1, 1], rtol=1e-9)
    assert abs(m_o[0, 1] / m_o[1, 1]) > 0.01                  # a coupling the ratio can see
    np.testing.assert_allclose(matrix[:, 1], scalar[:, 1], rtol=1e-12, atol=1e-9 * np.abs(scalar[:, 1]).max())


def test_the_native_observer_remakes_its_kept_gains_when_the_step_changes(fmus, native):
    """The native LegController keeps the observer's constants for its bandwidth and step
    (mb_observer_gains); the pythonfmu twin makes them every step (mb_observer_update). A run
    whose step goes 1 ms -> 0.5 ms -> 1 ms gives the same numbers bit for bit in both, and
    differs from the same inputs at 1 ms throughout (the kept gains were remade)."""
    values = {"observer_bandwidth": 32.0, "observer_mass": 2606.0, "observer_model": 1}
    watch = ["leg_force[2]", "disturbance_estimate[2]", "disturbance_estimate[5]", "observer_state[6]"]

    def run(path, steps):
        inst, status = opened(path, **values)
        assert status == OK
        rows, t = [], 0.0
        for k, h in enumerate(steps):
            inst.set("leg_length[2]", 3.0 * (1 + 1e-3 * np.sin(0.3 * k)))
            inst.set("leg_force_measured[2]", 5e3 * (1 + 1e-3 * np.sin(0.3 * k)))
            assert step(inst, t, h) == OK
            t += h
            rows.append(reals(inst, watch))
        return np.array(rows)

    changing = [1e-3] * 20 + [5e-4] * 20 + [1e-3] * 20
    python, c = run(fmus["leg_controller_fmu"], changing), run(native["leg_controller_fmu"], changing)
    assert np.array_equal(python, c)
    steady = run(native["leg_controller_fmu"], [1e-3] * 60)
    assert np.array_equal(c[:20], steady[:20]) and not np.array_equal(c[20:], steady[20:])
