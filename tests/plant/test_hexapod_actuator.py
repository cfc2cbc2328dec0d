"""The electromechanical leg actuator and the platform wrench of the hexapod plant
(plant/c/hexapod.c mb_hexapod_advance_actuated, plant.hexapod.ode.Actuator), each against
an independent truth:

- force loop: step and frequency response of the delivered force against the transfer
  function 1 / (1 + s / (2 pi f)) (python-control; the command is held over each step, so
  the sampled truth is its zero-order-hold discretisation). The force state depends on
  the command only, so the free plant (fixed base, friction off) is the test rig;
- reflected mass: energy conservation of the free platform with the kinetic energy
  u^T M0 u / 2 of the ideal kernel plus m_r ld^2 / 2 per leg (M0 without reflected mass);
- friction: the dissipated power F_fric . ld <= 0 at every sample, and the energy lost
  equal to the integral of that power (friction laws evaluated here in numpy);
- wrench: statics by virtual work (leg-length derivatives by finite differences of the
  inverse kinematics, potential m_p g z), and a platform held by its wrench alone.
"""
import math

import control
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from plant.errors import InvalidInputError
from plant.hexapod import kernel as kane
from plant.hexapod.model import HOME_POSE, StewartParams, inverse_dynamics, inverse_kinematics
from plant.hexapod.ode import Actuator, HexapodODE
from tests.fmu_helpers import open_fmu

PARAMS = StewartParams.paper()
M_P, G = PARAMS.kernel_data[0], PARAMS.kernel_data[10]
STATIC = inverse_dynamics(PARAMS, HOME_POSE, np.zeros(6), np.zeros(6), fidelity="massless_legs")


def _ode(actuator, max_step=1e-3, fidelity="massless_legs"):
    return HexapodODE(PARAMS, fidelity, moving_base=False, max_step=max_step, actuator=actuator)


def _delivered(ode, x, commands, h=1e-3):
    """Delivered leg forces after each step of the held ``commands`` (n, 6)."""
    out = []
    for k, command in enumerate(commands):
        ode.set_inputs(k * h, command)
        ode.advance(x, h)
        out.append(ode.outputs[3].copy())
    return np.array(out)


def test_force_step_follows_the_first_order_loop():
    bandwidth, h, n = 15.0, 1e-3, 150
    ode = _ode(Actuator(bandwidth=bandwidth))
    ode.set_inputs(0.0, STATIC)
    x = ode.initial_state(HOME_POSE)
    step = np.array([40.0, -30.0, 20.0, 10.0, -50.0, 25.0])
    forces = _delivered(ode, x, np.tile(STATIC + step, (n, 1)), h)
    t = h * np.arange(n + 1)
    _, truth = control.step_response(control.tf([1.0], [1 / (2 * math.pi * bandwidth), 1.0]), t)
    truth, t = truth[1:], t[1:]   # sample k: the force at the end of step k
    np.testing.assert_allclose(forces - STATIC, np.outer(truth, step), rtol=0, atol=1e-4)
    assert abs(truth[10] - 1 + math.exp(-2 * math.pi * bandwidth * t[10])) < 1e-9   # the TF is the design


@pytest.mark.parametrize("frequency", [2.0, 15.0, 60.0])
def test_force_frequency_response_matches_the_transfer_function(frequency):
    bandwidth, h = 15.0, 1e-3
    periods = max(3, int(round(frequency * 0.4)))
    n = int(round(periods / (frequency * h)))
    ode = _ode(Actuator(bandwidth=bandwidth))
    ode.set_inputs(0.0, STATIC)
    x = ode.initial_state(HOME_POSE)
    t = h * np.arange(n)
    amplitude = 20.0
    command = STATIC + amplitude * np.sin(2 * math.pi * frequency * t)[:, None]
    forces = _delivered(ode, x, command, h)[:, 0] - STATIC[0]   # sample k: the force at t_{k+1}
    gd = control.c2d(control.tf([1.0], [1 / (2 * math.pi * bandwidth), 1.0]), h, "zoh")
    _, expected = control.forced_response(gd, T=t, U=amplitude * np.sin(2 * math.pi * frequency * t))
    # the simulation from rest at the holding force is the discrete system's response from 0
    np.testing.assert_allclose(forces[:-1], expected[1:], rtol=0, atol=1e-4 * amplitude)
    # and its steady state has the gain and phase of the design G(jw), to the hold's half-step delay
    tail = slice(n // 2, n - 1)
    w = 2 * math.pi * frequency
    basis = np.c_[np.sin(w * t[1:][tail]), np.cos(w * t[1:][tail])]
    (a, b), *_ = np.linalg.lstsq(basis, forces[:-1][tail], rcond=None)
    response = complex(a, b) / amplitude
    design = 1 / (1 + 1j * frequency / bandwidth)
    assert abs(abs(response) - abs(design)) < 5e-3
    assert abs(np.angle(response / design) + w * h / 2) < 5e-3   # zero-order hold: -w h / 2


def test_force_limit_clips_the_command():
    ode = _ode(Actuator(force_limit=2000.0))
    ode.set_inputs(0.0, STATIC)
    x = ode.initial_state(HOME_POSE)
    command = np.array([1e5, -1e5, 1500.0, -1500.0, 3000.0, -2000.0])
    forces = _delivered(ode, x, [command])[0]
    np.testing.assert_array_equal(forces, np.clip(command, -2000.0, 2000.0))
    lagged = _ode(Actuator(bandwidth=50.0, force_limit=2000.0))
    lagged.set_inputs(0.0, command)
    x = lagged.initial_state(HOME_POSE)
    np.testing.assert_array_equal(x[12:], np.clip(command, -2000.0, 2000.0))


def _energy(x, reflected_mass, forces):
    """Kinetic (ideal kernel's M0 + m_r ld^2 / 2 per leg) + gravity + the potential of the
    constant leg forces (-F l) of state x, massless legs, fixed base."""
    z = np.zeros((1, 6))
    M, _, J, *_ = PARAMS.kernel.run(x[None, :6], x[None, 6:12], z, z, z, z,
                                    kane.BASE_NONE, False, True, kane.TERMS)
    u = x[6:12]
    ld = J[0] @ u
    lengths = inverse_kinematics(PARAMS, x[:6])
    return 0.5 * u @ M[0] @ u + 0.5 * reflected_mass * ld @ ld + M_P * G * x[2] - forces @ lengths


def _free_motion(actuator, n, h=1e-3, max_step=1e-3):
    ode = _ode(actuator, max_step)
    x = np.r_[HOME_POSE, 0.01, -0.02, 0.015, 0.004, -0.003, 0.005]
    states, rates = [x.copy()], [None]
    for k in range(n):
        ode.set_inputs(k * h, STATIC)
        ode.advance(x, h)
        states.append(x.copy())
        rates.append(ode.outputs[1].copy())
    return states, rates


def test_reflected_mass_conserves_energy_with_its_kinetic_term():
    m_r = 400.0
    states, _ = _free_motion(Actuator(reflected_mass=m_r), 400)
    energy = np.array([_energy(x, m_r, STATIC) for x in states])
    scale = 0.5 * m_r * 0.02 ** 2
    assert np.abs(energy - energy[0]).max() < 1e-8 * scale
    without = np.array([_energy(x, 0.0, STATIC) for x in states])   # the term matters
    assert np.abs(without - without[0]).max() > 1e-3 * scale
    ideal, _ = _free_motion(Actuator(), 400)
    assert np.abs(ideal[-1][:6] - states[-1][:6]).max() > 1e-5   # and it slows the platform


def test_friction_dissipates_the_energy_it_takes():
    coulomb, viscous, v_s, h = 150.0, 4000.0, 1e-3, 2e-4
    states, rates = _free_motion(Actuator(coulomb=coulomb, viscous=viscous, friction_velocity=v_s), 1500, h, h)
    energy = np.array([_energy(x, 0.0, STATIC) for x in states])
    ld = np.array([kane_rates(x) for x in states])
    power = -np.sum((coulomb * np.tanh(ld / v_s) + viscous * ld) * ld, axis=1)   # F_fric . ld
    assert (power <= 0).all()
    np.testing.assert_allclose(ld[1:], np.array(rates[1:]), rtol=0, atol=1e-15)
    dissipated = np.concatenate([[0.0], np.cumsum(0.5 * (power[1:] + power[:-1]) * h)])
    lost = energy - energy[0]
    np.testing.assert_allclose(lost, dissipated, rtol=0, atol=2e-3 * abs(dissipated[-1]))
    assert abs(dissipated[-1]) > 0.3 * (0.5 * 0.02 ** 2 * M_P)   # most of the motion is taken


def kane_rates(x):
    out = np.zeros((3, 6))
    PARAMS.kernel.leg_kinematics(np.ascontiguousarray(x[:12]), out)
    return out[1]


def _rotated(pose, axis, angle):
    """pose with its rotation turned by ``angle`` about ``axis`` of {B}."""
    R = Rotation.from_rotvec(angle * np.eye(3)[axis]) * Rotation.from_euler("ZYX", pose[5:2:-1])
    return np.r_[pose[:3], R.as_euler("ZYX")[::-1]]


@pytest.mark.parametrize("offset", [np.zeros(6), np.array([0.01, -0.02, 0.03, 0.02, -0.01, 0.03])])
def test_wrench_statics_by_virtual_work(offset):
    pose = HOME_POSE + offset
    wrench = np.array([300.0, -500.0, 2000.0, 150.0, -400.0, 250.0])
    z = np.zeros((1, 6))
    *_, forces, _ = PARAMS.kernel.run(pose[None], z, z, z, z, z, kane.BASE_NONE, False, True, kane.ID)
    out = [np.empty((1, 6, 6)), np.empty((1, 6)), np.empty((1, 6, 6)), np.empty((1, 6)), np.empty((1, 6)),
           np.empty((1, 6)), np.empty(1)]
    kane.kane(PARAMS.base_joints, PARAMS.platform_joints, PARAMS.kernel_data, pose[None], np.zeros((1, 6)),
              np.zeros((1, 6)), np.zeros((1, 6)), np.zeros((1, 6)), np.zeros((1, 6)), kane.BASE_NONE, False, True,
              kane.ID, *out, wrench=wrench[None])
    f_w = out[5][0]
    # virtual work: sum F_j dl_j + W . d = dV for every virtual displacement d of {P}
    eps = 1e-6
    dl = []
    for k in range(6):
        if k < 3:
            plus, minus = pose + eps * np.eye(6)[k], pose - eps * np.eye(6)[k]
        else:
            plus, minus = _rotated(pose, k - 3, eps), _rotated(pose, k - 3, -eps)
        dl.append((inverse_kinematics(PARAMS, plus) - inverse_kinematics(PARAMS, minus)) / (2 * eps))
    dl = np.array(dl)   # (displacement, leg)
    dV = M_P * G * np.eye(6)[2]
    np.testing.assert_allclose(dl @ f_w + wrench, dV, rtol=0, atol=1e-6 * M_P * G)
    np.testing.assert_allclose(dl @ forces[0], dV, rtol=0, atol=1e-6 * M_P * G)   # and without the wrench


def test_platform_held_by_its_wrench_alone_stays_at_rest():
    ode = _ode(Actuator())
    x = np.r_[HOME_POSE, np.zeros(6)]
    for k in range(100):
        ode.set_inputs(k * 1e-3, np.zeros(6), wrench=[0.0, 0.0, M_P * G, 0.0, 0.0, 0.0])
        ode.advance(x, 1e-3)
    assert np.abs(x - np.r_[HOME_POSE, np.zeros(6)]).max() < 1e-12
    free = _ode(Actuator())
    y = np.r_[HOME_POSE, np.zeros(6)]
    free.set_inputs(0.0, np.zeros(6))
    free.advance(y, 0.1)
    assert y[2] < HOME_POSE[2] - 0.04   # without it the platform falls


def test_all_off_is_the_ideal_plant_bit_for_bit():
    rng = np.random.default_rng(3)
    for _ in range(20):
        x0 = np.r_[HOME_POSE + rng.normal(0, 1e-2, 6), rng.normal(0, 0.05, 6)]
        inputs = np.r_[STATIC + rng.normal(0, 300, 6), rng.normal(0, 1e-3, 18)].reshape(4, 6)
        bounds = np.r_[PARAMS.home_lengths - 0.2, PARAMS.home_lengths + 0.2].reshape(2, 6)
        for mode in (kane.BASE_NONE, kane.BASE_FULL):
            a, b = x0.copy(), x0.copy()
            out_a, out_b = np.zeros((3, 6)), np.zeros((4, 6))
            da, sa = PARAMS.kernel.advance_fixed(True, 2, a, inputs, 0.0, 1e-3, mode, True, bounds, out_a)
            db, sb = PARAMS.kernel.advance_actuated(True, 2, Actuator().data, b, np.r_[inputs, np.zeros((1, 6))],
                                                    0.0, 1e-3, mode, True, bounds, out_b)
            assert (da, sa) == (db, sb)
            assert a.tobytes() == b.tobytes() and out_a.tobytes() == out_b[:3].tobytes()
            np.testing.assert_array_equal(out_b[3], inputs[0])


def test_bad_actuator_values_are_named():
    with pytest.raises(InvalidInputError, match="coulomb must be finite and >= 0"):
        Actuator(coulomb=-1.0)
    with pytest.raises(InvalidInputError, match="friction_velocity must be finite and > 0"):
        Actuator(friction_velocity=0.0)
    with pytest.raises(InvalidInputError, match="bandwidth 1000 Hz is too fast for rk4 at max_step 0.001"):
        _ode(Actuator(bandwidth=1000.0))


ON = dict(actuator_bandwidth=40.0, reflected_mass=300.0, coulomb_friction=80.0, viscous_friction=2000.0,
          friction_velocity=1e-3, actuator_force_limit=9000.0, moving_base=0)


def test_native_plant_equals_python_with_the_actuator_on(fmus, native_fmus):
    """Both FMUs with every effect on and a wrench: the same bytes, and a saved FMU state
    (the motor forces with it) replays."""
    native = native_fmus["hexapod_plant_fmu"]
    runs = []
    for path in (fmus["hexapod_plant_fmu"], native):
        plant = open_fmu(path, **ON, **{f"leg_force[{i + 1}]": STATIC[i] for i in range(6)})
        for i, w in enumerate([50.0, -80.0, 300.0, 20.0, 0.0, -40.0]):
            plant.set(f"platform_wrench[{i + 1}]", w)
        rows = []
        for k in range(60):
            for i in range(6):
                plant.set(f"leg_force[{i + 1}]", STATIC[i] + 200.0 * math.sin(0.1 * k + i))
            plant.do_step(k * 1e-3, 1e-3)
            if k == 29:
                saved = plant.fmu.getFMUState()
            rows.append([plant.get_real(f"{v}[{i + 1}]") for v in ("pose", "leg_force_actual") for i in range(6)])
        plant.fmu.setFMUState(saved)
        for k in range(30, 60):
            for i in range(6):
                plant.set(f"leg_force[{i + 1}]", STATIC[i] + 200.0 * math.sin(0.1 * k + i))
            plant.do_step(k * 1e-3, 1e-3)
        replay = [plant.get_real(f"{v}[{i + 1}]") for v in ("pose", "leg_force_actual") for i in range(6)]
        assert replay == rows[-1]
        plant.fmu.freeFMUState(saved)
        runs.append(np.array(rows))
    assert runs[0].tobytes() == runs[1].tobytes()
    assert np.abs(runs[0][-1, 6:] - STATIC).max() > 1.0   # the actuator acted


def test_radau_follows_rk4_with_every_effect_on():
    """The python plant's implicit path (scipy Radau over the same C right-hand side, 18
    states) against RK4: the same motion to Radau's tolerance."""
    actuator = Actuator(bandwidth=20.0, reflected_mass=300.0, coulomb=50.0, viscous=1000.0, friction_velocity=1e-3)
    results = []
    for method in ("rk4", "radau"):
        ode = HexapodODE(PARAMS, moving_base=False, method=method, actuator=actuator)
        ode.set_inputs(0.0, STATIC + 100.0, wrench=[10.0, 0.0, 0.0, 0.0, 0.0, 5.0])
        x = ode.initial_state(HOME_POSE)
        x[12:] = STATIC
        for k in range(50):
            ode.t0 = k * 1e-3
            ode.advance(x, 1e-3)
        results.append((x.copy(), ode.outputs[3].copy()))
    np.testing.assert_allclose(results[0][0][:12], results[1][0][:12], rtol=0, atol=1e-6)
    np.testing.assert_allclose(results[0][1], results[1][1], rtol=0, atol=1e-3)
    assert (results[0][0][12:] - STATIC > 90.0).all()   # the force loop followed the 100 N step


def test_native_plant_refuses_a_force_loop_too_fast_as_python_does(fmus, native_fmus):
    from tests.fmu_helpers import failure_lines, opened
    native = native_fmus["hexapod_plant_fmu"]
    lines = []
    for path in (fmus["hexapod_plant_fmu"], native):
        inst, status = opened(path, actuator_bandwidth=1000.0)
        assert status != 0
        lines.append([line for line in failure_lines(inst) if "too fast" in line])
    assert lines[0] == lines[1] and len(lines[0]) == 1
    assert "actuator bandwidth 1000 Hz is too fast for rk4 at max_step 0.001 s" in lines[0][0]


# --------------------------------------------- error-controlled substeps (tolerance > 0)
SHIPPED_ACTUATOR = dict(bandwidth=50.0, reflected_mass=758.0, coulomb=200.0, viscous=2000.0, force_limit=25e3)


def _sliding_then_sticking(actuator, n, max_step, tolerance=0.0, fidelity="massless_legs"):
    """Poses of the free platform launched at a few mm/s (its legs slide, slow down and
    stick) under the held static forces plus a step in the command, every 1 ms step."""
    ode = HexapodODE(PARAMS, fidelity, moving_base=False, max_step=max_step, actuator=actuator, tolerance=tolerance)
    ode.set_inputs(0.0, STATIC)
    x = ode.initial_state(HOME_POSE)
    x[6:12] = [0.004, -0.003, 0.002, 0.002, -0.001, 0.003]
    poses, substeps = [], 0
    for k in range(n):
        ode.set_inputs(k * 1e-3, STATIC + 300.0 * np.sin(0.05 * k + np.arange(6)))
        ode.advance(x, 1e-3)
        poses.append(x[:6].copy())
        substeps += PARAMS.kernel.counts[0] if tolerance else 0
    return np.array(poses), substeps


def test_controlled_substeps_integrate_the_lag_exactly():
    """The force loop is linear and its command held over a step: F(t0 + h) = F_cmd + (F(t0)
    - F_cmd) exp(-2 pi f h), to rounding, whatever substeps the friction asks for (fixed
    RK4 substeps of 1 ms miss it by RK4's error at 2 pi f h = 0.31, ~2.6e-5 of the step)."""
    bandwidth = 50.0
    step = np.array([400.0, -300.0, 200.0, 100.0, -500.0, 250.0])
    forces = {}
    for tolerance in (1e-10, 0.0):
        ode = HexapodODE(PARAMS, "massless_legs", moving_base=False, max_step=1e-3, tolerance=tolerance,
                         actuator=Actuator(**SHIPPED_ACTUATOR))
        ode.set_inputs(0.0, STATIC)
        x = ode.initial_state(HOME_POSE)
        truth = x[12:].copy()
        for k in range(5):
            ode.set_inputs(k * 1e-3, STATIC + step)
            ode.advance(x, 1e-3)
            truth = STATIC + step + (truth - STATIC - step) * math.exp(-2 * math.pi * bandwidth * 1e-3)
        forces[tolerance] = x[12:]
    np.testing.assert_allclose(forces[1e-10], truth, rtol=0, atol=1e-9)   # ~4e3 N: 2.5e-13 relative
    assert abs(truth - STATIC - step).max() > 50.0   # the lag is still in its transient
    assert abs(forces[0.0] - truth).max() > 1e-3


@pytest.mark.parametrize("friction_velocity, tolerance, substeps, fixed_error",
                         [(1e-4, 1e-10, (45, 58), 1e-9), (1e-5, 1e-11, (110, 135), 3e-7)])
def test_controlled_substeps_follow_a_stiff_friction(friction_velocity, tolerance, substeps, fixed_error):
    """Against RK4 at 1 µs fixed substeps (converged: 0.5 µs agrees to 1e-13 m), the free
    platform whose legs slide and stick, pushed by a varying command, under the shipped
    screw (v_s 0.1 mm/s: slope 2e6 N s/m) at the shipped tolerance, and under one 10x
    steeper at a 10x smaller one: within 0.5 nm at every 1 ms step, on about one substep a
    step for the shipped screw (40 steps), three for the steeper. Fixed 1 ms substeps
    miss by ``fixed_error`` and more."""
    actuator = Actuator(**SHIPPED_ACTUATOR, friction_velocity=friction_velocity)
    n = 40
    reference, _ = _sliding_then_sticking(actuator, n, 1e-6)
    assert np.abs(reference[-1] - reference[0]).max() > 5e-5   # the platform moved
    poses, taken = _sliding_then_sticking(actuator, n, 1e-3, tolerance)
    assert np.abs(poses - reference).max() < 5e-10
    assert substeps[0] <= taken <= substeps[1]
    fixed, _ = _sliding_then_sticking(actuator, n, 1e-3)
    assert np.abs(fixed - reference).max() > fixed_error


def test_controlled_substeps_refuse_endless_work_and_leave_the_state():
    """More tries than max_substeps: status WORK, x as it came (the FMU then reports a
    WorkBoundError and a host may retry the step)."""
    ode = HexapodODE(PARAMS, "massless_legs", moving_base=False, max_step=1e-3, tolerance=1e-10,
                     actuator=Actuator(**SHIPPED_ACTUATOR, friction_velocity=1e-7))
    ode.set_inputs(0.0, STATIC + 500.0)
    x = ode.initial_state(HOME_POSE)
    x[6:12] = 0.003
    before = x.copy()
    _, status = PARAMS.kernel.advance_controlled(1e-18, 1e-3, 10, ode._actuator, x, ode._inputs, 0.0, 1e-3,
                                                 ode.base_mode, ode.legs, ode._bounds, ode._outputs)
    assert status == kane.WORK
    assert x.tobytes() == before.tobytes()
    assert PARAMS.kernel.counts[0] + PARAMS.kernel.counts[1] == 10


@pytest.mark.parametrize("method, tolerance, words", [("euler", 1e-10, "needs integrator rk4"),
                                                      ("rk4", -1e-10, "finite and >= 0"),
                                                      ("rk4", math.nan, "finite and >= 0")])
def test_a_tolerance_the_integrator_cannot_take_is_refused(method, tolerance, words):
    with pytest.raises(InvalidInputError, match=words):
        HexapodODE(PARAMS, method=method, tolerance=tolerance)
