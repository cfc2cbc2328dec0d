"""The Telescope FMU's flexible feed support (support_* parameters, the support_load input,
the support_sway output): the pythonfmu FMU and its native twin bit for bit under a varying
load, with and without the axis servo; base_rate and base_acc the derivatives of base_pose
along a recorded run (central differences); the modes' state in the FMU state; the load
reaching the base only through that state (no direct feedthrough: catalogue.FEEDTHROUGH has
no telescope row, so the wind -> telescope -> wind cycle of a scenario is no algebraic loop)."""
import numpy as np
import pytest

from fmu_src import catalogue
from tests.fmu_helpers import DISCARD, OK, _stepping_failure, opened, outputs, reals, step

SUPPORT = {"support_frequency[1]": 1.8, "support_frequency[2]": 2.2, "support_load_gain": 1.25,
           "profile": 0, "start_delay": 0.2}
LOAD = np.array([300.0, 1500.0, -2600.0, -1500.0, 40.0, 0.0])   # N, N m: the wind's order at 10 m/s


def load_at(t):
    """A smooth wrench of gusts at 0.3 and 1.9 Hz (the second near the modes)."""
    return LOAD * (1 + 0.2 * np.sin(2 * np.pi * 0.3 * t) + 0.05 * np.sin(2 * np.pi * 1.9 * t + 1.0))


def drive(inst, n, h, start=0, names=None):
    """n steps of h from step ``start``, support_load set before each; the outputs after each."""
    rows = []
    for k in range(start, start + n):
        for j, value in enumerate(load_at(k * h)):
            inst.set(f"support_load[{j + 1}]", value)
        assert step(inst, k * h, h) == OK, inst.log[-3:]
        rows.append(reals(inst, names or outputs(inst.md)))
    return np.array(rows)


@pytest.mark.parametrize("servo", [0.0, 0.8])
def test_native_equals_python_bit_for_bit(fmus, native, servo):
    runs = []
    for paths in (fmus, native):
        inst, status = opened(paths["telescope_fmu"], servo_bandwidth=servo, **SUPPORT)
        assert status == OK, inst.log
        runs.append(np.vstack([reals(inst, outputs(inst.md)), drive(inst, 400, 2e-3)]))
    sway = runs[0][:, -6:]
    assert np.abs(sway[:, :2]).max() > 1e-4        # the modes move (0.1 mm and more)
    np.testing.assert_array_equal(runs[0], runs[1])


def test_rates_and_accelerations_are_the_derivatives_of_the_pose(native):
    """Along the slew's start (accelerating) under the load: central differences of the
    support's part of base_pose (base minus command_base: no servo, the command is the
    rigid base) against its part of base_rate, and of base_rate against base_acc, to the
    differences' O(h^2) and the held load's change over a step (1e-4 and 1e-3 of the scale; 3e-5 and
    3e-4 measured). The samples next to the trapezoid's corners are left out: there the
    rigid acceleration jumps, and with it the mode's (the differences straddle the jump)."""
    h = 1e-3
    inst, _ = opened(native["telescope_fmu"], **SUPPORT)
    names = [f"{v}[{k}]" for v in ("base_pose", "base_rate", "base_acc", "command_base_pose", "command_base_rate",
                                     "command_base_acc") for k in range(1, 7)]
    rows = drive(inst, 3000, h, names=names)
    pose, rate, acc = (rows[:, 6 * i:6 * i + 6] - rows[:, 18 + 6 * i:24 + 6 * i] for i in range(3))
    jumps = np.flatnonzero(np.abs(np.diff(rows[:, 30:36], axis=0)).max(axis=1) > 1e-4)
    smooth = np.ones(len(rows) - 2, bool)
    for k in jumps:
        smooth[max(k - 3, 0):k + 3] = False
    assert len(jumps) == 3 and smooth.sum() > 2950
    for value, derivative, tolerance in ((pose, rate, 1e-4), (rate, acc, 1e-3)):
        scale = np.abs(derivative).max(axis=0)
        assert scale[:2].min() > 1e-4                # the sway is in it (m/s, m/s2)
        error = np.abs((value[2:] - value[:-2]) / (2 * h) - derivative[1:-1])[smooth].max(axis=0)
        assert np.all(error <= tolerance * scale), error / scale


@pytest.mark.parametrize("implementation", ["native", "python"])
def test_modes_state_replays_bit_for_bit(fmus, native, implementation):
    """From a state saved after 50 steps (the modes swinging): the rest replays identically
    after fmi2SetFMUstate and after a serialise/deserialise round trip into a new instance."""
    path = (native if implementation == "native" else fmus)["telescope_fmu"]
    inst, _ = opened(path, servo_bandwidth=0.8, **SUPPORT)
    drive(inst, 50, 1e-3)
    state = inst.fmu.getFMUstate()
    blob = inst.fmu.serializeFMUstate(state)
    first = drive(inst, 30, 1e-3, start=50)
    inst.fmu.setFMUstate(state)
    np.testing.assert_array_equal(drive(inst, 30, 1e-3, start=50), first)
    other, _ = opened(path, servo_bandwidth=0.8, **SUPPORT)
    other.fmu.setFMUstate(other.fmu.deSerializeFMUstate(blob))
    np.testing.assert_array_equal(drive(other, 30, 1e-3, start=50), first)


def test_the_load_reaches_the_base_only_through_the_modes_state(fmus, native):
    """Setting support_load changes no output until a step integrates it; after one step
    of h from rest (the antenna still) the sway is the mode's exact response to the held
    generalized force f = (F - 0.06 rad/m x 2.6815 m x F) / m (the default shape's tilt
    against the moment of F taken at the platform's home origin, below the tip):
    q(h) = f / w^2 (1 - e^{-zeta w h} (cos w_d h + zeta w / w_d sin w_d h))."""
    assert "telescope" not in catalogue.FEEDTHROUGH
    assert catalogue.BY_KEY["telescope"].optional_inputs == ("support_load",)
    h, force, m, zeta = 0.05, 2e3, 1e4, 0.015
    w = 2 * np.pi * 1.8
    wd = w * np.sqrt(1 - zeta ** 2)
    f = (force - 0.06 * 2.6815 * force) / m
    exact = f / w ** 2 * (1 - np.exp(-zeta * w * h) * (np.cos(wd * h) + zeta * w / wd * np.sin(wd * h)))
    for paths in (fmus, native):
        inst, _ = opened(paths["telescope_fmu"], start_delay=10.0, **{"support_frequency[1]": 1.8})
        names = outputs(inst.md)
        before = reals(inst, names)
        inst.set("support_load[1]", force)
        np.testing.assert_array_equal(reals(inst, names), before)
        assert step(inst, 0.0, h) == OK
        assert inst.get_real("support_sway[1]") == pytest.approx(exact, rel=1e-12)


def test_a_nan_load_discards_with_the_same_message(fmus, native):
    text = _stepping_failure(fmus, native, "telescope_fmu", {"support_frequency[1]": 1.8},
                             {"support_load[3]": float("nan")})
    assert "support_load input contains NaN or inf" in text
    inst, _ = opened(native["telescope_fmu"])   # rigid: the load is not read
    inst.set("support_load[3]", float("inf"))
    assert step(inst, 0.0, 1e-3) != DISCARD
