"""The antenna's axis servo (plant/c/telescope.c mb_tel_servo_*, the telescope FMU's
servo_bandwidth): against its transfer function w^2 / (s^2 + 2 zeta w s + w^2) with
python-control (step and frequency response), off = today's outputs, and the native FMU
equal to the pythonfmu one bit for bit."""
import control
import numpy as np
import pytest

from fmu_src import telescope_fmu
from plant.telescope import model as telescope
from tests.fmu_helpers import opened, outputs, reals, step

BANDWIDTH, DAMPING = 0.8, 0.7       # Hz, 1
W = 2 * np.pi * BANDWIDTH
SERVO = control.tf([W ** 2], [1, 2 * DAMPING * W, W ** 2])


def _advance(state, cmd0, cmd1, h, bandwidth=BANDWIDTH, damping=DAMPING):
    telescope.servo_advance(bandwidth, damping, h, np.asarray(cmd0, float), np.asarray(cmd1, float), state)


@pytest.mark.parametrize("h", [1e-3, 0.02, 0.5])   # 0.5 s: substeps (w h = 2.5)
def test_step_response_is_the_transfer_functions(h):
    """From rest at 0 under a constant command of 1 rad (elevation 0.3 rad): the angle
    against control.step_response, which integrates the linear system exactly."""
    T = np.arange(0, 6.0 + h / 2, h)
    state, angles = np.array([0.0, 0.0, 0.3, 0.0]), [0.0]
    for _ in T[1:]:
        _advance(state, [1.0, 0, 0, 0.3, 0, 0], [1.0, 0, 0, 0.3, 0, 0], h)
        angles.append(state[0])
        assert state[2] == 0.3 and state[3] == 0.0     # a resting axis stays
    truth = control.step_response(SERVO, T).outputs
    wh = W * h / np.ceil(W * h / 0.05)                 # w h of the RK4 substeps (<= 0.05)
    assert np.max(np.abs(np.array(angles) - truth)) < wh ** 4 / 100   # RK4's global error ~ (w h)^4
    assert np.max(truth) > 1.03                        # zeta 0.7 overshoots (4.6 % at the peak)


@pytest.mark.parametrize("frequency", [0.1, 0.8, 3.0])
def test_frequency_response_is_the_transfer_functions(frequency):
    """Command A = a sin(2 pi f t) (analytic rates) through axis_servo; after the start
    transient the response's amplitude ratio and phase at f, fitted by least squares,
    against control.frequency_response."""
    h, a, omega = 1e-3, 0.01, 2 * np.pi * frequency
    t = np.arange(0, 30.0, h)
    axes = telescope.AxisMotion(t, a * np.sin(omega * t), a * omega * np.cos(omega * t),
                                -a * omega ** 2 * np.sin(omega * t), np.full_like(t, 0.5),
                                np.zeros_like(t), np.zeros_like(t))
    actual = telescope.axis_servo(axes, BANDWIDTH, DAMPING)
    keep = t >= 10.0                                   # the start transient decays as exp(-zeta w t)
    basis = np.column_stack([np.sin(omega * t[keep]), np.cos(omega * t[keep])])
    (s, c), *_ = np.linalg.lstsq(basis, actual.A[keep], rcond=None)
    truth = control.frequency_response(SERVO, [omega])
    assert np.hypot(s, c) / a == pytest.approx(float(np.abs(truth.magnitude).ravel()[0]), rel=1e-6)
    assert np.arctan2(c, s) == pytest.approx(float(np.asarray(truth.phase).ravel()[0]), abs=1e-6)
    # the acceleration output is the servo's law: it is the rate's derivative (the central
    # difference's error h^2/6 |A''''| <~ (w h)^2 / 6 |A''|)
    error = np.abs(np.gradient(actual.A_dot, h)[5:-5] - actual.A_ddot[5:-5])
    assert error.max() < 2 * max(W, omega) ** 2 * h ** 2 / 6 * np.abs(actual.A_ddot).max()


def _slave(**settings):
    slave = telescope_fmu.Telescope(instance_name="servo")
    slave.settings.update(settings)
    slave.initialize()
    return slave


def test_servo_off_outputs_are_todays_and_the_command():
    slave = _slave(start_delay=1.0)
    times = [0.0]
    rows = [slave.now.copy()]
    for k in range(2000):
        slave.step(k * 1e-3, 1e-3)
        times.append((k + 1) * 1e-3)
        rows.append(slave.now.copy())
    rows = np.array(rows)
    today = np.vstack([telescope.telescope_outputs(slave.params, slave.motion, np.zeros(1)),   # the FMU's times:
                       telescope.telescope_outputs(slave.params, slave.motion, 1e-3 + 1e-3 * np.arange(1000))])
    np.testing.assert_array_equal(rows[:1001, :40], today)
    np.testing.assert_array_equal(rows[:, 40:58], rows[:, :18])   # the command is the motion
    axes = telescope.profile_axes(slave.params, slave.motion, np.array(times))
    np.testing.assert_allclose(rows[:, 58], -axes[:, 2], rtol=0, atol=1e-15)
    np.testing.assert_allclose(rows[:, 59], axes[:, 5], rtol=0, atol=1e-15)


def test_servo_on_lags_the_command_and_follows_axis_servo():
    """Slew with the servo: base_* are the base motion of axis_servo(command) on the same
    grid (and base_acc is the derivative of base_rate), command_base_* today's base_*."""
    h, n = 1e-3, 8000
    slave = _slave(start_delay=1.0, servo_bandwidth=BANDWIDTH, servo_damping=DAMPING)
    rows = [slave.now.copy()]
    for k in range(n):
        slave.step(k * h, h)
        rows.append(slave.now.copy())
    rows, t = np.array(rows), np.r_[0.0, h * np.arange(n) + h]   # the times as the FMU forms them
    command = telescope._axes(slave.params, slave.motion, t)
    pose, rate, acc = telescope.base_motion(slave.params, telescope.axis_servo(command, BANDWIDTH, DAMPING))
    np.testing.assert_allclose(rows[:, :18], np.hstack([pose, rate, acc]), rtol=0, atol=1e-12)
    np.testing.assert_array_equal(rows[:, 40:58], np.hstack(telescope.base_motion(slave.params, command)))
    np.testing.assert_allclose(np.gradient(rows[:, 6:12], h, axis=0)[2:-2], rows[2:-2, 12:18], rtol=0, atol=1e-6)
    # yaw = A: at the cruise rate the actual lags the commanded by the ramp error 2 zeta / w A'
    assert rows[-1, 45] - rows[-1, 5] == pytest.approx(2 * DAMPING / W * command.A_dot[-1], rel=1e-6)
    assert command.A_ddot[-3000:].max() == 0 and abs(command.A_dot[-1]) == pytest.approx(np.radians(0.5))
    assert np.abs(rows[:1000, :18] - rows[:1000, 40:58]).max() == 0   # at rest before the slew


@pytest.fixture(scope="module")
def native_telescope(native_fmus):
    return native_fmus["telescope_fmu"]


@pytest.mark.parametrize("settings", [dict(profile=0, start_delay=0.5, servo_bandwidth=0.8),
                                      dict(profile=2, servo_bandwidth=2.0, servo_damping=0.4),
                                      dict(profile=0, start_delay=0.5)])
def test_native_equals_python_bit_for_bit(fmus, native_telescope, settings):
    runs = []
    for path in (fmus["telescope_fmu"], native_telescope):
        inst, status = opened(path, **settings)
        assert status == 0, inst.log
        names = outputs(inst.md)
        rows = [reals(inst, names)]
        for k in range(1500):
            assert step(inst, k * 2e-3, 2e-3) == 0
            if k % 50 == 0:
                rows.append(reals(inst, names))
        runs.append(np.array(rows))
    assert runs[0].shape[1] == 66   # the 60 motion outputs and the support's sway
    np.testing.assert_array_equal(runs[0], runs[1])


def test_native_servo_state_replays_after_set_and_deserialise(native_telescope):
    """The servo state is part of the FMU state: from a state saved mid-slew the run
    replays bit for bit (the native layer saves the model's bytes)."""
    inst, status = opened(native_telescope, servo_bandwidth=0.8, start_delay=0.01)
    assert status == 0
    names = ["base_acc[6]", "axis[1]", "command_base_pose[6]"]

    def run(instance, start, n):
        rows = []
        for k in range(start, start + n):
            assert step(instance, k * 1e-3, 1e-3) == 0
            rows.append(reals(instance, names))
        return np.array(rows)

    run(inst, 0, 200)
    state = inst.fmu.getFMUstate()
    blob = inst.fmu.serializeFMUstate(state)
    first = run(inst, 200, 300)
    inst.fmu.setFMUstate(state)
    np.testing.assert_array_equal(run(inst, 200, 300), first)
    other, _ = opened(native_telescope, servo_bandwidth=0.8, start_delay=0.01)
    other.fmu.setFMUstate(other.fmu.deSerializeFMUstate(blob))
    np.testing.assert_array_equal(run(other, 200, 300), first)
