"""Controller tests, each against a truth computed independently of the code under test."""
import dataclasses

import control
import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.linalg import expm
from scipy.optimize import brentq

from controller.design import (
    IDEAL,
    REALISTIC,
    Design,
    closed_loop_stable,
    default_gains,
    design_pid,
    leg_mass_matrix,
    linearised_plant,
    margins,
    max_stable_step,
    mode_loop,
    stiffest_pid,
)
from controller.feedforward import (
    FEEDFORWARD_MODES,
    Feedforward,
    feedforward_and_legs,
    feedforward_forces,
    reference_legs,
)
from controller.pid import PIDGains, pid_step
from plant.hexapod.model import (
    HOME_POSE,
    StewartParams,
    forward_dynamics,
    inverse_dynamics,
    inverse_kinematics,
    pose_jacobian,
)
from plant.trajectory import quintic

PARAMS = StewartParams.paper()
STEP = 1e-3


@pytest.fixture(scope="module")
def plant():
    return linearised_plant(PARAMS)


@pytest.fixture(scope="module")
def design():
    return design_pid(PARAMS, 8.0, 60.0, STEP)


# ------------------------------------------------------------------------ linearisation
def test_linearised_plant_matches_nonlinear_step_response(plant):
    """A small force step from equilibrium: linear model vs solve_ivp of forward_dynamics."""
    rest = np.zeros(6)
    hold = inverse_dynamics(PARAMS, HOME_POSE, rest, rest)
    step = np.array([20.0, -10.0, 5.0, 0.0, 15.0, -8.0])
    times = np.linspace(0, 0.5, 51)

    def rhs(_, state):
        return np.concatenate([state[6:], forward_dynamics(PARAMS, state[:6], state[6:], hold + step)])

    truth = solve_ivp(rhs, (0, times[-1]), np.concatenate([HOME_POSE, rest]), t_eval=times,
                      rtol=1e-10, atol=1e-13, method="DOP853")
    legs = inverse_kinematics(PARAMS, truth.y[:6].T) - PARAMS.home_lengths
    linear = control.forced_response(plant, times, np.tile(step[:, None], (1, times.size))).outputs.T
    scale = np.abs(legs).max()
    assert scale > 1e-4  # the step moved the legs measurably
    assert np.abs(linear - legs).max() < 1e-3 * scale
    # Gravity stiffness is in the model: without it the error is far larger.
    floppy = control.ss(plant.A * np.r_[np.zeros(6), np.ones(6)][None, :], plant.B, plant.C, plant.D)
    no_stiffness = control.forced_response(floppy, times, np.tile(step[:, None], (1, times.size))).outputs.T
    assert np.abs(no_stiffness - legs).max() > 1e-2 * scale


def test_linearised_plant_shape_and_output_is_leg_kinematics(plant):
    assert (plant.nstates, plant.ninputs, plant.noutputs) == (12, 6, 6)
    dpose = np.array([1e-6, -2e-6, 3e-6, 1e-6, 2e-6, -1e-6])
    expected = inverse_kinematics(PARAMS, HOME_POSE + dpose) - PARAMS.home_lengths
    assert np.allclose(plant.C @ np.r_[dpose, np.zeros(6)], expected, rtol=1e-5, atol=1e-14)


# ------------------------------------------------------------------------------- PID
def test_pid_hand_worked_sequence():
    gains = PIDGains(kp=2.0, ki=3.0, kd=0.5, force_limit=100.0)
    dt = 0.1
    # Step 1: e = 1, de = 0 - 0.5, I = 0.1 -> 10 + 2 + 0.3 - 0.25
    force, state = pid_step(gains, np.zeros(6), 1.0, 0.0, np.zeros(6), np.full(6, 0.5), 10.0, dt)
    assert np.allclose(force, 12.05) and np.allclose(state, 0.1)
    # Step 2: e = 0.5, de = 0.2 - 0.1, I = 0.15 -> 1 + 0.45 + 0.05
    force, state = pid_step(gains, state, 1.0, 0.2, np.full(6, 0.5), np.full(6, 0.1), 0.0, dt)
    assert np.allclose(force, 1.5) and np.allclose(state, 0.15)
    # Legs are independent: leg i sees error i.
    force, state = pid_step(gains, np.zeros(6), np.arange(6.0), 0.0, 0.0, 0.0, 0.0, dt)
    assert np.allclose(force, np.arange(6.0) * (2 + 3 * dt)) and np.allclose(state, np.arange(6.0) * dt)


def test_pid_saturates_both_ways():
    gains = PIDGains(kp=1e3, ki=0.0, kd=0.0, force_limit=50.0)
    force, _ = pid_step(gains, np.zeros(6), np.array([1, -1, 0.01, -0.01, 0, 0.0]), 0.0, 0.0, 0.0, 0.0, 1e-3)
    assert np.allclose(force, [50, -50, 10, -10, 0, 0])


def test_pid_anti_windup_freezes_integral_and_recovers_at_once():
    gains = PIDGains(kp=10.0, ki=100.0, kd=0.0, force_limit=20.0)
    state = np.zeros(6)
    for _ in range(200):  # a large error keeps the output saturated for 0.2 s
        force, state = pid_step(gains, state, 5.0, 0.0, 0.0, 0.0, 0.0, 1e-3)
        assert np.allclose(force, 20.0)
    assert np.allclose(state, 0.0)  # no windup (a free integrator would hold 1.0 m s -> 100 N)
    force, state = pid_step(gains, state, 0.0, 0.0, 0.01, 0.0, 0.0, 1e-3)  # error reverses
    assert np.all(np.abs(force) < 20.0) and np.all(force < 0)  # out of saturation on the first step


def test_pid_integrates_when_error_pulls_out_of_saturation():
    gains = PIDGains(kp=0.0, ki=1e3, kd=0.0, force_limit=20.0)
    # Feedforward alone saturates; a negative error reduces the force, so it must integrate.
    force, state = pid_step(gains, np.zeros(6), 0.0, 0.0, 0.01, 0.0, 30.0, 1e-3)
    assert np.allclose(state, -1e-5) and np.allclose(force, 20.0)


@pytest.mark.parametrize("position, name", [(2, "reference length"), (3, "reference rate"),
                                            (4, "measured length"), (5, "measured rate"),
                                            (6, "feedforward"), (1, "integral state")])
def test_pid_rejects_nan_naming_the_signal(position, name):
    args = [PIDGains(1.0, 1.0, 1.0), np.zeros(6), np.zeros(6), np.zeros(6), np.zeros(6), np.zeros(6),
            np.zeros(6), 1e-3]
    args[position] = np.array([0, 0, np.nan, 0, 0, 0.0])
    with pytest.raises(ValueError, match=name):
        pid_step(*args)


def test_pid_rejects_bad_step_and_gains():
    with pytest.raises(ValueError, match="time step"):
        pid_step(PIDGains(1.0, 1.0, 1.0), np.zeros(6), 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    with pytest.raises(ValueError, match="kd"):
        PIDGains(1.0, 1.0, -1.0)


# ---------------------------------------------------------------------------- design
def _loop_response(mass, gains, h, omega):
    """Independent closed form of the sampled per-leg loop: exact ZOH of 1/(m s^2) (length
    h^2 (z+1) / (2 m (z-1)^2), rate h / (m (z-1))), backward-Euler PID, one step delay."""
    z = np.exp(1j * omega * h)
    length = h ** 2 * (z + 1) / (2 * mass * (z - 1) ** 2)
    rate = h / (mass * (z - 1))
    return ((gains.kp + gains.ki * h * z / (z - 1)) * length + gains.kd * rate) / z


def _gain_margin(mass, gains, h, low, high):
    """1/|L| where L crosses the negative real axis between ``low`` and ``high`` rad/s."""
    omega = np.geomspace(low, high, 20000)
    imag = _loop_response(mass, gains, h, omega).imag
    i = np.flatnonzero(np.diff(np.sign(imag)))[0]
    w180 = brentq(lambda w: _loop_response(mass, gains, h, w).imag, omega[i], omega[i + 1], xtol=1e-12)
    response = _loop_response(mass, gains, h, w180)
    assert response.real < 0
    return -1 / response.real


def test_design_margins_match_independent_loop(design):
    gains, mass, h = design.gains, design.design_mass, design.comm_step
    assert mass == pytest.approx(np.linalg.eigvalsh(leg_mass_matrix(PARAMS)).max())
    w_c = 2 * np.pi * design.crossover_hz
    at_crossover = _loop_response(mass, gains, h, w_c)
    assert abs(at_crossover) == pytest.approx(1.0, abs=1e-6)
    assert np.degrees(np.angle(at_crossover)) + 180 == pytest.approx(design.phase_margin_deg, abs=1e-4)
    assert design.crossover_hz == pytest.approx(8.0, rel=1e-6)
    assert design.phase_margin_deg == pytest.approx(60.0, abs=1e-4)
    nyquist = np.pi / h
    gm = _gain_margin(mass, gains, h, w_c, 0.999 * nyquist)
    assert 20 * np.log10(gm) == pytest.approx(design.gain_margin_db, abs=1e-3)
    lower = _gain_margin(mass, gains, h, w_c / 100, w_c)  # integrator: phase -270 deg at low frequency
    assert 20 * np.log10(lower) == pytest.approx(design.lower_gain_margin_db, abs=1e-3)
    gm_light = _gain_margin(design.modal_masses.min(), gains, h, w_c, 0.999 * nyquist)
    assert 20 * np.log10(gm_light) == pytest.approx(design.modal_gain_margin_db, abs=1e-3)


def test_default_design_meets_its_requirements(design):
    assert default_gains(PARAMS, STEP) == design.gains
    assert isinstance(design, Design)
    assert 5 <= design.crossover_hz <= 10
    assert design.modal_phase_margin_deg >= 45 and design.modal_gain_margin_db >= 6
    # Every mode's loop is stable: 2 m z (z-1)^3 (1 + L) has its roots inside the unit circle.
    P = np.polynomial.Polynomial
    z = P([0, 1])
    g, h = design.gains, STEP
    for mass in design.modal_masses:
        numerator = (g.kp * (z - 1) + g.ki * h * z) * h ** 2 * (z + 1) + 2 * g.kd * h * (z - 1) ** 2
        assert np.abs((2 * mass * z * (z - 1) ** 3 + numerator).roots()).max() < 1
    assert closed_loop_stable(PARAMS, design.gains, STEP)[0]


def test_design_rejects_unreachable_or_destabilising_targets():
    with pytest.raises(ValueError, match="Nyquist"):
        design_pid(PARAMS, 60.0, 45.0, 10e-3)
    with pytest.raises(ValueError, match="out of reach"):
        design_pid(PARAMS, 20.0, 80.0, 10e-3)
    with pytest.raises(ValueError, match="destabilises the leg-space modes of 594"):
        design_pid(PARAMS, 30.0, 60.0, 1e-3)


# ------------------------------------------------------------------ the realistic loop
@pytest.fixture(scope="module")
def stiffest():
    """The search restricted to the integral ratio and phase target the full one picks (the
    same design in a tenth of the ~20 s the study spends on all twelve combinations)."""
    return stiffest_pid(PARAMS, STEP, integral_ratios=(2.0,), targets=(45.0,))


def test_realistic_loop_model_is_the_scenarios_loop():
    """REALISTIC carries the values the realistic scenario and study run with."""
    import tomllib

    from scenarios.runs import runner
    from scenarios.spec.units import to_si
    from studies import realistic_loop as study
    shipped = tomllib.loads(runner.resolve("telescope_slew_realistic").read_text())
    plant, sensor = shipped["fmus"]["plant"]["parameters"], shipped["fmus"]["sensor"]["parameters"]
    for values in (plant, study.ACTUATOR):
        assert to_si(values["reflected_mass"]) == REALISTIC.reflected_mass
        assert to_si(values["actuator_bandwidth"]) == REALISTIC.actuator_bandwidth
        assert to_si(values["viscous_friction"]) == REALISTIC.viscous_friction
    for values in (sensor, study.LEG_SENSOR):
        assert to_si(values["rate_cutoff"]) == REALISTIC.rate_cutoff
    assert sensor["delay_steps"] == study.DELAY["delay_steps"] == REALISTIC.delay_steps
    assert shipped["master"] == "jacobi" and (shipped["extrapolation"] == "linear") == REALISTIC.extrapolate


def _ideal_leg_loop(mass, gains, comm_step):
    """The shipped method's loop built from python-control blocks, independently of
    mode_loop: ZOH plant 1/(mass s^2) with sampled length and rate, the PID of
    controller.pid, one step of delay."""
    plant = control.c2d(control.ss([[0, 1], [0, 0]], [[0], [1 / mass]], np.eye(2), 0), comm_step, "zoh")
    pid = control.ss([[1.0]], [[comm_step, 0.0]], [[gains.ki]],
                     [[gains.kp + gains.ki * comm_step, gains.kd]], comm_step)
    delay = control.ss([[0.0]], [[1.0]], [[1.0]], [[0.0]], comm_step)
    return delay * pid * plant


def test_ideal_mode_loop_is_the_shipped_leg_loop(design):
    omega = np.geomspace(1.0, 0.99 * np.pi / STEP, 50)
    z = np.exp(1j * omega * STEP)
    for mass in design.modal_masses:
        assert np.allclose(mode_loop(mass, design.gains, STEP, IDEAL)(z), _ideal_leg_loop(mass, design.gains, STEP)(z),
                           rtol=1e-12)


def _realistic_response(mass, gains, h, omega):
    """Independent closed form of the realistic mode loop: ZOH of the actuator lag
    w/(s+w) and 1/(m s^2 + c s) by partial fractions, the sensor's z^-2 delay and
    filtered difference a (z-1) / (h (z - 1 + a)), backward-Euler PID, the controller's
    z^-1 and the master's extrapolation (3 - 1/z) / 2 on three connections."""
    w, c = 2 * np.pi * REALISTIC.actuator_bandwidth, REALISTIC.viscous_friction
    b = c / mass
    z = np.exp(1j * omega * h)
    # G(s) = w / (m s (s + b) (s + w)); ZOH: (1 - 1/z) Z{G(s)/s}, residues of G(s)/s at 0 (double), -b, -w
    k = w / mass
    r_b = k / (b ** 2 * (w - b))
    r_w = k / (w ** 2 * (b - w))
    r0 = -(r_b + r_w)                     # the 1/s term (double pole at 0: sum of residues is 0)
    r00 = k / (b * w)  # the 1/s^2 term
    step = (
        r00 * h * z / (z - 1) ** 2 + r0 * z / (z - 1) + r_b * z / (z - np.exp(-b * h)) + r_w * z / (z - np.exp(-w * h))
    )
    length = (1 - 1 / z) * step
    a = 1 - np.exp(-2 * np.pi * REALISTIC.rate_cutoff * h)
    late = z ** -(1 + REALISTIC.delay_steps)
    rate = a * (z - 1) / (h * (z - 1 + a))
    pid = (gains.kp + gains.ki * h * z / (z - 1)) + gains.kd * rate
    return ((3 - 1 / z) / 2) ** 3 / z * pid * late * length


def test_realistic_mode_loop_matches_independent_closed_form(stiffest):
    omega = np.geomspace(1.0, 0.99 * np.pi / STEP, 200)
    for mass in stiffest.modal_masses:
        got = mode_loop(mass, stiffest.gains, STEP, REALISTIC)(np.exp(1j * omega * STEP))
        assert np.allclose(got, _realistic_response(mass, stiffest.gains, STEP, omega), rtol=1e-7)


def _scaled(gains, factor):
    return dataclasses.replace(gains, kp=gains.kp * factor, ki=gains.ki * factor, kd=gains.kd * factor)


def test_stiffest_realistic_design_meets_the_bounds_on_every_mode(stiffest):
    """PM >= 45 deg on every mode, read off a denser grid than the design's; GM >= 6 dB
    both ways as closed-loop poles: every mode stays stable with the gains doubled and
    halved. The bound binds: 3 % more crossover at the same heavy-mode target and
    integral ratio breaks it."""
    assert stiffest.loop == REALISTIC
    assert stiffest.modal_masses[0] == pytest.approx(np.linalg.eigvalsh(leg_mass_matrix(PARAMS))[0] + 758.0)
    omega = np.geomspace(1.0, 0.999 * np.pi / STEP, 200000)
    for mass in stiffest.modal_masses:
        response = _realistic_response(mass, stiffest.gains, STEP, omega)
        crossings = np.flatnonzero(np.diff(np.sign(np.abs(response) - 1)))
        assert crossings.size
        phase_margins = 180 - np.abs(np.degrees(np.angle(response[crossings])))
        assert phase_margins.min() >= 45 - 0.05
        for factor in (2.0, 0.5):
            loop = mode_loop(mass, _scaled(stiffest.gains, factor), STEP, REALISTIC)
            assert np.abs(control.feedback(loop).poles()).max() < 1
    assert min(stiffest.modal_gain_margin_db, -stiffest.modal_lower_gain_margin_db) >= 6
    ratio = stiffest.gains.kp * 2 * np.pi * stiffest.crossover_hz / stiffest.gains.ki
    harder = design_pid(PARAMS, 1.03 * stiffest.crossover_hz, stiffest.phase_margin_deg, STEP, ratio, loop=REALISTIC)
    assert harder.gains.ki > stiffest.gains.ki
    assert (harder.modal_phase_margin_deg < 45 - 0.05 or harder.modal_gain_margin_db < 6
            or -harder.modal_lower_gain_margin_db < 6)


def test_shipped_gains_on_the_realistic_plant_are_recomputed_not_assumed(design):
    """The ideal-plant gains on the realistic plant: same gains, the margins of that loop
    (heavy mode's crossover moved by the 758 kg and the lags), and stable."""
    real = margins(PARAMS, design.gains, STEP, REALISTIC)
    assert real.gains == design.gains
    heavy = mode_loop(real.design_mass, design.gains, STEP, REALISTIC)
    at = heavy(np.exp(2j * np.pi * real.crossover_hz * STEP))
    assert abs(at) == pytest.approx(1.0, abs=1e-3)
    assert 180 - abs(np.degrees(np.angle(at))) == pytest.approx(real.phase_margin_deg, abs=0.05)


def test_loop_model_and_stiffest_search_reject_bad_input_naming_it():
    with pytest.raises(ValueError, match="reflected_mass must be finite and >= 0"):
        dataclasses.replace(REALISTIC, reflected_mass=-1.0)
    with pytest.raises(ValueError, match="delay_steps must be an integer"):
        dataclasses.replace(REALISTIC, delay_steps=1.5)
    with pytest.raises(ValueError, match="belong to the leg sensor"):
        dataclasses.replace(IDEAL, delay_steps=1)
    with pytest.raises(ValueError, match="no crossover gives phase margin >= 89"):
        stiffest_pid(PARAMS, STEP, phase_margin_deg=89.0, integral_ratios=(5.0,), targets=(60.0,))


def _cosim(tmp_path, gains, seconds=3.0):
    """The realistic slew's loop (leg encoders with noise, no quantisation; computation
    delay; actuator with its lag, reflected mass and viscous friction, Coulomb off: the
    linear part the design models) holding still under the fixed-base feedforward for
    ``seconds``, the leg lengths recorded every step; the sensor noise excites it."""
    from scenarios.runs import runner
    from studies import realistic_loop as study
    data = study.variant("telescope_slew", ("leg_sensors", "delay", "actuator"), "exact", ("fixed_base",),
                         {"leg_sensors": {"resolution": "0 um"}, "actuator": {"coulomb_friction": "0 N"}},
                         gains=("test", {"kp": gains.kp, "ki": gains.ki, "kd": gains.kd}))
    data["stop_time"], data["ci"] = f"{seconds} s", {"stop_time": f"{seconds} s"}
    data["record"] = {"interval": "1 ms", "variables": ["plant.leg_length"]}
    data["metrics"] = [m for m in data["metrics"] if m["kind"] == "leg_tracking"]
    data["metrics"][0]["from"] = "1 s"
    tmp_path.mkdir(parents=True, exist_ok=True)
    path = tmp_path / f"{data['name']}.toml"
    path.write_text(study.toml_text(data))
    [run] = runner.run_scenario(path, tmp_path / "out", ci=True, progress=False,
                                 allow_unstable=True)[1]   # the 1.25x gains: beyond the predicted limit, on purpose
    rows = np.column_stack([run.records.time, run.records.values])
    return run.metrics["leg error"]["rms"], rows[rows[:, 0] > 1.5, 1:]


def test_realistic_gain_margin_predicts_the_cosimulation(stiffest, tmp_path):
    """The co-simulation of the realistic loop with the gains at 0.8x the predicted gain
    margin stays still (leg error under 1 µm: the 20 nm sensor noise, amplified near the
    limit), at 1.25x it oscillates into the force limits, at the frequency where
    python-control puts the lightest mode's phase crossover (within 3 %)."""
    lightest = mode_loop(stiffest.modal_masses[0], stiffest.gains, STEP, REALISTIC)
    omega = np.geomspace(1.0, 0.999 * np.pi / STEP, 4000)
    gm, _, _, wpc, _, _ = control.stability_margins(control.FRD(lightest, omega), returnall=True)
    upper = np.asarray(gm) > 1
    assert 20 * np.log10(np.asarray(gm)[upper].min()) == pytest.approx(stiffest.modal_gain_margin_db, abs=0.05)
    f180 = np.asarray(wpc)[upper][np.argmin(np.asarray(gm)[upper])] / (2 * np.pi)
    limit = 10 ** (stiffest.modal_gain_margin_db / 20)
    calm, _ = _cosim(tmp_path / "below", _scaled(stiffest.gains, 0.8 * limit))
    wild, lengths = _cosim(tmp_path / "above", _scaled(stiffest.gains, 1.25 * limit))
    assert calm < 1.0          # µm: 20 nm sensor noise through a stable loop near its limit
    assert wild > 100 * calm
    swing = lengths - lengths.mean(axis=0)
    power = (np.abs(np.fft.rfft(swing, axis=0)) ** 2).sum(axis=1)
    frequency = np.fft.rfftfreq(len(swing), STEP)[np.argmax(power)]
    assert frequency == pytest.approx(f180, rel=0.03)


# ------------------------------------------------------------------- closed-loop stability
def _simulate(plant, gains, h, steps):
    """Co-simulation of the linearised plant (exact ZOH) with controller.pid in a Jacobi
    loop: the plant holds the force the controller computed from the previous samples."""
    n = plant.nstates
    phi = expm(np.block([[plant.A, plant.B], [np.zeros((6, n + 6))]]) * h)
    Ad, Bd = phi[:n, :n], phi[:n, n:]
    rates_of = pose_jacobian(PARAMS, HOME_POSE)
    x = np.r_[1e-4, -2e-4, 1e-4, 1e-5, -1e-5, 2e-5, np.zeros(6)]
    held, integral, norms = np.zeros(6), np.zeros(6), []
    for _ in range(steps):
        length, rate = plant.C @ x, rates_of @ x[6:]
        force, integral = pid_step(gains, integral, 0.0, 0.0, length, rate, 0.0, h)
        x = Ad @ x + Bd @ held
        held = force
        norms.append(np.linalg.norm(np.r_[x, held * 1e-6, integral]))
    return np.array(norms)


def test_closed_loop_stability_matches_simulation(plant, design):
    h_max = max_stable_step(PARAMS, design.gains)
    gains = dataclasses.replace(design.gains, force_limit=1e300)  # stay linear
    for h, expect_stable in ((0.9 * h_max, True), (1.1 * h_max, False)):
        stable, radius = closed_loop_stable(PARAMS, gains, h)
        assert stable == expect_stable
        norms = _simulate(plant, gains, h, 1500)
        growth = (norms[-1] / norms[-1001]) ** (1 / 1000)
        assert growth == pytest.approx(radius, abs=2e-3)
        assert (norms[-1] < 1e-2 * norms[0]) if expect_stable else (norms[-1] > 1e2 * norms[0])


# ---------------------------------------------------------------------------- feedforward
def _moving_reference(t):
    pose, rate, acc = quintic(HOME_POSE, HOME_POSE + [0.005, 0.02, 0.03, 0.002, -0.002, 0.0], 6.0, t)
    base = quintic(np.zeros(6), np.radians([0, 0, 0, 45, 0, 30]), 6.0, t)
    return (pose, rate, acc), base


def test_feedforward_modes_reproduce_reference_acceleration():
    (pose, rate, acc), base = _moving_reference(np.array([1.0, 2.5, 4.0]))
    moving = feedforward_forces(PARAMS, "moving_base", pose, rate, acc, *base)
    fixed = feedforward_forces(PARAMS, "fixed_base", pose, rate, acc, *base)
    # Each drives the plant model it assumes along the reference.
    assert np.allclose(forward_dynamics(PARAMS, pose, rate, moving, *base), acc, atol=1e-9)
    assert np.allclose(forward_dynamics(PARAMS, pose, rate, fixed, fidelity="no_base"), acc, atol=1e-9)
    assert np.allclose(fixed, inverse_dynamics(PARAMS, pose, rate, acc))
    assert np.abs(moving - fixed).max() > 1e3  # the base motion matters (kN)
    assert np.array_equal(feedforward_forces(PARAMS, "none", pose, rate, acc, *base), np.zeros((3, 6)))


def test_feedforward_rejects_unknown_mode_naming_choices():
    with pytest.raises(ValueError, match="moving_base") as info:
        feedforward_forces(PARAMS, "full", HOME_POSE, np.zeros(6), np.zeros(6))
    assert all(mode in str(info.value) for mode in FEEDFORWARD_MODES)


def test_reference_legs_match_differenced_inverse_kinematics():
    (pose, rate, _), _ = _moving_reference(np.array([1.0, 3.0, 5.0]))
    lengths, rates = reference_legs(PARAMS, pose, rate)
    dt = 1e-5
    (ahead, _, _), _ = _moving_reference(np.array([1.0, 3.0, 5.0]) + dt)
    (behind, _, _), _ = _moving_reference(np.array([1.0, 3.0, 5.0]) - dt)
    differenced = (inverse_kinematics(PARAMS, ahead) - inverse_kinematics(PARAMS, behind)) / (2 * dt)
    assert np.allclose(lengths, inverse_kinematics(PARAMS, pose))
    assert np.allclose(rates, differenced, rtol=1e-6, atol=1e-10)
    with pytest.raises(ValueError, match="pose_rate"):
        reference_legs(PARAMS, pose, np.full((3, 6), np.nan))


def test_single_state_feedforward_equals_the_batched_one():
    params = StewartParams.paper()
    rng = np.random.default_rng(5)
    for mode in FEEDFORWARD_MODES:
        fast = Feedforward(params, mode)
        for _ in range(5):
            pose = HOME_POSE + rng.normal(size=6) * 0.01
            rate, acc, base_pose = rng.normal(size=6) * 0.1, rng.normal(size=6), rng.normal(size=6)
            base_rate, base_acc = rng.normal(size=6), rng.normal(size=6)
            expected = feedforward_and_legs(params, mode, pose, rate, acc, base_pose, base_rate, base_acc)
            for got, want in zip(fast(pose, rate, acc, base_pose, base_rate, base_acc), expected):
                np.testing.assert_allclose(got, want, rtol=1e-13, atol=1e-9)
