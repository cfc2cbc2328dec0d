"""The guard with the payload as built (issue 41, goal 6): the hexapod plant's payload errors
move its leg-space modes, and with them the step and observer limits; the leg-space observer
keeps the paper payload's matrix, so each mode meets its Rayleigh quotient of it, less and
plus its coupling to the other modes (design.observer_masses). The truth: the coupled 6-leg
loop (full matrices, every leg's PID, sensor, load cell and the observer's matrix) built in
python-control, and co-simulation."""
import dataclasses
import re

import numpy as np
import pytest

from controller import design
from plant.hexapod.model import HOME_POSE, StewartParams
from scenarios import spec
from scenarios.runs import flags, runner

PAPER = StewartParams.paper()
I6 = np.eye(6)
# the payload cases: -50 %, 0, +50 % of the paper's 2130 kg, and the centre of mass off by
# (0.3, 0, 0.4) m (within the plant's +-0.5 m range: a payload that breaks the legs' symmetry)
CASES = {"-50 %": {"platform_mass": 0.5 * PAPER.platform_mass}, "0": {},
         "+50 %": {"platform_mass": 1.5 * PAPER.platform_mass},
         "centre of mass off": {"platform_com": PAPER.platform_com + np.array([0.3, 0.0, 0.4])}}


# the coupled loop's step limit over the per-mode one (bisected to 0.1 %: the slow test's figures)
BEYOND = {"-50 %": 1.0, "0": 1.0, "+50 %": 1.0096, "centre of mass off": 1.0666}


@pytest.fixture(scope="module")
def shipped():
    """The observer slew's loop as the guard reads it (REALISTIC, Jacobi with linear
    extrapolation, leg sensors, load cells at 200 Hz, the leg-space observer at 32 Hz)."""
    scenario, paths, descriptions, values = runner.prepare(runner.resolve("telescope_slew_observer"))
    (loop,) = flags.loops(scenario, descriptions, values)
    return loop


def _legs(siso, h):
    """One SISO discrete system on each of the six legs (block diagonal)."""
    import control
    s = control.ss(siso)
    if s.nstates == 0:
        return control.ss([], [], [], float(s.D[0, 0]) * I6, h)
    return control.ss(*(np.kron(I6, m) for m in (s.A, s.B, s.C, s.D)), h)


def coupled_poles(m_leg, observer, gains, h, loop):
    """The closed-loop poles of the six legs together: the plant of leg-space mass matrix
    ``m_leg`` + m_r I (actuator lag, viscous friction; 18 states), the leg sensors, the PID on
    every leg, the observer of matrix ``observer`` (6, 6) on the load cells, the master's
    delays and extrapolation as design.LoopModel describes them (Jacobi or Gauss-Seidel),
    every signal a 6-vector: no modes."""
    import control
    gain = lambda m: control.ss([], [], [], np.atleast_2d(m), h)   # noqa: E731
    z, Z = control.tf([1, 0], [1], h), np.zeros((6, 6))
    inverse, c, w_a = np.linalg.inv(m_leg + loop.reflected_mass * I6), loop.viscous_friction, \
        2 * np.pi * loop.actuator_bandwidth
    plant = control.c2d(control.ss(np.block([[-w_a * I6, Z, Z], [Z, Z, I6], [inverse, Z, -c * inverse]]),
                                   np.vstack([w_a * I6, Z, Z]), np.block([[Z, I6, Z], [Z, Z, I6], [I6, Z, -c * I6]]),
                                   np.zeros((18, 6))), h, "zoh")   # out: lengths, rates, delivered forces
    pick = lambda k: gain(np.hstack([I6 if j == k else Z for j in range(3)]))   # noqa: E731
    pid = control.ss(I6, np.hstack([h * I6, Z]), gains.ki * I6,
                     np.hstack([(gains.kp + gains.ki * h) * I6, gains.kd * I6]), h)
    stale = 1 if loop.gauss_seidel else 3
    lead = ((1.5 * z - 0.5) / z) ** stale if loop.extrapolate else control.tf([1], [1], h)
    a = 1 - np.exp(-2 * np.pi * loop.rate_cutoff * h)
    late = control.tf([1], [1] + [0] * (stale - 2 + loop.delay_steps if stale > 1 else loop.delay_steps), h)
    reads = control.append(_legs(late, h), _legs(late * a * (z - 1) / (h * (z - (1 - a))), h)) * \
        gain(np.vstack([I6, I6])) * pick(0)
    w = 2 * np.pi * loop.observer_bandwidth
    q = control.c2d(control.ss([[0, 1], [-w * w, -np.sqrt(2) * w]], [[0], [w * w]], [[1, 0]], 0), h, "zoh")
    b = 1 - np.exp(-2 * np.pi * loop.load_cell_bandwidth * h)
    cell = b * z / (z - (1 - b)) * z ** -(loop.load_cell_delay_steps + (0 if loop.gauss_seidel else 1))
    acc = gain(observer) * _legs((z - 1) ** 2 / (z * z * h * h), h) * _legs(late, h) * pick(0)
    command = _legs(lead / z if stale > 1 else lead, h) * (pid * reads + _legs(q, h) * (acc - _legs(cell, h) * pick(2)))
    return control.feedback(command * plant, gain(I6)).poles()


def _observer_matrix(loop):
    """The observer's matrix of the controller (controller/c/observer.c, observer_model
    leg_space): the paper payload's M_leg at home shifted to observer_mass."""
    from controller.observer import observer_mass_matrix
    return observer_mass_matrix(loop.observer_mass, design.leg_mass_matrix(PAPER), True)


def test_a_payload_as_modelled_gives_each_mode_its_own_mass(shipped):
    """Without a payload error the observer's matrix shares the plant's mode shapes: each
    mode's Rayleigh quotient is the mass observer_mode_mass gives it and its coupling is
    rounding (to 1e-12: two eigen-solvers' rounding), and the guard's limit is the one a 1-D
    array of masses gives, bit for bit."""
    loop = shipped.model
    pairs = flags.leg_masses(PAPER, HOME_POSE[None], loop)
    assert pairs[:, 1] == pytest.approx([design.observer_mode_mass(m, loop) for m in pairs[:, 0]], rel=1e-12)
    plain = flags.leg_masses(PAPER, HOME_POSE[None], dataclasses.replace(loop, observer_bandwidth=0.0))
    assert flags._merge(pairs)[:, 0] == pytest.approx(flags._merge(plain), rel=1e-12)
    assert design.step_limit(flags._merge(pairs), shipped.gains, loop) == \
        design.step_limit(flags._merge(plain), shipped.gains, loop)


def test_a_payload_error_brackets_each_modes_observer_mass(shipped):
    """With the centre of mass off, the observer's matrix seen in the plant's mode shapes
    (V^T M_o V) has off-diagonal terms: each mode's pair of rows is its Rayleigh quotient
    R -+ r, r the norm of its row's off-diagonal part, and M_o has an eigenvalue within r
    of each R (the bound the bracket rests on)."""
    params = StewartParams.paper(**CASES["centre of mass off"])
    m_leg, observer = design.leg_mass_matrix(params), _observer_matrix(shipped.model)
    pairs = flags.leg_masses(params, HOME_POSE[None], shipped.model)
    low, high = pairs[:6, 1], pairs[6:, 1]
    seen = np.linalg.eigh(m_leg)[1].T @ observer @ np.linalg.eigh(m_leg)[1]
    assert (low + high) / 2 == pytest.approx(np.diag(seen), rel=1e-12)
    assert (high - low) / 2 == pytest.approx(np.sqrt((seen ** 2).sum(axis=1) - np.diag(seen) ** 2), rel=1e-6)
    eigen = np.linalg.eigvalsh(observer)
    assert all(np.abs(eigen - centre).min() <= half * (1 + 1e-9) for centre, half in zip((low + high) / 2,
                                                                                          (high - low) / 2))
    assert ((high - low) / (low + high)).max() == pytest.approx(0.2572, abs=1e-3)   # up to 26 % of R


@pytest.mark.parametrize("case", [pytest.param(c, marks=pytest.mark.slow) if c in ("0", "+50 %") else c
                                  for c in CASES])   # the default run: the two a guard got wrong (~3 s)
def test_the_coupled_loop_goes_unstable_where_the_modes_say(shipped, case):
    """The per-mode step limit (the guard's, at home) against the coupled 6-leg loop, whose
    boundary lies at ``BEYOND`` x of it (bisected to 0.1 %: stable at 0.99x that, unstable at
    1.01x; conservative): the mass errors' within the guard's 0.1 % bisection (-50 %, 0) or
    1 % above (+50 %), the centre of mass off 6.7 % above (its R alone: 0.3 % below, an
    optimistic limit). With the mass errors the spectral radii at 1 ms agree to rounding (the
    limiting modes' shapes are the observer's), with the centre of mass off within 1e-3."""
    params = StewartParams.paper(**CASES[case])
    m_leg, observer = design.leg_mass_matrix(params), _observer_matrix(shipped.model)
    pairs = flags.leg_masses(params, HOME_POSE[None], shipped.model)
    limit = design.step_limit(pairs, shipped.gains, shipped.model)
    radius = lambda h: np.abs(coupled_poles(m_leg, observer, shipped.gains, h, shipped.model)).max()   # noqa: E731
    modal = max(design._radius(mode, shipped.gains, 1e-3, shipped.model) for mode in design.distinct_modes(pairs))
    assert radius(1e-3) == pytest.approx(modal, abs=1e-3 if case == "centre of mass off" else 1e-11)
    beyond = BEYOND[case]
    assert radius(limit) < 1 and radius(0.99 * beyond * limit) < 1 < radius(1.01 * beyond * limit)
    # the paper payload's limit 1.462 ms; a lighter payload lowers the lightest mode and the limit
    assert limit * 1e3 == pytest.approx({"-50 %": 1.1583, "0": 1.4621, "+50 %": 1.5965,
                                         "centre of mass off": 1.2936}[case], rel=1e-3)


@pytest.mark.slow
@pytest.mark.parametrize("case, ratio", [("-50 %", 1.017), ("+50 %", 1.0225), ("centre of mass off", 1.049)])
def test_the_coupled_observer_limit_against_the_modes(shipped, case, ratio):
    """The observer's bandwidth limit at 1 ms, bisected on the coupled loop to 0.1 %, over
    the guard's (per mode, bisected to 1 %): above it (conservative) by 1.7 % (-50 %), 2.3 %
    (+50 %) and 4.9 % (centre of mass off). With the Rayleigh quotient alone it was equal
    within the bisection for the mass errors, and 9 % optimistic with the centre of mass
    0.5 m off (2.6 % at 0.14 m, 0.5 % at 35 mm)."""
    params = StewartParams.paper(**CASES[case])
    m_leg, observer = design.leg_mass_matrix(params), _observer_matrix(shipped.model)
    pairs = flags.leg_masses(params, HOME_POSE[None], shipped.model)
    predicted = design.observer_limit(pairs, shipped.gains, 1e-3, shipped.model, rtol=1e-3)
    stable = lambda hz: np.abs(coupled_poles(m_leg, observer, shipped.gains, 1e-3, dataclasses.replace(
        shipped.model, observer_bandwidth=hz))).max() < 1   # noqa: E731
    low, high = 0.8 * predicted, 1.25 * predicted
    assert stable(low) and not stable(high)
    while high / low > 1.001:
        mid = np.sqrt(low * high)
        low, high = (mid, high) if stable(mid) else (low, mid)
    assert low / predicted == pytest.approx(ratio, abs=0.003)


@pytest.mark.slow
def test_the_coupled_step_limit_is_bisected_where_beyond_says(shipped):
    """BEYOND's figures: the coupled loop's step limit bisected to 0.1 % over the guard's."""
    for case, beyond in BEYOND.items():
        params = StewartParams.paper(**CASES[case])
        m_leg, observer = design.leg_mass_matrix(params), _observer_matrix(shipped.model)
        limit = design.step_limit(flags.leg_masses(params, HOME_POSE[None], shipped.model), shipped.gains,
                                  shipped.model)
        stable = lambda h: np.abs(coupled_poles(m_leg, observer, shipped.gains, h, shipped.model)).max() < 1   # noqa
        low, high = limit, 1.25 * limit
        assert stable(low) and not stable(high)
        while high / low > 1.001:
            mid = np.sqrt(low * high)
            low, high = (mid, high) if stable(mid) else (low, mid)
        assert low / limit == pytest.approx(beyond, abs=0.002), case


def test_a_campaigns_payloads_get_their_own_limits_and_equal_ones_share_it(shipped):
    """Distinct payloads are predicted apart (the limit reads their masses), the same
    payload with other seeds shares the search; the refusal names the payload and the limit
    the payload as modelled would have."""
    scenario, paths, descriptions, values = runner.prepare(runner.resolve("telescope_slew_observer"), ci=True)
    drawn = lambda seed, **plant: {**values, "plant": {**values["plant"], **plant},   # noqa: E731
                                   "wind": {**values["wind"], "seed": seed}}
    cache = {}
    light = flags.predict(scenario, paths, descriptions, drawn(3, payload_mass_error=-1064.85), cache=cache)
    again = flags.predict(scenario, paths, descriptions, drawn(4, payload_mass_error=-1064.85), cache=cache)
    off = flags.predict(scenario, paths, descriptions, drawn(3, **{"payload_com_error[1]": 0.3,
                                                                   "payload_com_error[3]": 0.4}), cache=cache)
    assert again.limit == light.limit == pytest.approx(1.1583e-3, rel=1e-3)
    assert off.limit == pytest.approx(1.2938e-3, rel=1e-3)   # as at home: the slew's first 1.5 s holds still
    assert light.modelled_limit == off.modelled_limit == pytest.approx(1.4621e-3, rel=1e-3)
    assert sum(1 for key in cache if key[0] == "step limit") == 3   # -1065 kg, off centre, as modelled
    with pytest.raises(spec.ScenarioError) as refused:
        flags.check(dataclasses.replace(scenario, step=1.3e-3), dataclasses.replace(light, step=1.3e-3))
    message = str(refused.value)
    assert "beyond the predicted stability limit 1.158 ms" in message
    assert re.search(r"with the payload's -1065 kg mass error \(as modelled it would be 1.46[23] ms", message)
    assert "centre of mass (+300, +0, +400) mm off" in flags._payload(drawn(3, **{
        "payload_com_error[1]": 0.3, "payload_com_error[3]": 0.4}), descriptions, "plant")


def test_the_loop_analysis_shows_each_modes_observer_mass():
    """movingbase.loop_analysis of a payload 50 % light: the guard's modes, each with the
    observer's mass at both ends of its bracket, and each mode's python-control loop closes
    at the pole radius the guard's numpy loop finds for that pair (within 1e-9)."""
    import control

    import movingbase
    analysis = movingbase.loop_analysis("telescope_slew_observer", set={"plant.payload_mass_error": -1064.85},
                                        ci=True)
    assert analysis.step_limit == pytest.approx(1.1583e-3, rel=1e-3)
    assert len(analysis.observer_masses) == len(analysis.masses) > 4   # the four modes (with pairs), bracketed
    for k in (0, -1):
        pair = (analysis.masses[k], analysis.observer_masses[k])
        assert np.abs(control.feedback(analysis.open_loop(k)).poles()).max() == pytest.approx(
            design._radius(pair, analysis.gains, analysis.step, analysis.model), abs=1e-9)


def _light_scene(tmp_path, step):
    """The shipped observer slew with a payload 1064.85 kg (50 %) lighter than modelled, at
    ``step`` ms for 2.7 s in calm air without the screws' Coulomb friction (the prediction
    leaves it out), recorded every 10 steps."""
    text = runner.resolve("telescope_slew_observer").read_text()
    text = re.sub(r"\n\[requirements\].*?(?=\n\[|\Z)", "", text, flags=re.S)
    text = text.replace('values = ["0 Hz", "32 Hz"]', 'values = ["32 Hz"]').replace('stop_time = "60 s"',
                                                                                  'stop_time = "2.7 s"')
    text = text.replace('step = "1 ms"', f'step = "{step:g} ms"').replace('interval = "10 ms"',
                                                                          f'interval = "{10 * step:g} ms"')
    text = text.replace('mean_speed = "10 m/s"', 'mean_speed = "0 m/s"').replace('coulomb_friction = "200 N"',
                                                                                 'coulomb_friction = "0 N"')
    text = text.replace('actuator_force_limit = "25 kN"',
                        'actuator_force_limit = "25 kN", payload_mass_error = -1064.85')
    path = tmp_path / f"light_{step:g}.toml"
    path.write_text(text)
    return path


@pytest.mark.slow
def test_cosimulation_confirms_the_light_payloads_limit(tmp_path):
    """A payload 50 % light: the guard predicts 1.158 ms (as modelled: 1.462 ms, which let
    a 1.35 ms run through). At 1.35 ms (1.17x) it is refused, and run anyway its leg forces
    oscillate and grow into the 25 kN limits (52 kN between records); at 1 ms (0.86x) they stay
    at the sensors' noise (26 N between records)."""
    jitter = {}
    for step in (1.0, 1.35):
        path = _light_scene(tmp_path, step)
        if step > 1:   # the payload as modelled would have run it: its limit is above the step
            prediction = flags.predict(*runner.prepare(path))
            assert prediction.limit < 1.35e-3 < prediction.modelled_limit
            with pytest.raises(spec.ScenarioError, match=r"limit 1.158 ms .*-1065 kg mass error .*1.46[23] ms"):
                runner.pre_run_flags(*runner.prepare(path))
        _, (run,), _ = runner.run_scenario(path, tmp_path / "out", progress=False, allow_unstable=True,
                                           charts="none")
        t = run.records.time
        force = np.array([run.records[f"controller.leg_force[{i}]"] for i in range(1, 7)]).T
        jitter[step] = np.abs(np.diff(force[t >= 1.7], axis=0)).max()
    assert jitter[1.35] > 2e4 and jitter[1.35] > 10 * jitter[1.0], jitter
