"""Controller design with python-control: linearised plant, decoupled PID gains, and the
stability of the sampled MIMO loop against the co-simulation's communication step.

Timing model of the co-simulation (Jacobi master, step h): at t_k the master hands the
plant's leg lengths and rates y_k to the controller and the controller's output, computed
during its previous step from y_{k-1}, to the plant, which holds it (zero-order hold)
over [t_k, t_k + h). So the loop has a ZOH and one step of delay:
x_{k+1} = Ad x_k + Bd u_{k-1}, u_k = PID(y_k). The PID is discretised exactly as
controller.pid does it (backward-Euler integral, derivative on the sampled leg rates).

Decoupling: with the same PID on every leg, the leg-space loop is
PID(s) M_leg^-1 / s^2 (M_leg = J^-T M J^-1, gravity stiffness neglected), which
diagonalises exactly in the eigenvectors of the symmetric M_leg: each eigenvalue is one
SISO loop PID(s) / (m_j s^2). The design therefore sets crossover and phase margin on
the heaviest mode (largest eigenvalue; the diagonal, 1.85 t at home, is an average that
hides the spread 0.59-3.42 t) and checks the margins of every mode: lighter modes cross
over higher, where the PID has more phase lead but the delay eats more, and they set
the gain margin.

The realistic loop (LoopModel, REALISTIC; mode_loop): reflected motor and screw mass
(M_leg + m_r I: same mode shapes, each mode m_r heavier), the actuator's force lag and
viscous friction in the plant, the leg encoders' filtered-difference rate with their
latency and computation delay, and the master's linear extrapolation, each as the FMUs
and the master implement it. margins() gives any gains' margins on it, design_pid the
shipped method on it, stiffest_pid the largest integral gain within phase and gain
margin bounds on every mode.

The step limit of any master (step_limit): under Jacobi every connection of the loop
is one step stale, under Gauss-Seidel only the one into the FMU that steps first
(LoopModel.gauss_seidel; the linear extrapolation acts on the stale connections only).
The limit is where the first mode's closed loop (closed_loop_polynomial, the
characteristic polynomial of mode_loop in w = (z - 1) / h) gets a pole outside the unit
circle; scenarios.runs.flags takes it over the modes along a scenario's motion before it runs.
"""
from dataclasses import dataclass, replace

import numpy as np  # python-control (~1.3 s to import, with scipy) is imported in the functions that

from controller.pid import DEFAULT_FORCE_LIMIT, PIDGains

# use it: a run's step-limit check (step_limit) needs numpy only
from plant.hexapod.model import HOME_POSE, dynamics_terms, forward_dynamics, inverse_dynamics, pose_jacobian

# Shipped design (see default_gains): crossover of the heaviest leg-space mode and its
# phase margin, integral zero a factor 5 below crossover.
DEFAULT_CROSSOVER_HZ = 8.0
DEFAULT_PHASE_MARGIN_DEG = 60.0
DEFAULT_INTEGRAL_RATIO = 5.0

_AXES = ("x", "y", "z", "roll", "pitch", "yaw")


@dataclass(frozen=True)
class Design:
    """PID gains and what they achieve at the communication step ``comm_step`` [s].

    Margins of the design loop (heaviest mode, mass ``design_mass`` [kg]): gain crossover
    [Hz], phase margin [deg], gain margin [dB] (gain increase to instability) and lower gain
    margin [dB] (gain decrease to instability: PID on a double integrator is conditionally
    stable). ``modal_*``: the worst phase and (upper) gain margin over all leg-space modes
    ``modal_masses`` [kg], and the least lower gain margin over them [dB, negative]; ``loop``:
    the LoopModel the margins hold for."""

    gains: PIDGains
    comm_step: float
    design_mass: float
    crossover_hz: float
    phase_margin_deg: float
    gain_margin_db: float
    lower_gain_margin_db: float
    modal_masses: np.ndarray
    modal_phase_margin_deg: float
    modal_gain_margin_db: float
    loop: "LoopModel | None" = None
    modal_lower_gain_margin_db: float = float("nan")


def linearised_plant(params, pose=HOME_POSE, step=1e-6):
    """Continuous StateSpace of the hexapod about static equilibrium at ``pose`` (fixed base).

    States: pose deviation [x, y, z, roll, pitch, yaw] and its rate (12); inputs: leg force
    deviations from the forces that hold the platform at rest (6); outputs: leg length
    deviations (6). A and B by central differences of forward_dynamics (``step`` in m, rad,
    m/s, rad/s; 1 N for forces, in which the accelerations are linear)."""
    import control
    pose = np.asarray(pose, dtype=float)
    rest = np.zeros(6)
    hold = inverse_dynamics(params, pose, rest, rest)
    zero, delta, push = np.zeros((6, 6)), step * np.eye(6), np.eye(6)
    # Perturbation blocks: +-pose, +-rate, +-force.
    poses = pose + np.concatenate([delta, -delta, zero, zero, zero, zero])
    rates = np.concatenate([zero, zero, delta, -delta, zero, zero])
    forces = hold + np.concatenate([zero, zero, zero, zero, push, -push])
    acc = forward_dynamics(params, poses, rates, forces).reshape(3, 2, 6, 6)
    d_pose, d_rate, d_force = ((acc[:, 0] - acc[:, 1]) / (2 * np.array([step, step, 1.0]))[:, None, None]
                               ).transpose(0, 2, 1)
    A = np.block([[zero, np.eye(6)], [d_pose, d_rate]])
    B = np.vstack([zero, d_force])
    C = np.hstack([pose_jacobian(params, pose), zero])
    return control.ss(A, B, C, np.zeros((6, 6)), name="hexapod",
                      states=[f"d{a}" for a in _AXES] + [f"d{a}_rate" for a in _AXES],
                      inputs=[f"dF{i}" for i in range(1, 7)], outputs=[f"dl{i}" for i in range(1, 7)])


def leg_mass_matrix(params, pose=HOME_POSE):
    """M_leg = J^-T M J^-1 (6, 6) [kg]: the mass the leg forces accelerate, in leg space."""
    terms = dynamics_terms(params, pose, np.zeros(6))
    inverse = np.linalg.inv(terms.jacobian)
    return inverse.T @ terms.mass @ inverse


def loop_margins(loop, points=4000):
    """(gain crossover [rad/s], phase margin [deg], upper and lower gain margin [ratio]) of a
    discrete SISO loop, from its frequency response up to Nyquist.

    Uses python-control's FRD margins: its polynomial method finds spurious crossings near
    the loop's triple pole at z = 1. With several gain crossovers, the one with the smallest
    phase margin counts. Lower gain margin 0 means there is none."""
    import control
    nyquist = np.pi / loop.dt
    omega = np.geomspace(1e-4 * nyquist, 0.999 * nyquist, points)
    gm, pm, _, _, wgc, _ = control.stability_margins(control.FRD(loop, omega), returnall=True)
    gm, pm, wgc = np.atleast_1d(gm), np.atleast_1d(pm), np.atleast_1d(wgc)
    worst = np.argmin(pm)
    upper = gm[gm > 1].min(initial=np.inf)
    lower = gm[gm < 1].max(initial=0.0)
    return wgc[worst], pm[worst], upper, lower


def _db(ratio):
    with np.errstate(divide="ignore"):
        return 20 * np.log10(ratio)


# ----------------------------------------------------------------- the realistic loop
@dataclass(frozen=True)
class LoopModel:
    """What lies between the controller and a leg-space mode besides the mode's mass, as
    the realistic loop's FMUs and master implement it (defaults: IDEAL, sampled length and
    rate, the PID, one step of delay). Per leg: ``reflected_mass`` [kg] (motor rotor and
    screw through the pitch; it adds m_r I to M_leg, so the modes keep their shapes and gain m_r each),
    ``actuator_bandwidth`` [Hz] (the force follows the held command through
    dF/dt = 2 pi f (F_cmd - F), plant/c/hexapod.c; 0: at once), ``viscous_friction``
    [N s/m]; ``leg_sensor``: the controller reads the LegSensor FMU (sensors.c: the length
    sampled at t_k, the rate a backward difference low-passed by a = 1 - exp(-2 pi
    ``rate_cutoff`` h), read out ``delay_steps`` samples late and one communication step
    later under Jacobi) instead of the plant's exact length and rate; ``extrapolate``: the
    master's linear input extrapolation (scenarios/cosim/master.py, Jacobi: every input
    u_k + (u_k - u_k-1) / 2, a lead of about half a step that doubles the gain at Nyquist);
    ``gauss_seidel``: the master steps the FMUs one after the other, so of the loop's
    connections only the one into the FMU that steps first is stale (its source has not
    stepped yet: one step of delay, and the only input extrapolated): the plant, which
    scenarios.cosim.master.step_order steps first on the loop's cycles (the load cell's path
    then fresh as the leg sensor's); Jacobi: all stale.
    ``gravity_rate`` [1/s^2]: the largest destabilising eigenvalue of the plant's
    acceleration per displacement under gravity at rest (the 3T mechanism's sliders: a
    real open-loop pole at sqrt of it), given every mode as a negative stiffness
    (conservative: gravity's mode shapes are not the mass's); the hexapod's is left out
    (its modal limit is the full linearised plant's). Coulomb friction is left out
    (nonlinear: below its smoothing velocity it is a stiff damper, above it a constant
    force, a disturbance; the guard checks the loop with that damper's slope added to say
    when the friction hides an instability), and so are quantisation and noise.

    The disturbance observer (controller/c/observer.c; ``observer_bandwidth`` [Hz] > 0):
    the controller also subtracts Q_d(z) [M_o (z - 1)^2 / (z^2 h^2) l_meas - F_meas] from
    its command (Q_d: the observer's zero-order-hold Q, its output the state before the
    step; M_o = ``observer_mass`` [kg], the one leg-space mass it assumes, against each
    mode's own mass; ``observer_leg_space``: its matrix is the controller's model M_leg at
    home shifted to the mean diagonal ``observer_mass`` (observer_model leg_space), so a mode of
    mass m (m_r included) meets m - m_r + observer_mass - ``observer_model_mean`` (the
    model's mean diagonal): its own mass when observer_mass is that mean plus m_r; the
    modes of M_leg and of the model's shifted matrix share their shapes, so each stays one
    SISO loop (with a payload error they do not: observer_masses gives each plant mode
    its Rayleigh quotient of the observer's matrix less and plus its coupling, and
    (mass, observer's mass) pairs carry them); along a motion the model keeps its home
    matrix, which this leaves out: the modal masses move about 0.5 % per cm of heave from
    home, 1.6 % at 3 cm). F_meas: the
    force the plant delivers (its lag state less the viscous friction) through the LoadCell
    FMU (``load_cell``: its first-order low-pass
    ``load_cell_bandwidth`` [Hz], ``load_cell_delay_steps`` samples late, one communication
    step later under Jacobi as a sensor FMU is); without a load cell the observer's force
    input is held (no force path). Its poles are found with python-control (no
    closed-form polynomial)."""

    reflected_mass: float = 0.0
    actuator_bandwidth: float = 0.0
    viscous_friction: float = 0.0
    leg_sensor: bool = False
    rate_cutoff: float = 0.0
    delay_steps: int = 0
    extrapolate: bool = False
    gauss_seidel: bool = False
    gravity_rate: float = 0.0
    observer_bandwidth: float = 0.0
    observer_mass: float = 0.0
    observer_leg_space: bool = False
    observer_model_mean: float = 0.0
    load_cell: bool = False
    load_cell_bandwidth: float = 0.0
    load_cell_delay_steps: int = 0

    def __post_init__(self):
        for name in ("reflected_mass", "actuator_bandwidth", "viscous_friction", "rate_cutoff", "gravity_rate",
                     "observer_bandwidth", "observer_mass", "observer_model_mean", "load_cell_bandwidth"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value >= 0):
                raise ValueError(f"loop model {name} must be finite and >= 0, got {value}")
        if self.delay_steps < 0 or int(self.delay_steps) != self.delay_steps:
            raise ValueError(f"loop model delay_steps must be an integer >= 0, got {self.delay_steps}")
        if not self.leg_sensor and (self.rate_cutoff or self.delay_steps):
            raise ValueError("rate_cutoff and delay_steps belong to the leg sensor: set leg_sensor=True")
        if self.observer_leg_space and not self.observer_model_mean > 0:
            raise ValueError("observer_leg_space needs the model's mean diagonal observer_model_mean > 0")
        if not self.load_cell and (self.load_cell_bandwidth or self.load_cell_delay_steps):
            raise ValueError("load_cell_bandwidth and load_cell_delay_steps belong to the load cell: "
                             "set load_cell=True")


IDEAL = LoopModel()
# The loop of scenarios/files/telescope_slew_realistic.toml and studies/realistic_loop.py
# (values and sources there; the tests check the two agree): 758 kg reflected, 50 Hz force
# loop, 2000 N s/m viscous; encoders with a 100 Hz rate filter and one sample of
# computation delay; Jacobi with linear extrapolation.
REALISTIC = LoopModel(reflected_mass=758.0, actuator_bandwidth=50.0, viscous_friction=2000.0, leg_sensor=True,
                      rate_cutoff=100.0, delay_steps=1, extrapolate=True)


def modal_masses(params, loop=IDEAL, pose=HOME_POSE):
    """Masses [kg] of the decoupled leg-space modes, lightest first: the eigenvalues of
    M_leg + m_r I."""
    return np.linalg.eigvalsh(leg_mass_matrix(params, pose)) + loop.reflected_mass


def mode_loop(mass, gains, comm_step, loop=IDEAL, observer_mass=None):
    """Discrete SISO loop transfer of one leg-space mode of ``mass`` [kg] (its reflected
    mass included, see modal_masses) in the loop ``loop`` (``observer_mass``: the mass [kg]
    its observer assumes for it, by default observer_mode_mass's): force command held over the
    step (ZOH) -> actuator lag -> mass with viscous friction -> (leg sensor) -> PID of
    controller.pid -> one step of controller delay; the master's extrapolation on every
    connection of the loop. With IDEAL: ZOH plant 1/(mass s^2) with sampled length
    and rate, the PID of controller.pid, one step of delay."""
    import control
    h = comm_step
    full = control.c2d(control.ss(*_mode_plant(mass, loop)), h, "zoh")
    plant = full[:2, 0]   # outputs: length, exact rate
    pid = control.ss([[1.0]], [[h, 0.0]], [[gains.ki]], [[gains.kp + gains.ki * h, gains.kd]], h)
    z = control.tf([1, 0], [1], h)
    stale = _stale_connections(loop)
    lead = ((1.5 * z - 0.5) / z) ** stale if loop.extrapolate else 1
    pick = lambda *rows: control.ss([], [], [], np.eye(3)[list(rows)], h)   # of the plant's outputs
    if loop.leg_sensor:   # length only into the sensor; out: measured length and rate
        a = 1 - np.exp(-2 * np.pi * loop.rate_cutoff * h) if loop.rate_cutoff > 0 else 1.0
        late = z ** -(stale - 2 + loop.delay_steps) if stale > 1 else (1 / z) ** loop.delay_steps
        rate = late * a * (z - 1) / (h * (z - (1 - a)))
        split = control.ss([], [], [], [[1.0], [1.0]], h)
        sensor = control.append(control.ss(late), control.ss(rate)) * split
        feedback, reads = sensor * plant[0, 0], sensor * pick(0)   # plant -> sensor -> controller -> plant
        length = control.ss(late) * pick(0)
    else:
        feedback, reads, length = plant, pick(0, 1), pick(0)
    outer = 1 / z * lead if stale > 1 else lead * control.tf([1], [1], h)
    if loop.observer_bandwidth > 0:   # the plant once, read by the PID and the observer
        assumed = observer_mode_mass(mass, loop) if observer_mass is None else observer_mass
        return control.ss(outer) * (pid * reads + _observer(loop, assumed, h, z, length, pick(2))) * full
    return control.ss(outer) * pid * feedback


def _mode_plant(mass, loop):
    """(A, B, C, D) of one mode's plant in continuous time: the force command in; out the
    length, its rate and the delivered force F - c dl/dt (with the actuator's lag, states
    (F, l, dl/dt); without, (l, dl/dt) and the command delivered at once)."""
    w_a, g, c = 2 * np.pi * loop.actuator_bandwidth, loop.gravity_rate, loop.viscous_friction
    if w_a > 0:
        A = [[-w_a, 0, 0], [0, 0, 1], [1 / mass, g, -c / mass]]
        B, C, D = [[w_a], [0], [0]], [[0, 1, 0], [0, 0, 1], [1, 0, -c]], [[0], [0], [0]]
    else:
        A, B, C, D = [[0, 1], [g, -c / mass]], [[0], [1 / mass]], [[1, 0], [0, 1], [0, -c]], [[0], [0], [1]]
    return tuple(np.array(m, dtype=float) for m in (A, B, C, D))


def _observer_filter(loop):
    """(A, B, C) of the observer's Q in continuous time: a 2nd-order Butterworth low-pass at
    its bandwidth (controller/c/observer.c)."""
    w = 2 * np.pi * loop.observer_bandwidth
    return np.array([[0, 1], [-w * w, -np.sqrt(2) * w]]), np.array([[0], [w * w]]), np.array([[1.0, 0]])


def observer_mode_mass(mass, loop):
    """The mass [kg] the observer of ``loop`` assumes for the leg-space mode of ``mass`` (its
    reflected mass included): loop.observer_mass, or with observer_leg_space the model's
    mode shifted as its matrix is (the plant's modes then the model's: a payload as modelled;
    a payload error gives each mode its own, observer_masses)."""
    if loop.observer_leg_space:
        return mass - loop.reflected_mass + loop.observer_mass - loop.observer_model_mean
    return loop.observer_mass


def model_mean_leg_mass(params):
    """The mean diagonal [kg] of the leg-space mass matrix at home (the controller's model,
    observer_model leg_space, shifts it to observer_mass)."""
    return float(np.trace(leg_mass_matrix(params))) / 6


def _observer(loop, observer_mass, h, z, length, force):
    """The observer's part of the command (controller/c/observer.c) from the plant's
    outputs (l, dl/dt, F): Q_d [M_o (z - 1)^2 / (z h)^2 l_meas - F_meas] (M_o: the mode's
    ``observer_mass``), ``length``
    picking l_meas as the PID reads it, ``force`` the delivered force, F_meas through the
    load cell (without one, the held force input adds nothing)."""
    import control
    q = control.c2d(control.ss(*_observer_filter(loop), 0), h, "zoh")
    acc = control.ss(observer_mass * (z - 1) ** 2 / (z * z * h * h)) * length
    if not loop.load_cell:
        return q * acc
    b = 1 - np.exp(-2 * np.pi * loop.load_cell_bandwidth * h) if loop.load_cell_bandwidth > 0 else 1.0
    # plant -> cell -> controller -> plant, as the leg sensor's path: under Jacobi one step
    # late (and extrapolated) more than the PID's path when the PID reads the plant directly
    if loop.gauss_seidel:
        cell = b * z / (z - (1 - b)) * z ** -loop.load_cell_delay_steps
    else:
        cell = b * z / (z - (1 - b)) * z ** -(1 + loop.load_cell_delay_steps)
        if not loop.leg_sensor and loop.extrapolate:
            cell = cell * (1.5 * z - 0.5) / z
    return q * (acc - control.ss(cell) * force)


def _stale_connections(loop):
    """Connections of the loop whose target reads its source's output of t_k: all of
    them (2, or 3 through the leg sensor) under Jacobi, one under Gauss-Seidel. The
    loop's delay is one step less than their number (an FMU's output at t_k+1 depends
    on its inputs at t_k), each of them carries the extrapolation."""
    return 1 if loop.gauss_seidel else (3 if loop.leg_sensor else 2)


def _distinct(masses):
    """The sorted masses without repeats (the hexapod's symmetry gives pairs, equal to
    rounding): each distinct mode's loop is evaluated once."""
    return masses[np.r_[True, np.diff(masses) > 1e-9 * masses[1:]]]


def distinct_modes(masses):
    """The leg-space modes' masses [kg], sorted, each distinct mode once (the loops a
    scenario's prediction is taken over: flags.Prediction.masses); (mass, observer's mass)
    pairs (n, 2) stay pairs, sorted by the mass."""
    masses = np.asarray(masses, dtype=float)
    return _distinct(np.sort(masses)) if masses.ndim == 1 else _modes(masses, IDEAL)


def _modes(masses, loop):
    """The modes as rows (mass, the mass the observer assumes for it) [kg], sorted by mass,
    each distinct once: ``masses`` (n,) (the observer's from ``loop``, observer_mode_mass)
    or already such pairs (n, 2) (observer_masses: an observer whose matrix does not share
    the plant's mode shapes)."""
    masses = np.asarray(masses, dtype=float)
    if masses.ndim == 1:
        masses = _distinct(np.sort(masses))
        return np.column_stack([masses, [observer_mode_mass(m, loop) for m in masses]])
    pairs = masses[np.lexsort((masses[:, 1], masses[:, 0]))]
    step = np.abs(np.diff(pairs, axis=0)).max(axis=1, initial=0.0)
    return pairs[np.r_[True, step > 1e-9 * pairs[1:, 0]]]


def observer_masses(plant, observer, reflected_mass=0.0):
    """(mass, the observer's mass) of each mode [kg] (2 n, 2): the eigenvalues of the plant's
    leg-space matrix ``plant`` (n, n; M_leg) plus ``reflected_mass``, each with the
    observer's matrix ``observer`` (n, n; controller.observer.observer_mass_matrix) in its
    eigenvector v: the Rayleigh quotient R = v^T M_o v less and plus r = |(M_o - R) v|, the
    coupling to the other modes (M_o has an eigenvalue within r of R). Exact when the two
    commute (a payload as the model has it: same mode shapes, r = 0); with a payload error
    the mode is taken to meet either end, and the coupled 6-leg loop bears that out
    (conservative by 0-7 % on its step and observer limits where R alone is up to 11 %
    optimistic: tests/scenarios/runs/test_payload_guard.py)."""
    mass, shapes = np.linalg.eigh(plant)
    seen = shapes.T @ observer @ shapes
    quotient = np.diag(seen)
    coupling = np.linalg.norm(seen - np.diag(quotient), axis=1)
    mass = mass + reflected_mass
    return np.r_[np.c_[mass, quotient - coupling], np.c_[mass, quotient + coupling]]


def modal_margins(gains, comm_step, masses, loop=IDEAL):
    """The Design record of PID ``gains`` (controller.pid.PIDGains) at the communication
    step ``comm_step`` [s] on the leg-space modes ``masses`` [kg] in the loop model ``loop``
    (LoopModel): the heaviest mode's crossover and margins, the worst over every mode.
    ValueError naming the modes if a mode's closed loop is unstable."""
    design = _modal_design(gains, comm_step, masses, loop)
    if design is None:
        raise ValueError(f"gains {gains} destabilise a leg-space mode of {_modes(masses, loop)[:, 0]} kg at "
                         f"{comm_step * 1e3:g} ms in {loop}")
    return design


def _modal_design(gains, comm_step, masses, loop, points=4000):
    """The Design of ``gains`` on the modes ``masses`` (or (mass, observer's mass) pairs) in
    ``loop``; None if a mode's closed loop is unstable."""
    import control
    modes = _modes(masses, loop)
    loops = [mode_loop(m, gains, comm_step, loop, assumed) for m, assumed in modes]
    masses = np.sort(np.asarray(masses, dtype=float).reshape(len(masses), -1)[:, 0])
    if any(np.abs(control.feedback(one).poles()).max() >= 1 for one in loops):
        return None
    modal = np.array([loop_margins(one, points) for one in loops])
    w_gc, pm, gm, lower = modal[-1]
    return Design(gains, comm_step, float(masses[-1]), float(w_gc / (2 * np.pi)), float(pm), float(_db(gm)),
                  float(_db(lower)), masses, float(modal[:, 1].min()), float(_db(modal[:, 2].min())), loop,
                  float(_db(modal[:, 3].max())))


def margins(params, gains, comm_step, loop=IDEAL, pose=HOME_POSE):
    """The Design record (margins per mode) of given ``gains`` in ``loop`` at one pose: e.g.
    the shipped gains on the realistic plant. ``params``: the hexapod's parameters
    (plant.hexapod.model.StewartParams, ``StewartParams.paper()`` the kit's); ``gains``:
    controller.pid.PIDGains; ``comm_step`` [s]; ``loop``: a LoopModel (IDEAL, REALISTIC);
    ``pose``: the platform's pose in {B} whose leg-space masses are taken (home). A
    scenario's loop along its motion: movingbase.loop_analysis. Raises ValueError if a mode
    is unstable."""
    return modal_margins(gains, comm_step, modal_masses(params, loop, pose), loop)


def _solve_gains(mass, crossover_hz, phase_margin_deg, comm_step, integral_ratio, loop):
    """(kp, ki, kd) putting |L| = 1 and arg L = PM - 180 deg at the crossover of the mode
    ``mass``: L(w_c) = kp a + kd c is linear in (kp, kd) once ki/kp is fixed."""
    w_c = 2 * np.pi * crossover_hz
    z = np.exp(1j * w_c * comm_step)
    a = mode_loop(mass, PIDGains(1.0, w_c / integral_ratio, 0.0), comm_step, loop)(z)
    c = mode_loop(mass, PIDGains(0.0, 0.0, 1.0), comm_step, loop)(z)
    target = np.exp(1j * np.radians(phase_margin_deg - 180))
    kp, kd = np.linalg.solve([[a.real, c.real], [a.imag, c.imag]], [target.real, target.imag])
    return kp, kp * w_c / integral_ratio, kd


def design_pid(params, crossover_hz, phase_margin_deg, comm_step, integral_ratio=DEFAULT_INTEGRAL_RATIO,
               force_limit=DEFAULT_FORCE_LIMIT, pose=HOME_POSE, loop=IDEAL):
    """PID gains that give the heaviest leg-space mode crossover ``crossover_hz`` with phase
    margin ``phase_margin_deg`` in the sampled loop (mode_loop in ``loop``; IDEAL: the
    shipped method's loop), ki = kp w_c / integral_ratio.

    |L| = 1 and arg L = PM - 180 deg at w_c are solved exactly. Raises ValueError if the
    crossover is not below Nyquist, if that needs a negative gain (crossover too high or
    margin too large for the loop), or if the gains destabilise a mode."""
    import control
    if not 0 < crossover_hz < 0.5 / comm_step:
        raise ValueError(f"crossover {crossover_hz} Hz must lie between 0 and the Nyquist frequency "
                         f"{0.5 / comm_step} Hz of comm step {comm_step} s")
    masses = modal_masses(params, loop, pose)
    kp, ki, kd = _solve_gains(masses[-1], crossover_hz, phase_margin_deg, comm_step, integral_ratio, loop)
    if kp <= 0 or kd <= 0:
        raise ValueError(f"crossover {crossover_hz} Hz with phase margin {phase_margin_deg} deg is "
                         f"out of reach at comm step {comm_step} s (kp {kp:.3g}, kd {kd:.3g})")
    gains = PIDGains(float(kp), float(ki), float(kd), force_limit)
    unstable = [f"{m:.0f}" for m in _distinct(masses)
                if np.abs(control.feedback(mode_loop(m, gains, comm_step, loop)).poles()).max() >= 1]
    if unstable:
        raise ValueError(f"crossover {crossover_hz} Hz with phase margin {phase_margin_deg} deg at comm "
                         f"step {comm_step} s destabilises the leg-space modes of {', '.join(unstable)} kg")
    return _modal_design(gains, comm_step, masses, loop)


def stiffest_pid(params, comm_step, loop=REALISTIC, phase_margin_deg=45.0, gain_margin_db=6.0,
                 integral_ratios=(2.0, 2.5, 3.5, DEFAULT_INTEGRAL_RATIO), force_limit=DEFAULT_FORCE_LIMIT,
                 pose=HOME_POSE, targets=(45.0, 50.0, 55.0), resolution_hz=0.05):
    """The design_pid with the largest integral gain ki whose every mode keeps phase margin
    >= ``phase_margin_deg`` and upper and lower gain margins >= ``gain_margin_db``.

    Stiffness is ki: a slow force (wind gusts, well below crossover) meets the loop's
    |C(jw)| ~ ki / w; the crossover alone is no measure (a high heavy-mode phase target
    reaches a high crossover with kp -> 0, a loop of pure damping). The search: for each
    integral ratio w_c / (ki / kp) in ``integral_ratios`` and heavy-mode phase-margin
    target in ``targets``, the crossover is bisected to ``resolution_hz`` between 0.5 Hz
    and Nyquist / 25 (feasibility taken to fall once with the crossover; ki grows with
    it); the boundary design with the largest ki wins. Raises ValueError if no crossover
    meets the bounds."""
    masses = modal_masses(params, loop, pose)

    def feasible(crossover_hz, target, ratio):
        kp, ki, kd = _solve_gains(masses[-1], crossover_hz, target, comm_step, ratio, loop)
        if kp <= 0 or kd <= 0:
            return None
        design = _modal_design(PIDGains(float(kp), float(ki), float(kd), force_limit), comm_step, masses, loop,
                               points=1000)
        ok = design is not None and design.modal_phase_margin_deg >= phase_margin_deg and min(
            design.modal_gain_margin_db, -design.modal_lower_gain_margin_db) >= gain_margin_db
        return design if ok else None

    best = None
    for ratio in integral_ratios:
        for target in targets:
            low, high = 0.5, 0.02 / comm_step
            found = feasible(low, target, ratio)
            if found is None:
                continue
            while high - low > resolution_hz:
                mid = 0.5 * (low + high)
                design = feasible(mid, target, ratio)
                low, high, found = (mid, high, design) if design else (low, mid, found)
            if best is None or found.gains.ki > best[3]:
                best = (low, target, ratio, found.gains.ki)
    if best is None:
        raise ValueError(f"no crossover gives phase margin >= {phase_margin_deg} deg and gain margins >= "
                         f"{gain_margin_db} dB on every mode in {loop}")
    return design_pid(params, best[0], best[1], comm_step, best[2], force_limit, pose, loop)


def design_observer(params, gains, comm_step, loop, phase_margin_deg=30.0, gain_margin_db=6.0, resolution_hz=0.05,
                    high_hz=100.0, pose=HOME_POSE):
    """The Design of the highest observer bandwidth [Hz] (in ``loop``, its observer mass and
    load cell as given) with which ``gains`` keep phase margin >= ``phase_margin_deg`` and
    upper gain margin >= ``gain_margin_db`` on every mode, bisected to ``resolution_hz``
    below ``high_hz``; its ``loop.observer_bandwidth`` is the answer. The observer makes a
    mode of mass m look like the observer's mass within its band (the PID then meets that
    mass) and feeds the force back through Q (m_o / m - 1): margins fall as it widens.
    Raises ValueError if even the lowest bandwidth misses the bounds."""
    masses = modal_masses(params, loop, pose)

    def feasible(hz):
        design = _modal_design(gains, comm_step, masses, replace(loop, observer_bandwidth=hz), points=1000)
        ok = (design is not None and design.modal_phase_margin_deg >= phase_margin_deg
              and design.modal_gain_margin_db >= gain_margin_db)
        return design if ok else None

    low, high = resolution_hz, high_hz
    found = feasible(low)
    if found is None:
        raise ValueError(f"no observer bandwidth keeps phase margin >= {phase_margin_deg} deg and gain margin >= "
                         f"{gain_margin_db} dB on every mode with {gains} in {loop}")
    while high - low > resolution_hz:
        mid = 0.5 * (low + high)
        design = feasible(mid)
        low, high, found = (mid, high, design) if design else (low, mid, found)
    return found


def default_gains(params, comm_step=1e-3):
    """The shipped gains: heaviest mode at 8 Hz crossover with 60 deg phase margin for a
    controller at ``comm_step`` (see design_pid; at 1 ms every mode keeps >= 60 deg and
    >= 10 dB)."""
    return design_pid(params, DEFAULT_CROSSOVER_HZ, DEFAULT_PHASE_MARGIN_DEG, comm_step).gains


# ------------------------------------------- the step limit of any master and loop
def _charpoly(a):
    """Characteristic polynomial of a 2x2 or 3x3 matrix from its invariants."""
    tr = np.trace(a)
    if len(a) == 2:
        return np.array([1.0, -tr, np.linalg.det(a)])
    return np.array([1.0, -tr, 0.5 * (tr * tr - np.trace(a @ a)), -np.linalg.det(a)])


def _expm(m, terms=18):
    """exp(m) of a small matrix: Taylor series after scaling to norm <= 1/2, then squaring
    (scipy's expm costs ~10 ms a call here, this ~20 us)."""
    norm = np.abs(m).sum(axis=1).max()
    squarings = max(0, int(np.ceil(np.log2(norm))) + 1) if norm > 0 else 0
    x = m / 2.0 ** squarings
    term = result = np.eye(len(m))
    for k in range(1, terms):
        term = term @ x / k
        result = result + term
    for _ in range(squarings):
        result = result @ result
    return result


def _mul(a, b):
    return np.convolve(a, b)


def _add(a, b):
    """Sum of two polynomials (highest power first) of any lengths."""
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    if len(a) < len(b):
        a, b = b, a
    out = a.copy()
    out[len(a) - len(b):] += b
    return out


def closed_loop_polynomial(mass, gains, comm_step, loop=IDEAL):
    """Characteristic polynomial of the closed loop of mode_loop (the same loop, as the
    numerator + denominator of its transfer function) in w = (z - 1) / h, highest power
    first: the loop's poles are z = 1 + h w. In z the poles crowd about z = 1 at small
    steps and root-finding scatters them by ~1e-3; in w they stay apart. ~100x cheaper
    than python-control's, for the step-limit search before every run."""
    h = comm_step
    w_a = 2 * np.pi * loop.actuator_bandwidth
    g = loop.gravity_rate
    if w_a > 0:   # states (F, l, dl/dt), input F_cmd, as mode_loop
        A = np.array([[-w_a, 0, 0], [0, 0, 1], [1 / mass, g, -loop.viscous_friction / mass]])
        B, rows = np.array([w_a, 0, 0]), (np.array([0, 1.0, 0]), np.array([0, 0, 1.0]))
    else:
        A = np.array([[0, 1.0], [g, -loop.viscous_friction / mass]])
        B, rows = np.array([0, 1 / mass]), (np.array([1.0, 0]), np.array([0, 1.0]))
    n = len(A)
    block = np.zeros((n + 1, n + 1))
    block[:n, :n], block[:n, n] = A * h, B * h
    zoh = _expm(block)
    M, Bw = (zoh[:n, :n] - np.eye(n)) / h, zoh[:n, n] / h    # z I - Ad = h (w I - M)
    den = _charpoly(M)
    length, rate = (_charpoly(M - np.outer(Bw, c)) - den for c in rows)   # numerators (D = 0)
    z, z1 = [h, 1.0], [h, 0.0]                                # z and z - 1 in w
    integral = [(gains.kp + gains.ki * h) * h, gains.ki * h]  # (kp + ki h) z - kp: PID on the length, / (z - 1)
    stale = _stale_connections(loop)
    delay = stale - 1
    if loop.leg_sensor:
        a = 1 - np.exp(-2 * np.pi * loop.rate_cutoff * h) if loop.rate_cutoff > 0 else 1.0
        fil = [h * h, h * a]                                  # h (z - (1 - a))
        num = _mul(length, _add(_mul(integral, fil), gains.kd * a * np.array([h * h, 0, 0])))
        den = _mul(den, _mul(z1, fil))
        delay += loop.delay_steps
    else:
        num = _add(_mul(integral, length), gains.kd * _mul(z1, rate))
        den = _mul(z1, den)
    if loop.extrapolate:
        for _ in range(stale):   # (1.5 z - 0.5) / z
            num, den = _mul(num, [1.5 * h, 1.0]), _mul(den, z)
    for _ in range(delay):
        den = _mul(den, z)
    return _add(den, num)


# ------------------------------- the observer's loop as plain matrices (the guard's cost)
# mode_loop's python-control objects cost ~0.1 s a loop, and the step-limit search before a
# run evaluates ~30 of them: the same loop is built here from numpy arrays, (A, B, C, D) of a
# discrete state space, block by block as mode_loop composes it (~0.5 ms).
def _ss_tf(num, den):
    """(A, B, C, D) of the proper discrete transfer function num(z) / den(z) (highest power
    first): the controllable canonical form."""
    num, den = np.asarray(num, dtype=float), np.asarray(den, dtype=float)
    num, den = num / den[0], den / den[0]
    n = len(den) - 1
    num = np.r_[np.zeros(n + 1 - len(num)), num]
    A = np.zeros((n, n))
    if n:
        A[0], A[1:, :-1] = -den[1:], np.eye(n - 1)
    return A, np.eye(n, 1), (num[1:] - num[0] * den[1:])[None, :], np.array([[num[0]]])


def _ss_gain(gain):
    gain = np.atleast_2d(np.asarray(gain, dtype=float))
    return np.zeros((0, 0)), np.zeros((0, gain.shape[1])), np.zeros((gain.shape[0], 0)), gain


def _ss_series(after, first):
    """``first``'s outputs into ``after``'s inputs (python-control's after * first)."""
    (A2, B2, C2, D2), (A1, B1, C1, D1) = after, first
    n1, n2 = len(A1), len(A2)
    A = np.zeros((n1 + n2, n1 + n2))
    A[:n1, :n1], A[n1:, :n1], A[n1:, n1:] = A1, B2 @ C1, A2
    return A, np.vstack([B1, B2 @ D1]), np.hstack([D2 @ C1, C2]), D2 @ D1


def _ss_sum(one, other, sign=1.0):
    """One input into both, their outputs added (``sign`` -1: subtracted)."""
    (A1, B1, C1, D1), (A2, B2, C2, D2) = one, other
    n1, n2 = len(A1), len(A2)
    A = np.zeros((n1 + n2, n1 + n2))
    A[:n1, :n1], A[n1:, n1:] = A1, A2
    return A, np.vstack([B1, B2]), np.hstack([C1, sign * C2]), D1 + sign * D2


def _ss_stack(top, bottom):
    """One input into both, their outputs stacked (python-control's append * split)."""
    (A1, B1, C1, D1), (A2, B2, C2, D2) = top, bottom
    n1, n2, p1 = len(A1), len(A2), len(C1)
    A, C = np.zeros((n1 + n2, n1 + n2)), np.zeros((p1 + len(C2), n1 + n2))
    A[:n1, :n1], A[n1:, n1:], C[:p1, :n1], C[p1:, n1:] = A1, A2, C1, C2
    return A, np.vstack([B1, B2]), C, np.vstack([D1, D2])


def _zoh(A, B, h):
    """(Ad, Bd) of dx/dt = A x + B u with u held over h (_expm of the augmented matrix)."""
    n = len(A)
    block = np.zeros((n + 1, n + 1))
    block[:n, :n], block[:n, n] = A * h, B[:, 0] * h
    zoh = _expm(block)
    return zoh[:n, :n], zoh[:n, n:]


def _observer_loop_poles(mass, gains, comm_step, loop, observer_mass=None):
    """The closed-loop poles of mode_loop with the observer (its feedback's), from numpy's
    state space of the same blocks in the same order (tests hold the two together)."""
    h = comm_step
    A, B, C, D = _mode_plant(mass, loop)
    full = (*_zoh(A, B, h), C, D)
    pid = (np.ones((1, 1)), np.array([[h, 0.0]]), np.array([[gains.ki]]),
           np.array([[gains.kp + gains.ki * h, gains.kd]]))
    stale = _stale_connections(loop)
    delay = lambda k: np.r_[1.0, np.zeros(k)]                              # z^k, as a polynomial
    lead = [1.0]
    for _ in range(stale if loop.extrapolate else 0):    # (1.5 z - 0.5) / z per stale connection
        lead = np.convolve(lead, [1.5, -0.5])
    outer = _ss_tf(lead, delay(len(lead) - 1 + (1 if stale > 1 else 0)))
    pick = lambda *rows: _ss_gain(np.eye(3)[list(rows)])
    if loop.leg_sensor:
        a = 1 - np.exp(-2 * np.pi * loop.rate_cutoff * h) if loop.rate_cutoff > 0 else 1.0
        k = stale - 2 + loop.delay_steps if stale > 1 else loop.delay_steps
        late = _ss_tf([1.0], delay(k))
        rate = _ss_tf(np.array([a, -a]) / h, np.convolve(delay(k), [1.0, -(1 - a)]))
        reads, length = _ss_series(_ss_stack(late, rate), pick(0)), _ss_series(late, pick(0))
    else:
        reads, length = pick(0, 1), pick(0)
    A, B, C = _observer_filter(loop)
    q = (*_zoh(A, B, h), C, np.zeros((1, 1)))
    assumed = observer_mode_mass(mass, loop) if observer_mass is None else observer_mass
    acc = _ss_series(_ss_tf(assumed * np.array([1.0, -2, 1]) / (h * h), delay(2)), length)
    if loop.load_cell:
        b = 1 - np.exp(-2 * np.pi * loop.load_cell_bandwidth * h) if loop.load_cell_bandwidth > 0 else 1.0
        num, den = [b, 0.0], np.convolve([1.0, -(1 - b)], delay(loop.load_cell_delay_steps
                                                                  + (0 if loop.gauss_seidel else 1)))
        if not loop.gauss_seidel and not loop.leg_sensor and loop.extrapolate:
            num, den = np.convolve(num, [1.5, -0.5]), np.convolve(den, delay(1))
        acc = _ss_sum(acc, _ss_series(_ss_tf(num, den), pick(2)), sign=-1.0)
    command = _ss_series(outer, _ss_sum(_ss_series(pid, reads), _ss_series(q, acc)))
    A, B, C, D = _ss_series(command, full)
    return np.linalg.eigvals(A - B @ C / (1 + D[0, 0]))


def _poles(mode, gains, comm_step, loop):
    """The closed loop's poles in z of a ``mode`` (mass, the observer's mass) [kg]: from
    closed_loop_polynomial, or with the observer (no closed-form polynomial) from
    _observer_loop_poles, mode_loop's state space in numpy."""
    if loop.observer_bandwidth > 0:
        return _observer_loop_poles(mode[0], gains, comm_step, loop, mode[1])
    return 1 + comm_step * np.roots(closed_loop_polynomial(mode[0], gains, comm_step, loop))


def _radius(mode, gains, comm_step, loop):
    return float(np.abs(_poles(mode, gains, comm_step, loop)).max())


def least_damped_period(masses, gains, comm_step, loop=IDEAL):
    """Period [s] of the closed loop's least-damped oscillating pole (the largest |z| off
    the real axis) over the modes ``masses`` [kg] (or (mass, observer's mass) pairs) at
    ``comm_step``: the oscillation of the loop that lasts longest, or grows. inf if no pole
    oscillates."""
    largest, period = -1.0, float("inf")
    for mode in _modes(masses, loop):
        z = _poles(mode, gains, comm_step, loop)
        turning = z[np.abs(np.angle(z)) > 1e-9]
        if len(turning) and np.abs(turning).max() > largest:
            pole = turning[np.argmax(np.abs(turning))]
            largest, period = float(abs(pole)), float(2 * np.pi * comm_step / abs(np.angle(pole)))
    return period


def step_limit(masses, gains, loop=IDEAL, low=1e-5, high=0.2, rtol=1e-3):
    """The communication step [s] at which the first mode of ``masses`` [kg] (or (mass,
    observer's mass) pairs (n, 2): observer_masses) goes unstable (each mode taken to be
    stable below a step and unstable above it, as the loops here are): the lightest mode's
    boundary by a geometric scan (factor 1.5) from ``low`` and bisection to ``rtol``, then
    every mode checked just below it; a mode unstable there is bisected next. 0.0 if
    unstable already at ``low``, inf if stable up to ``high``. With a gravity rate, the
    lower of the limits with and without it (given every mode, it may soften a light mode
    that gravity does not touch, and so raise its limit)."""
    limit = _step_limit(masses, gains, loop, low, high, rtol)
    if loop.gravity_rate > 0:
        limit = min(limit, _step_limit(masses, gains, replace(loop, gravity_rate=0.0), low, high, rtol))
    return limit


def modes_stable(masses, gains, comm_step, loop):
    """Whether the closed loop of every mode of ``masses`` [kg] (or (mass, observer's mass)
    pairs) is stable at ``comm_step``."""
    return all(_radius(mode, gains, comm_step, loop) < 1 for mode in _modes(masses, loop))


def observer_limit(masses, gains, comm_step, loop, high_hz=1000.0, rtol=1e-2, low_hz=0.25, factor=1.5):
    """The observer bandwidth [Hz] (loop.observer_bandwidth's limit) above which a mode of
    ``masses`` (or (mass, observer's mass) pairs) goes unstable at ``comm_step``: the first
    unstable bandwidth of a geometric scan (``factor``) from ``low_hz`` up to ``high_hz``,
    bisected to ``rtol`` against the stable one before it (0.0 if unstable already at
    ``low_hz``, inf if stable all the way). Scanned up, not bisected down from ``high_hz``:
    the boundary need not be monotonic, as with load cells samples late under Gauss-Seidel,
    where a loop unstable at 260 Hz is stable again at 1 kHz (the observer's Q then passes
    the delay's phase whole)."""
    stable = lambda hz: modes_stable(masses, gains, comm_step, replace(loop, observer_bandwidth=hz))
    if not stable(low_hz):
        return 0.0
    good, bad = low_hz, None
    for hz in np.geomspace(low_hz, high_hz, int(np.ceil(np.log(high_hz / low_hz) / np.log(factor))) + 1)[1:]:
        if not stable(hz):
            bad = hz
            break
        good = hz
    if bad is None:
        return float("inf")
    while bad - good > rtol * bad:
        mid = 0.5 * (good + bad)
        good, bad = (mid, bad) if stable(mid) else (good, mid)
    return float(good)


def _step_limit(masses, gains, loop, low, high, rtol):
    masses = _modes(masses, loop)
    stable = lambda m, h: _radius(m, gains, h, loop) < 1
    good, bad, mode = low, None, masses[0]
    while True:
        if not stable(mode, good):
            return 0.0
        if bad is None:   # scan up for this mode's first unstable step
            for bad in np.geomspace(good, high, int(np.ceil(np.log(high / good) / np.log(1.5))) + 1)[1:]:
                if not stable(mode, bad):
                    break
                good = bad
            else:
                bad = None
        while bad is not None and bad / good > 1 + rtol:
            mid = np.sqrt(good * bad)
            good, bad = (mid, bad) if stable(mode, mid) else (good, mid)
        worse = next((m for m in masses if not stable(m, good)), None)
        if worse is None:
            return float(good) if bad is not None else float("inf")
        mode, bad, good = worse, good, low   # a mode unstable below: its boundary lies lower


def _closed_loop_matrix(plant, gains, comm_step):
    """Transition matrix of z_k = (x_k, u_{k-1}, I_{k-1}): plant state, held force, PID
    integral, for reference zero and no feedforward (deviations about equilibrium)."""
    import control
    sampled = control.c2d(plant, comm_step, "zoh")
    lengths = plant.C
    rates = plant.C @ plant.A  # dl/dt = C (A x + B u) and C B = 0: lengths depend on pose only
    n, m = plant.nstates, plant.ninputs
    feedback = (gains.kp + gains.ki * comm_step) * lengths + gains.kd * rates
    return np.block([
        [sampled.A, sampled.B, np.zeros((n, m))],
        [-feedback, np.zeros((m, m)), gains.ki * np.eye(m)],
        [-comm_step * lengths, np.zeros((m, m)), np.eye(m)],
    ])


def _spectral_radius(plant, gains, comm_step):
    return np.max(np.abs(np.linalg.eigvals(_closed_loop_matrix(plant, gains, comm_step))))


def closed_loop_stable(params, gains, comm_step, pose=HOME_POSE):
    """(stable, spectral radius) of the sampled closed loop: the full 12-state linearised
    plant, ZOH, one step of delay and the discrete PID on every leg."""
    radius = _spectral_radius(linearised_plant(params, pose), gains, comm_step)
    return bool(radius < 1), float(radius)


def max_stable_step(params, gains, pose=HOME_POSE, start=1e-4, rtol=1e-4):
    """Largest communication step [s] for which closed_loop_stable holds, by bisection.

    Doubles from ``start`` to bracket the boundary; raises ValueError if the loop is
    unstable already at ``start`` or still stable at 10 s."""
    plant = linearised_plant(params, pose)
    stable = lambda h: _spectral_radius(plant, gains, h) < 1
    if not stable(start):
        raise ValueError(f"closed loop unstable already at comm step {start} s")
    low, high = start, 2 * start
    while stable(high):
        low, high = high, 2 * high
        if high > 10:
            raise ValueError("closed loop stable up to a 10 s comm step: no boundary found")
    while high / low > 1 + rtol:
        mid = np.sqrt(low * high)
        low, high = (mid, high) if stable(mid) else (low, mid)
    return low
