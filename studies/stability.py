"""Where methods fail: the stability limits of the co-simulation and of the explicit
integrators, predicted from the linearised hexapod and observed in runs.

Run ``python -m studies.stability`` (``--full`` for the finer grid): it prints the
predicted and observed boundaries and the convergence orders, and writes three charts
into docs/figures/ (stability_boundary.png, integrator_stability.png,
convergence_order.png).

1. Co-simulation (Jacobi master, plant FMU + leg-controller FMU, fixed base). The loop
   is sampled with a zero-order hold and one step of delay, so the communication step h
   is part of the controller: beyond a step that depends on the gains the loop goes
   unstable, however accurate the plant's integrator. Prediction:
   controller.design.closed_loop_stable (12-state linearised plant, ZOH, one-step delay,
   discrete PID). Observation: co-simulations through scenarios.cosim.master with the real
   FMUs, the PID gains scaled by k, the platform started OFFSET off its home pose (a
   step disturbance of ~10 µm on the legs, small enough to stay linear and far from the
   force limit) and the leg-length error classified:

   * stable: the error decays (it falls below 1e-6 of its start, or its peak over the
     last third of the run is below its peak over the middle third);
   * unstable: it grows (last third above middle third, or above 10x its start: an
     explicit method beyond its limit can also settle on a spurious fixed point far
     from the equilibrium, see below), or the force saturates;
   * failed: the master raised FmuError (an FMU refused a step: a leg past its stroke,
     a diverged integrator, a singular pose).

   The grid runs twice: with the shipped force limit (50 kN, an unstable loop saturates
   into a bounded limit cycle) and with an unlimited actuator (1e9 N: an unstable loop
   grows until a leg leaves its stroke and the plant FMU refuses the step, FmuError).

   There are two boundaries: the communication step (above) and a lower gain limit, as a
   PID on a double integrator is conditionally stable: with ki/kp and kd/kp fixed the
   continuous loop of a leg-space mode of mass m needs k > m ki / (kd kp) (Routh), ~0.20
   for the heaviest mode with the default gains.

2. Explicit integrators on the monolithic closed loop (ClosedLoopODE: the plant and the
   continuous PID with feedforward as ONE ODE, no sample-and-hold, no delay, no force
   saturation, so that a divergence is the integrator's own). The derivative gain makes
   it stiff: its fastest eigenvalue is ~ -kd/m of the lightest leg-space mode (-263 1/s
   at k = 1). Prediction: the largest h with |R(h lambda)| < 1 for every eigenvalue
   lambda of the linearised closed loop (closed_loop_matrix), R(z) = 1 + z for explicit
   Euler and the degree-4 Taylor polynomial for RK4. Observation: bisection on h with
   runs of plant.integrators.advance, classified as above; a run whose leg error passes
   the leg stroke is stopped with ConvergenceError. Not every failure raises: at low
   gain RK4 just beyond its limit settles on a spurious fixed point of its map, finite,
   steady and wrong (spurious_fixed_point); only the classifier's "grown" rule sees it.

3. Convergence orders inside the safe region: the plant's fixed-step integrators
   (HexapodODE, one communication step split into max_step substeps, against the same
   integrator at a 16x finer step) and the co-simulation (error against the monolithic
   closed loop integrated finely: ZOH + one-step delay are first order in h).
"""
import argparse
import math
import pathlib
import tempfile
import time
from dataclasses import dataclass, field, replace

import numpy as np

from controller.design import closed_loop_stable, default_gains, linearised_plant, max_stable_step
from plant import integrators
from plant.errors import ConvergenceError, PlantError
from plant.hexapod.model import (
    HOME_POSE,
    StewartParams,
    dynamics_terms,
    inverse_dynamics,
    inverse_kinematics,
    rates_from_twist,
)
from plant.hexapod.ode import HexapodODE
from scenarios import spec
from scenarios.cosim.fmi import FmuError, unpack
from scenarios.runs import single

ROOT = pathlib.Path(__file__).resolve().parent.parent
FIGURES = ROOT / "docs" / "figures"
PARAMS = StewartParams.paper()
GAINS = default_gains(PARAMS)   # the controller FMU's defaults (designed at 1 ms)

# The step disturbance: the platform starts this far off its reference (home) pose
# [m, m, m, rad, rad, rad]; a generic direction, so every leg-space mode is excited.
OFFSET = 1e-5 * np.array([0.8, -0.5, 1.0, 0.6, -0.9, 0.7])
DURATION = 2.0       # s of simulated time per classifying run (>= 3 periods of the slowest mode)
DECAYED = 1e-6       # error below this fraction of its start: decayed, stop early
UNLIMITED_FORCE = 1e9  # N: "no" force limit, so that an unstable loop runs a leg past its stroke
GROWN = 10.0         # error above this multiple of its start over the last third: grown
STABLE, UNSTABLE, FAILED = "stable", "unstable", "failed"

# Grids: the small default (octaves) and the --full one (half octaves).
SMALL_STEPS = 0.25e-3 * 2.0 ** np.arange(6)          # 0.25 .. 8 ms
SMALL_SCALES = 2.0 ** np.arange(-3, 3)               # 0.125 .. 4
FULL_STEPS = 0.25e-3 * 2.0 ** np.arange(0, 5.01, 0.5)
FULL_SCALES = 2.0 ** np.arange(-3, 2.01, 0.5)


def scaled(gains, k):
    """The PID gains multiplied by k (force limit unchanged)."""
    return replace(gains, kp=k * gains.kp, ki=k * gains.ki, kd=k * gains.kd)


# ---------------------------------------------------------------------- classification
@dataclass
class Outcome:
    """One classified run: its verdict, the observed growth rate of the leg error [1/s]
    (tail: last third against middle third; nan when undefined) and the error trace."""

    step: float
    k: float
    verdict: str
    rate: float
    t: np.ndarray = field(repr=False)
    error: np.ndarray = field(repr=False)
    saturated: bool = False
    message: str = ""


def growth_rate(t, error):
    """ln(peak of the last third / peak of the middle third) / (a third of the span) [1/s]."""
    t, error = np.asarray(t), np.asarray(error)
    if len(t) < 6:
        return math.nan
    span = t[-1] - t[0]
    last = t >= t[0] + 2 * span / 3
    middle = (t >= t[0] + span / 3) & ~last
    if not last.any() or not middle.any():
        return math.nan
    floor = 1e-300
    return math.log(max(error[last].max(), floor) / max(error[middle].max(), floor)) / (span / 3)


def classify(t, error, saturated=False):
    """(verdict, growth rate) of an error trace that ran to its end (see module doc)."""
    t, error = np.asarray(t), np.asarray(error)
    rate = growth_rate(t, error)
    if saturated:
        return UNSTABLE, rate
    if error[-1] < DECAYED * error[0]:
        return STABLE, rate
    last = error[t >= t[0] + 2 * (t[-1] - t[0]) / 3]
    if last.max() > GROWN * error[0] or not rate < 0:
        return UNSTABLE, rate
    return STABLE, rate


class _Decided(Exception):
    """Raised by the trace to stop a run whose verdict is settled (decayed)."""


class _Trace:
    """A metric for scenarios.runs.single.run that keeps the leg-length error per step and the
    peak force, and stops the run once the error has decayed by DECAYED."""

    name, start = "stability trace", 0.0
    needs = ["plant.leg_length", "controller.leg_force"]

    def __init__(self, reference_lengths, stop_when_decided=True):
        self.reference = reference_lengths
        self.stop = stop_when_decided
        self.t, self.error, self.force_peak = [], [], 0.0

    def feed(self, t, columns):
        """Rows at times t as scenarios.cosim.master's recorder hands them over, a block at a
        time; ``columns`` in the order of ``needs``."""
        for k, at in enumerate(t.tolist()):
            self.update(at, {name: column[k] for name, column in zip(self.needs, columns)})

    def update(self, t, values):
        self.t.append(t)
        self.error.append(float(np.abs(values["plant.leg_length"] - self.reference).max()))
        self.force_peak = max(self.force_peak, float(np.abs(values["controller.leg_force"]).max()))
        if self.stop and len(self.error) > 10 and self.error[-1] < DECAYED * self.error[0] \
                and max(self.error[-10:]) < DECAYED * self.error[0]:
            raise _Decided

    def result(self):
        return {}

    def series(self):
        return np.array(self.t), np.array(self.error)

    def undersampled(self):
        """None: a trace of every recorded row, not a metric reported from them."""
        return None


# -------------------------------------------------------------------- co-simulation
_SCENARIO = """
name = "stability_probe"
description = "plant + leg controller, fixed base, platform started off its reference"
stop_time = {stop!r}
step = {step!r}
master = "jacobi"

[fmus.plant]
fmu = "hexapod_plant"
implementation = "python"   # what CoSim runs: the pythonfmu FMUs (builder.ensure_built)
[fmus.plant.parameters]
moving_base = 0
fidelity = "full"
integrator = "{integrator}"
max_step = {max_step!r}
initial_pose = {pose}
base_pose = [0, 0, 0, 0, 0, 0]
base_rate = [0, 0, 0, 0, 0, 0]
base_acc = [0, 0, 0, 0, 0, 0]

[fmus.controller]
fmu = "leg_controller"
implementation = "python"   # what CoSim runs: the pythonfmu FMUs (builder.ensure_built)
[fmus.controller.parameters]
feedforward = "fixed_base"
kp = {kp!r}
ki = {ki!r}
kd = {kd!r}
force_limit = {force_limit!r}
reference_pose = {reference}
reference_rate = [0, 0, 0, 0, 0, 0]
reference_acc = [0, 0, 0, 0, 0, 0]
base_pose = [0, 0, 0, 0, 0, 0]
base_rate = [0, 0, 0, 0, 0, 0]
base_acc = [0, 0, 0, 0, 0, 0]

[[connections]]
from = "plant.leg_length"
to = "controller.leg_length"
[[connections]]
from = "plant.leg_rate"
to = "controller.leg_rate"
[[connections]]
from = "controller.leg_force"
to = "plant.leg_force"
"""


def _toml_list(values):
    return "[" + ", ".join(repr(float(v)) for v in values) + "]"


def scenario_text(step, stop, gains, pose, reference=HOME_POSE, integrator="rk4", max_step=1e-3):
    """The probe scenario as TOML text: plant and controller FMUs, fixed base, reference
    held at ``reference``, platform starting at ``pose`` (at rest)."""
    return _SCENARIO.format(stop=float(stop), step=float(step), integrator=integrator, max_step=float(max_step),
                            pose=_toml_list(pose), reference=_toml_list(reference), kp=float(gains.kp),
                            ki=float(gains.ki), kd=float(gains.kd), force_limit=float(gains.force_limit))


class CoSim:
    """The plant and leg-controller FMUs run by scenarios.cosim.master on the probe scenario.

    ``paths``: {"hexapod_plant_fmu": ..., "leg_controller_fmu": ...} of built FMUs (e.g.
    the tests' fixture); without it they are built into ``fmu_dir`` or, by default, a
    temporary folder (so a study never rebuilds the kit's build/ while others use it)."""

    def __init__(self, paths=None, fmu_dir=None):
        self._folders = []
        if paths is None:
            from fmu_src.python_build import ensure_built
            if fmu_dir is None:
                self._folders.append(tempfile.TemporaryDirectory(prefix="stability_fmu_"))
                fmu_dir = self._folders[-1].name
            paths = ensure_built(["hexapod_plant_fmu", "leg_controller_fmu"], pathlib.Path(fmu_dir))
        self.paths = {"plant": paths["hexapod_plant_fmu"], "controller": paths["leg_controller_fmu"]}
        self.descriptions = {inst: unpack(p)[0] for inst, p in self.paths.items()}
        self._folders.append(tempfile.TemporaryDirectory(prefix="stability_runs_"))
        self.outdir = pathlib.Path(self._folders[-1].name)
        self.runs = 0
        self.wall = 0.0

    def run(self, step, k=1.0, duration=DURATION, gains=GAINS, offset=OFFSET, reference=HOME_POSE,
            stop_when_decided=True, integrator="rk4", max_step=1e-3):
        """Co-simulate ``duration`` s at communication step ``step`` with the gains scaled
        by k; returns the classified Outcome (verdict FAILED when the master raised)."""
        gains = scaled(gains, k)
        steps = max(6, int(round(duration / step)))
        text = scenario_text(step, steps * step, gains, np.asarray(reference) + offset, reference,
                             integrator, max_step)
        scenario = spec.parse(text, "studies.stability")
        values = spec.bind(scenario, self.descriptions)
        trace = _Trace(inverse_kinematics(PARAMS, np.asarray(reference, dtype=float)), stop_when_decided)
        message = ""
        start = time.perf_counter()
        try:
            single.run(scenario, self.paths, values, self.outdir, "probe", [trace])
        except _Decided:
            pass
        except FmuError as exc:
            message = str(exc)
        finally:
            self.runs += 1
            self.wall += time.perf_counter() - start
        t, error = trace.series()
        saturated = trace.force_peak >= gains.force_limit * (1 - 1e-9)
        if message:
            return Outcome(step, k, FAILED, growth_rate(t, error), t, error, saturated, message)
        verdict, rate = classify(t, error, saturated)
        return Outcome(step, k, verdict, rate, t, error, saturated)


def predicted(step, k, gains=GAINS):
    """(stable, spectral radius) of the sampled loop (controller.design.closed_loop_stable)."""
    return closed_loop_stable(PARAMS, scaled(gains, k), step)


def _bisect(stable_at, good, bad, iterations):
    """Geometric bisection between a stable ``good`` and an unstable ``bad`` value."""
    for _ in range(iterations):
        mid = math.sqrt(good * bad)
        good, bad = (mid, bad) if stable_at(mid) else (good, mid)
    return good, bad


@dataclass
class BoundaryStudy:
    steps: np.ndarray            # communication steps [s] (columns)
    scales: np.ndarray           # gain scales k (rows)
    verdicts: np.ndarray         # (k, h) observed verdicts
    rates: np.ndarray            # (k, h) observed growth rates [1/s]
    saturated: np.ndarray        # (k, h) the force reached its limit
    radius: np.ndarray           # (k, h) predicted spectral radius
    step_limits: list            # (k, predicted h_max, observed stable h, observed unstable h)
    gain_limit: tuple            # (h, predicted k_min, observed unstable k, observed stable k) or None
    messages: dict               # (k, h) -> FmuError text of failed runs
    wall: float = 0.0
    runs: int = 0
    refine: int = 0              # bisections per observed boundary (0: grid brackets only)

    @property
    def agreement(self):
        """Fraction of grid points where observation and prediction agree (failed counts
        as not stable)."""
        return float(np.mean((self.verdicts == STABLE) == (self.radius < 1)))


def predicted_step_limit(k, gains=GAINS):
    """Predicted largest stable communication step [s] at gain scale k (nan if the loop
    is unstable already at 0.1 ms)."""
    try:
        return max_stable_step(PARAMS, scaled(gains, k))
    except ValueError:
        return math.nan


def predicted_gain_limit(step, gains=GAINS, low=0.05, high=1.0, rtol=1e-4):
    """Predicted smallest stable gain scale k at communication step ``step``."""
    stable = lambda k: predicted(step, k, gains)[0]
    if stable(low) or not stable(high):
        return math.nan
    while high / low > 1 + rtol:
        mid = math.sqrt(low * high)
        low, high = (low, mid) if stable(mid) else (mid, high)
    return high


def sweep(steps=SMALL_STEPS, scales=SMALL_SCALES, cosim=None, duration=DURATION, refine=5,
          refine_duration=3 * DURATION, gain_limit_step=1e-3, gains=GAINS):
    """Observe every (k, h) of the grid by co-simulation and predict it; then refine the
    observed boundaries by ``refine`` bisections with runs of ``refine_duration`` s (near
    a boundary the error grows or decays slowly: a 2 s run resolves growth rates down to
    ~0.05 1/s, a 6 s run ~0.005 1/s): the step limit of every k whose row goes stable ->
    not stable, and the gain limit at ``gain_limit_step`` (if on the grid)."""
    cosim = cosim or CoSim()
    runs0, wall0 = cosim.runs, cosim.wall
    steps, scales = np.asarray(steps, float), np.asarray(scales, float)
    verdicts = np.empty((len(scales), len(steps)), dtype=object)
    rates = np.full(verdicts.shape, np.nan)
    saturated = np.zeros(verdicts.shape, dtype=bool)
    radius = np.empty(verdicts.shape)
    messages = {}
    for i, k in enumerate(scales):
        for j, h in enumerate(steps):
            out = cosim.run(h, k, duration, gains)
            verdicts[i, j], rates[i, j], saturated[i, j] = out.verdict, out.rate, out.saturated
            if out.message:
                messages[(k, h)] = out.message
            radius[i, j] = predicted(h, k, gains)[1]
    observe = lambda h, k: cosim.run(h, k, refine_duration, gains).verdict == STABLE
    step_limits = []
    for i, k in enumerate(scales):
        row = verdicts[i] == STABLE
        if not row[0]:
            continue
        first_bad = int(np.argmin(row)) if not row.all() else None
        good = steps[first_bad - 1] if first_bad is not None else steps[-1]
        bad = steps[first_bad] if first_bad is not None else math.nan
        if first_bad is not None and refine:
            good, bad = _bisect(lambda h: observe(h, k), good, bad, refine)
        step_limits.append((k, predicted_step_limit(k, gains), good, bad))
    gain_limit = None
    column = np.flatnonzero(np.isclose(steps, gain_limit_step))
    if column.size:
        col = verdicts[:, column[0]] == STABLE
        if col.any() and not col[0]:
            first_good = int(np.argmax(col))
            bad, good = scales[first_good - 1], scales[first_good]
            if refine:
                good, bad = _bisect(lambda k: observe(gain_limit_step, k), good, bad, refine)
            gain_limit = (gain_limit_step, predicted_gain_limit(gain_limit_step, gains), bad, good)
    return BoundaryStudy(steps, scales, verdicts, rates, saturated, radius, step_limits, gain_limit, messages,
                         cosim.wall - wall0, cosim.runs - runs0, refine)


# ------------------------------------------------------------- monolithic closed loop
class ClosedLoopODE:
    """Plant and continuous PID (with the fixed-base feedforward at the reference) as one
    ODE, state z = [pose (6), twist (6), integral of the leg-length error (6)]:

        M du/dt + h = J^T F,   F = ff + kp (l_ref - l) + ki I - kd dl/dt,   dI/dt = l_ref - l

    the continuous-time limit of the co-simulated loop with a fixed base, without the
    force saturation (so an integrator's divergence is not capped by the actuator)."""

    def __init__(self, gains=GAINS, reference=HOME_POSE, params=PARAMS):
        self.gains, self.params = gains, params
        self.reference = np.asarray(reference, dtype=float)
        self.reference_lengths = inverse_kinematics(params, self.reference)
        self.feedforward = inverse_dynamics(params, self.reference, np.zeros(6), np.zeros(6), fidelity="no_base")
        self.calls = 0

    def rhs(self, t, z):
        self.calls += 1
        pose, twist, integral = z[:6], z[6:12], z[12:]
        terms = dynamics_terms(self.params, pose, twist, twist_speeds=True)
        error = self.reference_lengths - terms.leg_lengths
        g = self.gains
        forces = self.feedforward + g.kp * error + g.ki * integral - g.kd * terms.leg_rates
        acc = np.linalg.solve(terms.mass, terms.jacobian.T @ forces - terms.bias)
        return np.concatenate([rates_from_twist(pose, twist), acc, error])

    def initial_state(self, offset=OFFSET):
        return np.r_[self.reference + offset, np.zeros(12)]

    def leg_error(self, z):
        return float(np.abs(inverse_kinematics(self.params, z[:6]) - self.reference_lengths).max())

    def simulate(self, method, step, duration, offset=OFFSET, stop_when_decided=True, sample=None):
        """Integrate with plant.integrators.advance(method) at a fixed ``step`` [s]; returns
        (t, leg error, states at every ``sample`` s if given). Raises ConvergenceError when
        the integrator diverges: the leg error passes the leg stroke, the state is no
        longer finite (integrators.advance), or a stage of a step that started from a valid
        state leaves the valid states (a PlantError inside the step). A start at a
        singular pose raises SingularConfigurationError."""
        z = self.initial_state(offset)
        bound = max(abs(s) for s in self.params.stroke)
        n = max(6, int(round(duration / step)))
        every = None if sample is None else max(1, int(round(sample / step)))
        ts, errors, states = [0.0], [self.leg_error(z)], [z.copy()]
        self.rhs(0.0, z)   # a start at a singular pose raises here, as itself
        for i in range(n):
            t = i * step
            try:
                z = integrators.advance(method, self.rhs, t, z, step, step)
            except PlantError as exc:
                if isinstance(exc, ConvergenceError):
                    raise
                # A stage of the step left the valid states (typically a singular pose
                # after a huge overshoot) although the step started from a valid one.
                raise ConvergenceError(
                    f"{method} diverged on the monolithic closed loop at step {step:.4g} s: a stage of the "
                    f"step from t = {t:.4g} s left the valid states ({type(exc).__name__}: {exc})") from exc
            error = self.leg_error(z)
            if not error < bound:
                raise ConvergenceError(
                    f"{method} diverged on the monolithic closed loop at step {step:.4g} s: leg error "
                    f"{error:.3g} m at t = {t + step:.4g} s exceeds the stroke {bound} m")
            ts.append(t + step)
            errors.append(error)
            if every and (i + 1) % every == 0:
                states.append(z.copy())
            if stop_when_decided and i > 10 and max(errors[-10:]) < DECAYED * errors[0]:
                break
        return np.array(ts), np.array(errors), np.array(states)

    def run(self, method, step, duration=DURATION, offset=OFFSET):
        """Classified Outcome of one run (a ConvergenceError is verdict UNSTABLE with its
        message: the integrator diverged)."""
        try:
            t, error, _ = self.simulate(method, step, duration, offset)
        except ConvergenceError as exc:
            return Outcome(step, math.nan, UNSTABLE, math.nan, np.array([]), np.array([]), message=str(exc))
        verdict, rate = classify(t, error)
        return Outcome(step, math.nan, verdict, rate, t, error)


def closed_loop_matrix(gains=GAINS, params=PARAMS):
    """A (18, 18) of the monolithic closed loop linearised at rest at home, states
    [pose deviation, pose rate, integral]: the plant of controller.design.linearised_plant
    with F = -kp C q + ki I - kd C dq/dt, dI/dt = -C q."""
    plant = linearised_plant(params)
    A, B, C = plant.A, plant.B, plant.C[:, :6]
    zero = np.zeros((6, 6))
    return np.block([
        [A[:6, :6], A[:6, 6:], zero],
        [A[6:, :6] - gains.kp * B[6:] @ C, A[6:, 6:] - gains.kd * B[6:] @ C, gains.ki * B[6:]],
        [-C, zero, zero],
    ])


def stability_function(method, z):
    """R(z) of one step on y' = lambda y, z = h lambda."""
    z = np.asarray(z, dtype=complex)
    if method == "euler":
        return 1 + z
    if method == "rk4":
        return 1 + z + z ** 2 / 2 + z ** 3 / 6 + z ** 4 / 24
    raise ValueError(f"no stability function for {method!r}")


def integrator_step_limit(eigenvalues, method, h_max=1.0, points=4000):
    """Largest step h with |R(h lambda)| <= 1 for every eigenvalue (first crossing along
    each eigenvalue's ray, refined by bisection); 0 if an eigenvalue has Re >= 0."""
    eigenvalues = np.atleast_1d(eigenvalues)
    hs = np.geomspace(1e-7, h_max, points)
    limit = h_max
    for lam in eigenvalues:
        inside = np.abs(stability_function(method, hs * lam)) <= 1
        if not inside[0]:
            return 0.0
        if inside.all():
            continue
        i = int(np.argmin(inside))
        low, high = hs[i - 1], hs[i]
        for _ in range(60):
            mid = 0.5 * (low + high)
            low, high = (mid, high) if abs(stability_function(method, mid * lam)) <= 1 else (low, mid)
        limit = min(limit, low)
    return limit


def predicted_integrator_limit(method, k=1.0, gains=GAINS):
    """(step limit [s], eigenvalue that sets it) of the linearised monolithic loop."""
    eigenvalues = np.linalg.eigvals(closed_loop_matrix(scaled(gains, k)))
    limits = [integrator_step_limit(lam, method) for lam in eigenvalues]
    i = int(np.argmin(limits))
    return limits[i], eigenvalues[i]


def observed_integrator_limit(method, k=1.0, gains=GAINS, low=0.25e-3, high=40e-3, iterations=8,
                              duration=DURATION):
    """(largest stable, smallest unstable) step [s] of ``method`` on the monolithic loop,
    by geometric bisection between ``low`` (assumed stable) and ``high`` (checked unstable,
    doubled until it is). A run lasts ``duration`` s and at least 300 steps."""
    ode = ClosedLoopODE(scaled(gains, k))
    run = lambda h: ode.run(method, h, max(duration, 300 * h)).verdict == STABLE
    while run(high):
        low, high = high, 2 * high
        if high > 1.0:
            raise ValueError(f"{method} still stable at a step of {low} s")
    return _bisect(run, low, high, iterations)


def spurious_fixed_point(k=0.25, factor=1.04, steps=300, gains=GAINS):
    """RK4 just beyond its step limit on the low-gain loop: it does not blow up but settles
    on a fixed point of the RK4 map that is not an equilibrium of the ODE (a spurious
    steady state). Returns its step, leg error [m], heave [m] and heave rate [m/s], the
    residual |dz/dt| there and the state change over the last step."""
    ode = ClosedLoopODE(scaled(gains, k))
    h = factor * predicted_integrator_limit("rk4", k, gains)[0]
    _, error, states = ode.simulate("rk4", h, steps * h, stop_when_decided=False, sample=h)
    z = states[-1]
    return {"step": float(h), "leg_error": float(error[-1]), "heave": float(z[2] - ode.reference[2]),
            "heave_rate": float(z[8]), "residual": float(np.abs(ode.rhs(0.0, z)).max()),
            "change": float(np.abs(states[-1] - states[-2]).max())}


# ------------------------------------------------------------------ convergence orders
def orders(steps, errors):
    """Observed orders log(e_i / e_i+1) / log(h_i / h_i+1)."""
    steps, errors = np.asarray(steps), np.asarray(errors)
    return np.log(errors[:-1] / errors[1:]) / np.log(steps[:-1] / steps[1:])


PLANT_ERROR = "pose after 0.4 s against max_step / 16, largest of x, y, z [m] and the angles [rad]"
COSIM_ERROR = "leg lengths against the monolithic loop (RK4, 0.1 ms), largest over legs and 0.2 s [m]"


def plant_convergence(method="rk4", max_steps=(0.1, 0.05, 0.025, 0.0125), duration=0.4,
                      push=(400.0, -300.0, 200.0, 0.0, 300.0, -500.0)):
    """Pose error after one advance of ``duration`` s of the plant (HexapodODE, fixed
    base, the holding forces plus ``push`` [N] held) against the same method at a 16x
    finer max_step, for each max_step. Returns (max_steps, errors [m or rad])."""
    forces = inverse_dynamics(PARAMS, HOME_POSE, np.zeros(6), np.zeros(6)) + np.asarray(push)

    def final(max_step):
        ode = HexapodODE(PARAMS, moving_base=False, method=method, max_step=max_step)
        ode.set_inputs(0.0, forces)
        x = np.r_[HOME_POSE, np.zeros(6)]
        ode.advance(x, duration)
        return x

    reference = final(min(max_steps) / 16)
    return np.array(max_steps), np.array([np.abs(final(s) - reference)[:6].max() for s in max_steps])


def cosim_convergence(cosim, steps=(1e-3, 5e-4, 2.5e-4, 1.25e-4), duration=0.2, k=1.0, gains=GAINS,
                      reference_step=1e-4, offset=OFFSET):
    """Leg-length error of the co-simulation against the monolithic closed loop (RK4 at
    ``reference_step``), max over the times on a 1 ms grid up to ``duration``, for each
    communication step. Returns (steps, errors [m])."""
    ode = ClosedLoopODE(scaled(gains, k))
    grid = 1e-3
    _, _, states = ode.simulate("rk4", reference_step, duration, offset, stop_when_decided=False, sample=grid)
    reference = inverse_kinematics(PARAMS, states[:, :6])
    errors = []
    for h in steps:
        out = _lengths_on_grid(cosim, h, k, duration, gains, offset, grid)
        errors.append(np.abs(out - reference[:len(out)]).max())
    return np.array(steps), np.array(errors)


def _lengths_on_grid(cosim, h, k, duration, gains, offset, grid):
    """Plant leg lengths of a co-simulation at the multiples of ``grid`` s."""
    lengths = {}

    class Lengths(_Trace):
        def update(self, t, values):
            n = round(t / grid)
            if abs(t - n * grid) < 1e-9:
                lengths[n] = values["plant.leg_length"].copy()

    text = scenario_text(h, duration, scaled(gains, k), HOME_POSE + offset)
    scenario = spec.parse(text, "studies.stability")
    single.run(scenario, cosim.paths, spec.bind(scenario, cosim.descriptions), cosim.outdir, "order",
               [Lengths(None, False)])
    return np.array([lengths[n] for n in sorted(lengths)])


# ------------------------------------------------------------------------------ charts
def _plt():
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt


def plot_boundary(panels, path, gains=GAINS, resolution=48):
    """Predicted boundary (spectral radius = 1 of closed_loop_stable on a fine grid: the
    force limit plays no part in it) and observed verdicts (markers) in the (h, k) plane;
    one panel per (title, BoundaryStudy) in ``panels``."""
    plt = _plt()
    from scenarios.output.charts import save
    first = panels[0][1]
    hs = np.geomspace(first.steps.min() / 1.3, first.steps.max() * 1.3, resolution)
    ks = np.geomspace(first.scales.min() / 1.3, first.scales.max() * 1.3, resolution)
    rho = np.array([[predicted(h, k, gains)[1] for h in hs] for k in ks])
    fig, axes = plt.subplots(1, len(panels), figsize=(6.2 * len(panels) + 3.2, 6.2), squeeze=False)
    style = {STABLE: dict(marker="o", color="tab:green", ls="none", ms=8, label="observed: error decays"),
             UNSTABLE: dict(marker="x", color="tab:red", ls="none", ms=9, mew=2, label="observed: error grows"),
             FAILED: dict(marker="s", color="k", ls="none", ms=7,
                           label="observed: run failed (FmuError, a leg past its stroke)")}
    labels = {}
    for ax, (title, study) in zip(axes[0], panels):
        ax.contourf(hs * 1e3, ks, rho, levels=[0, 1, np.inf], colors=["#e8f4e8", "#f8e4e4"])
        ax.contour(hs * 1e3, ks, rho, levels=[1.0], colors="k", linewidths=1.8)
        ax.plot([], [], "k-", lw=1.8, label="predicted boundary: spectral radius 1\n(linearised plant, ZOH, "
                "one-step delay)")
        K, H = np.meshgrid(study.scales, study.steps, indexing="ij")
        for verdict, kw in style.items():
            mask = study.verdicts == verdict
            if mask.any():
                ax.plot(H[mask] * 1e3, K[mask], **kw)
        wrong = (study.verdicts == STABLE) != (study.radius < 1)
        if wrong.any():
            ax.plot(H[wrong] * 1e3, K[wrong], "o", mfc="none", mec="tab:orange", ms=15, mew=2,
                    label="observation disagrees with prediction")
        for n, (k, h_pred, good, bad) in enumerate(study.step_limits if study.refine else []):
            if np.isfinite(bad):
                ax.plot([good * 1e3, bad * 1e3], [k, k], "|-", color="tab:blue", ms=12, mew=2,
                        label="observed step limit (bisection bracket)" if n == 0 else None)
        if study.gain_limit and study.refine:
            h, _, bad, good = study.gain_limit
            ax.plot([h * 1e3, h * 1e3], [bad, good], "_-", color="tab:purple", ms=12, mew=2,
                    label="observed gain limit (bisection bracket)")
        ax.plot(1.0, 1.0, "*", color="gold", mec="k", ms=16, label="shipped design (k = 1, h = 1 ms)")
        _log_axes(ax, study.steps * 1e3, study.scales)
        ax.set_xlabel("communication step h [ms]")
        ax.set_ylabel("gain scale k (kp, ki, kd all x k)")
        ax.set_title(f"{title}\n{study.runs} co-simulations; grid: {study.agreement:.0%} agree with the "
                     "prediction", fontsize=10)
        for handle, label in zip(*ax.get_legend_handles_labels()):
            labels.setdefault(label, handle)
    fig.suptitle("Co-simulation stability: plant + PID FMUs, Jacobi master, fixed base, 10 µm step disturbance; "
                 "shading: predicted stable (green) / unstable (red)", fontsize=10)
    fig.legend(list(labels.values()), list(labels.keys()), loc="center right", fontsize=8, framealpha=0.9)
    fig.tight_layout(rect=(0, 0, 1 - 3.4 / fig.get_figwidth(), 1))
    path.parent.mkdir(parents=True, exist_ok=True)
    save(fig, path)
    return path


def plot_integrators(limits, path, cosim_limits=None, gains=GAINS):
    """Left: the stability regions |R(z)| = 1 of explicit Euler and RK4 with h lambda of
    the closed loop's eigenvalues at each method's observed limit (k = 1). Right: step
    limits against k, predicted (lines) and observed (markers); the co-simulation's
    predicted limit for comparison."""
    plt = _plt()
    from scenarios.output.charts import save
    fig, (left, zoom, right) = plt.subplots(1, 3, figsize=(16, 5.6), width_ratios=(1, 0.9, 1.2))
    x, y = np.meshgrid(np.linspace(-3.5, 1.0, 500), np.linspace(-3.2, 3.2, 500))
    colors = {"euler": "tab:blue", "rk4": "tab:red"}
    MARKS = {"euler": "s", "rk4": "o"}
    for method, color in colors.items():
        left.contour(x, y, np.abs(stability_function(method, x + 1j * y)), levels=[1.0], colors=color)
        left.plot([], [], color=color, label=f"|R(z)| = 1, {'explicit Euler' if method == 'euler' else 'RK4'}")
    eigenvalues = np.linalg.eigvals(closed_loop_matrix(gains))
    # most eigenvalues sit within |h lambda| < 0.3, where the whole plane's markers pile
    # up: the middle panel zooms on them
    for ax in (left, zoom):
        for method, color in colors.items():
            row = [r for r in limits if r[0] == method and r[1] == 1.0]
            if row:
                h = row[0][3]
                ax.plot((h * eigenvalues).real, (h * eigenvalues).imag, MARKS[method], color=color, mfc="none",
                        ms=6 if ax is left else 5, label=f"h lambda at the observed {method} limit h = {h * 1e3:.2f} "
                        "ms (k = 1)")
        ax.axhline(0, color="0.6", lw=0.5)
        ax.axvline(0, color="0.6", lw=0.5)
    for method, color in colors.items():
        zoom.contour(x, y, np.abs(stability_function(method, x + 1j * y)), levels=[1.0], colors=color)
    zoom.set(xlim=(-0.4, 0.05), ylim=(-0.22, 0.22), aspect="equal", xlabel="Re(h lambda)",
             title="the same, near the origin")
    zoom.set_xticks([-0.4, -0.3, -0.2, -0.1, 0.0])
    left.indicate_inset((-0.4, -0.22, 0.45, 0.44), inset_ax=zoom, edgecolor="0.4")
    left.set_aspect("equal")
    left.set_xlabel("Re(h lambda)")
    left.set_ylabel("Im(h lambda)")
    left.set_title("Stability regions and the closed loop's eigenvalues")
    left.legend(fontsize=7, loc="lower left", framealpha=0.95)
    ks = np.geomspace(0.22, 4.5, 60)
    for method, color in colors.items():
        pred = [predicted_integrator_limit(method, k, gains)[0] for k in ks]
        right.plot(ks, np.array(pred) * 1e3, "-", color=color, label=f"{method}: predicted (eigenvalues)")
        rows = [r for r in limits if r[0] == method]
        if rows:
            k_obs = np.array([r[1] for r in rows])
            lo, hi = np.array([r[3] for r in rows]), np.array([r[4] for r in rows])
            right.errorbar(k_obs, np.sqrt(lo * hi) * 1e3, yerr=[(np.sqrt(lo * hi) - lo) * 1e3,
                           (hi - np.sqrt(lo * hi)) * 1e3], fmt="o", color=color, capsize=3,
                           label=f"{method}: observed (bisection)")
    if cosim_limits is not None:
        right.plot(ks, [predicted_step_limit(k, gains) * 1e3 for k in ks], "k--",
                   label="co-simulation (ZOH + delay): predicted")
    _log_axes(right, [0.25, 0.5, 1, 2, 4], [1, 2, 5, 10, 20, 50, 100])
    right.set_xlabel("gain scale k")
    right.set_ylabel("largest stable step [ms]")
    right.set_title("Monolithic closed loop: explicit integrators' step limit")
    right.legend(fontsize=8)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    save(fig, path)
    return path


def _log_axes(ax, xticks, yticks):
    """Log axes with plain-number ticks at the grid values."""
    from matplotlib.ticker import NullFormatter
    ax.set_xscale("log")
    ax.set_yscale("log")
    for ticks, axis in ((xticks, ax.xaxis), (yticks, ax.yaxis)):
        if ticks is not None:
            axis.set_ticks(list(ticks))
            axis.set_ticklabels([f"{v:g}" for v in ticks])
            axis.set_minor_formatter(NullFormatter())
    ax.grid(True, which="major", alpha=0.3)


def plot_convergence(curves, path):
    """Error against step (log-log) with the observed orders in the legend; ``curves``:
    (label, steps, errors, what the error is)."""
    plt = _plt()
    from scenarios.output.charts import plain_log_axis, save
    fig, ax = plt.subplots(figsize=(8.5, 5.6), layout="constrained")
    for label, steps, errors, what in curves:
        p = orders(steps, errors)
        ax.loglog(np.array(steps) * 1e3, errors, "o-", label=f"{label}: order {', '.join(f'{v:.2f}' for v in p)}\n"
                  f"  error: {what}")
    plain_log_axis(ax.xaxis, subs=(1.0,))
    ax.set_xlabel("step [ms] (plant: max_step; co-simulation: communication step)")
    ax.set_ylabel("error against the curve's reference [m] (log)")
    ax.set_title("Convergence inside the stable region")
    ax.grid(True, which="major", alpha=0.3)
    fig.legend(*ax.get_legend_handles_labels(), fontsize=8, loc="outside lower center")
    path.parent.mkdir(parents=True, exist_ok=True)
    save(fig, path)
    return path


# -------------------------------------------------------------------------------- main
def main(argv=None):
    parser = argparse.ArgumentParser(description="Stability study: where the co-simulation and the "
                                                 "explicit integrators fail, predicted and observed.")
    parser.add_argument("--full", action="store_true", help="half-octave grid (11 x 11) instead of octaves (6 x 6)")
    parser.add_argument("--out", default=str(FIGURES), help="folder for the charts")
    parser.add_argument("--fmu-dir", default=None, help="build the FMUs here (default: a temporary folder)")
    args = parser.parse_args(argv)
    out = pathlib.Path(args.out)
    started = time.perf_counter()
    cosim = CoSim(fmu_dir=args.fmu_dir)
    print(f"default gains: kp {GAINS.kp:.4g} N/m, ki {GAINS.ki:.4g} N/(m s), kd {GAINS.kd:.4g} N s/m, "
          f"force limit {GAINS.force_limit:.3g} N; initial offset {np.abs(OFFSET).max() * 1e6:.0f} µm/µrad, "
          f"runs of {DURATION} s")

    steps, scales = (FULL_STEPS, FULL_SCALES) if args.full else (SMALL_STEPS, SMALL_SCALES)
    study = sweep(steps, scales, cosim)
    print(f"\n1. Co-simulation stability ({study.runs} runs, {study.wall:.1f} s of co-simulation)")
    print("   cell: observed verdict (S stable, U unstable, F failed), predicted growth rate ln(rho)/h and")
    print("   observed growth rate of the leg error [1/s] ('sat': the force saturated, no rate)")
    print("   k \\ h [ms] " + "".join(f"{h * 1e3:>17.3g}" for h in study.steps))
    for i, k in enumerate(study.scales):
        cells = []
        for j, h in enumerate(study.steps):
            sigma = math.log(study.radius[i, j]) / h
            rate = "sat" if study.saturated[i, j] else f"{study.rates[i, j]:+.1f}"
            cells.append(f"{study.verdicts[i, j][0].upper()} {sigma:+6.1f}/{rate:>6}")
        print(f"   {k:9.3g}  " + "".join(f"{c:>17}" for c in cells))
    print(f"   agreement with the prediction: {study.agreement:.0%} of {study.verdicts.size} grid points")
    for (k, h), msg in study.messages.items():
        print(f"   failed at k {k:.3g}, h {h * 1e3:.3g} ms: {msg.splitlines()[0]}")
    print("   step limit per k: predicted h_max [ms] | observed bracket [ms] (bisection, 6 s runs) | "
          "predicted / observed")
    for k, h_pred, good, bad in study.step_limits:
        if np.isfinite(bad):
            print(f"     k {k:6.3g}: {h_pred * 1e3:7.3f} | [{good * 1e3:.3f}, {bad * 1e3:.3f}] | "
                  f"{h_pred / math.sqrt(good * bad):.3f}")
        else:
            print(f"     k {k:6.3g}: {h_pred * 1e3:7.3f} | stable up to the grid's largest step {good * 1e3:.3f}")
    if study.gain_limit:
        h, k_pred, bad, good = study.gain_limit
        print(f"   gain limit at h = {h * 1e3:g} ms: predicted k_min {k_pred:.4f}, observed bracket "
              f"[{bad:.4f}, {good:.4f}] (continuous-time Routh limit of the heaviest mode: "
              f"{_routh_gain_limit():.4f})")
    unlimited = sweep(steps, scales, cosim, refine=0, gains=replace(GAINS, force_limit=UNLIMITED_FORCE))
    failed = unlimited.verdicts == FAILED
    print(f"   the same grid with an unlimited actuator (force limit {UNLIMITED_FORCE:.0e} N, {unlimited.runs} runs): "
          f"{unlimited.agreement:.0%} agree; {failed.sum()} of {np.sum(unlimited.radius >= 1)} predicted-unstable "
          "runs fail (FmuError), e.g.:")
    for (k, h), msg in list(unlimited.messages.items())[:1]:
        print(f"     k {k:.3g}, h {h * 1e3:.3g} ms: {' '.join(msg.split())}")
    panels = [(f"shipped force limit {GAINS.force_limit / 1e3:g} kN: unstable runs saturate", study),
              (f"unlimited actuator ({UNLIMITED_FORCE:.0e} N): unstable runs leave the stroke", unlimited)]
    print(f"   chart: {plot_boundary(panels, out / 'stability_boundary.png')}")

    print("\n2. Explicit integrators on the monolithic closed loop (plant + continuous PID as one ODE)")
    t0 = time.perf_counter()
    limits = []
    for k in (0.25, 0.5, 1.0, 2.0, 4.0):
        for method in ("euler", "rk4"):
            h_pred, lam = predicted_integrator_limit(method, k)
            good, bad = observed_integrator_limit(method, k)
            limits.append((method, k, h_pred, good, bad))
            print(f"   {method:5s} k {k:4.3g}: predicted {h_pred * 1e3:7.3f} ms (set by lambda = "
                  f"{lam.real:.1f}{lam.imag:+.1f}j 1/s) | observed [{good * 1e3:.3f}, {bad * 1e3:.3f}] ms | "
                  f"pred/obs {h_pred / math.sqrt(good * bad):.3f}")
    ghost = spurious_fixed_point()
    print(f"   rk4 just beyond its limit at k 0.25 (h = {ghost['step'] * 1e3:.1f} ms): no error, no NaN, the run "
          f"settles on a fixed point of the RK4 map: leg error {ghost['leg_error'] * 1e3:.1f} mm, heave "
          f"{ghost['heave'] * 1e3:.1f} mm, heave rate {ghost['heave_rate']:.2f} m/s while the pose stays put "
          f"(|dz/dt| {ghost['residual']:.3g}, state change per step {ghost['change']:.2g})")
    print(f"   ({time.perf_counter() - t0:.1f} s)")
    print(f"   chart: {plot_integrators(limits, out / 'integrator_stability.png', cosim_limits=True)}")

    print("\n3. Convergence orders inside the stable region")
    t0 = time.perf_counter()
    curves = []
    for method in ("rk4", "euler"):
        max_steps = (0.1, 0.05, 0.025, 0.0125) if method == "rk4" else (0.02, 0.01, 0.005, 0.0025)
        s, e = plant_convergence(method, max_steps)
        curves.append((f"plant {method} (max_step)", s, e, PLANT_ERROR))
    s, e = cosim_convergence(cosim)
    curves.append(("co-simulation, Jacobi ZOH (comm step)", s, e, COSIM_ERROR))
    for label, s, e, _ in curves:
        print(f"   {label:40s} steps [ms] {np.round(s * 1e3, 4).tolist()}  errors {[f'{v:.3g}' for v in e]}  "
              f"orders {np.round(orders(s, e), 2).tolist()}")
    print(f"   ({time.perf_counter() - t0:.1f} s)")
    print(f"   chart: {plot_convergence(curves, out / 'convergence_order.png')}")
    print(f"\nstudy wall time {time.perf_counter() - started:.1f} s")


def _routh_gain_limit(gains=GAINS):
    """Continuous-time lower gain limit of the heaviest leg-space mode: k > m ki / (kd kp)."""
    from controller.design import leg_mass_matrix
    mass = np.linalg.eigvalsh(leg_mass_matrix(PARAMS))[-1]
    return mass * gains.ki / (gains.kd * gains.kp)


if __name__ == "__main__":
    main()
