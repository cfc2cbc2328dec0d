"""A run that went wrong says so: the stability prediction before a run, the detectors
during it, and the Flag each of them raises.

Before (``predict``, ``check``): the hexapod loop of the scenario (plant, controller and
a leg sensor between them if there is one) as controller.design models it, with the
scenario's master, extrapolation, gains and plant (fidelity, reflected mass, actuator
lag, friction), and its leg-space masses at poses along the reference motion (the
telescope FMU stepped alone, as fidelity="auto" does). Its predicted step limit is the
smallest over those poses. A step beyond it is refused (ScenarioError naming the limit
and what would run) unless the run is asked for anyway; then every run is flagged.
The model is linear and leaves out gravity stiffness, Coulomb friction and saturation.

During (``Watch``, fed each recorded row by the master): what a prediction cannot see.
Kinds of Flag:

* ``step_beyond_limit``: run anyway beyond the predicted limit (the loop is unstable);
* ``unstable``: the leg-force oscillation (second difference of the recorded forces,
  which a smooth motion keeps small) or that of the leg lengths grows steadily;
* ``saturated``: leg forces at the controller's force limit, with the fraction of time,
  and every warning an FMU logged (the controller warns when it saturates);
* ``stroke``: a leg within 10 % of the end of its stroke;
* ``non_finite``: a recorded value is NaN or infinite;
* ``cut_short``: an FMU stopped the run (RunFailed) before its stop time;
* ``motion_unfinished``: a slew whose stop time comes before the motion ends.
"""
import math
from dataclasses import dataclass, replace

import numpy as np

from movingbase.controller import design
from movingbase.plant.stewart import FIDELITIES, HOME_POSE, StewartParams, dynamics_terms
from . import fidelity as scene_fidelity
from .records import Block
from .spec import ScenarioError

POSES = 9             # poses along the reference motion at which the leg-space masses are taken
WINDOW = 1.0          # s: the detectors' envelope window (shorter for short runs, see Watch.window)
GROWTH = 10.0         # an envelope that grows by this factor ...
GROWTH_WINDOWS = 6    # ... steadily over at least this many windows is unstable
PERSIST = 3.0         # a growth that ends at its peak counts if the envelope after it stays above peak / PERSIST
FLOORS = (50.0, 1e-7)     # N, m: oscillation envelopes below these are noise, not growth
NEAR_STROKE = 0.9     # a leg beyond this fraction of its half stroke is near its end
MOVING = 1e-6         # rad/s: a base still turning faster than this at stop has not arrived


@dataclass(frozen=True)
class Flag:
    """Something wrong with a run: ``kind`` (see the module doc) and a sentence."""

    kind: str
    message: str


def as_dicts(flags):
    return [{"kind": f.kind, "message": f.message} for f in flags]


def from_dicts(items):
    return [Flag(d["kind"], d["message"]) for d in items or []]


# the kinds, worst first: a run that did not reach its stop time is no result at all, so
# its cause is said before any symptom it showed on the way (reprs, tables, summaries)
SEVERITY = ("cut_short", "non_finite", "step_beyond_limit", "unstable", "saturated", "stroke",
            "motion_unfinished", "fmu_warning")


def by_severity(flags):
    """The flags, worst kind first (kinds not in SEVERITY last, in their order)."""
    rank = {kind: i for i, kind in enumerate(SEVERITY)}
    return sorted(flags, key=lambda f: rank.get(f.kind, len(SEVERITY)))


def summary(flags):
    """One line of a run's flags, worst first ('' if none); a cut-short run starts FAILED."""
    ordered = by_severity(flags)
    text = "; ".join(f"{f.kind}: {f.message}" for f in ordered)
    return f"FAILED ({text})" if ordered and ordered[0].kind == "cut_short" else text


# ------------------------------------------------------------------ before the run
@dataclass(frozen=True)
class Prediction:
    """The predicted step limit [s] of a scenario's hexapod loop, the loop and the
    leg-space masses [kg] it was taken over, and the scene's flags known before it runs."""

    limit: float
    step: float
    loop: design.LoopModel
    gains: object
    masses: np.ndarray
    flags: tuple = ()

    @property
    def beyond(self):
        return self.step > self.limit


def _of_type(scenario, kind):
    return [inst for inst, fmu in scenario.fmus.items() if fmu == kind]


def _sources(scenario, target):
    """Instances whose outputs feed the input ``target`` ("inst.var")."""
    return [s.split(".", 1)[0] for s, targets in scenario.connections if target in targets]


def _value(values, descriptions, inst, name):
    """A parameter as the run will use it: the scenario's value, else the FMU's start value."""
    given = values.get(inst, {}).get(name)
    if isinstance(given, (int, float)):   # not a link ("@inst.var"): those stay at the FMU's start value
        return given
    start = next(v.start for v in descriptions[inst].modelVariables if v.name == name)
    return float(start) if name != "fidelity" else int(start)


def _loop(scenario, descriptions, values):
    """(plant, controller, LoopModel, PIDGains) of the scenario's hexapod loop, or None."""
    for controller in _of_type(scenario, "leg_controller"):
        plants = [inst for inst in _of_type(scenario, "hexapod_plant")
                  if controller in _sources(scenario, f"{inst}.leg_force")]
        if not plants:
            continue
        plant = plants[0]
        feeds = _sources(scenario, f"{controller}.leg_length")
        sensor = next((s for s in feeds if scenario.fmus[s] == "leg_sensor"), None)
        get = lambda inst, name: _value(values, descriptions, inst, name)
        gains = design.PIDGains(get(controller, "kp"), get(controller, "ki"), get(controller, "kd"),
                                get(controller, "force_limit"))
        loop = design.LoopModel(
            reflected_mass=get(plant, "reflected_mass"), actuator_bandwidth=get(plant, "actuator_bandwidth"),
            viscous_friction=get(plant, "viscous_friction"), leg_sensor=sensor is not None,
            rate_cutoff=get(sensor, "rate_cutoff") if sensor else 0.0,
            delay_steps=int(get(sensor, "delay_steps")) if sensor else 0,
            # "derivatives" extrapolates the loop's own signals (leg forces, lengths, rates: no
            # FMU of the loop gives derivatives) linearly, so the loop is the linear one
            extrapolate=scenario.extrapolation in ("linear", "derivatives"), gauss_seidel=scenario.master == "gauss-seidel")
        return plant, controller, loop, gains
    return None


def plant_params(values, descriptions, plant):
    return StewartParams.paper(stroke=(-_value(values, descriptions, plant, "stroke"),
                                       _value(values, descriptions, plant, "stroke")))


def leg_masses(params, poses, loop, fidelity="full"):
    """Leg-space modal masses [kg] (M_leg + m_r I) at every pose (n, 6), one array."""
    terms = dynamics_terms(params, poses, np.zeros_like(poses), fidelity=fidelity)
    inverse = np.linalg.inv(terms.jacobian)
    m_leg = np.swapaxes(inverse, -1, -2) @ terms.mass @ inverse
    return np.linalg.eigvalsh(m_leg).ravel() + loop.reflected_mass


def _merge(masses, rtol=1e-3):
    """The masses with those within ``rtol`` of a kept one left out: the limit moves
    smoothly with the mass, so near-equal modes need no evaluation of their own."""
    kept = []
    for m in np.sort(masses):
        if not kept or m > kept[-1] * (1 + rtol):
            kept.append(m)
    return np.array(kept)


def predict(scenario, paths, descriptions, values, ci=False):
    """The Prediction for a scenario (None if it has no hexapod loop to predict)."""
    found = _loop(scenario, descriptions, values)
    if found is None:
        return None
    plant, controller, loop, gains = found
    poses, flags = HOME_POSE[None, :], []
    telescope = _telescope(scenario, controller)
    if telescope:
        motion = scene_fidelity.scene_motion(scenario, paths, values, telescope)
        poses = motion[0][np.linspace(0, len(motion[0]) - 1, POSES).round().astype(int)]
        flags = [] if ci else _unfinished(scenario, telescope, motion[4])
    level = values.get(plant, {}).get("fidelity", _value(values, descriptions, plant, "fidelity"))
    fidelity = FIDELITIES[level] if isinstance(level, int) else level
    masses = _merge(leg_masses(plant_params(values, descriptions, plant), poses, loop, fidelity))
    limit = design.step_limit(masses, gains, loop)
    return Prediction(limit, scenario.step, loop, gains, masses, tuple(flags))


def motion_flags(scenario, paths, descriptions, values):
    """The flags of the scene's motion alone (a slew unfinished at the stop time): what
    ``predict`` flags per scenario, for each run of a campaign, whose limit is predicted
    once for many runs."""
    found = _loop(scenario, descriptions, values)
    telescope = found and _telescope(scenario, found[1])
    if not telescope:
        return []
    return _unfinished(scenario, telescope, scene_fidelity.scene_motion(scenario, paths, values, telescope)[4])


def _telescope(scenario, controller):
    """The telescope instance feeding the controller's reference pose, or None."""
    return next((s for s in _sources(scenario, f"{controller}.reference_pose") if scenario.fmus[s] == "telescope"),
                None)


def _unfinished(scenario, telescope, base_rate):
    """[motion_unfinished] if the slew (or paper manoeuvre) still turns the base at the
    stop time (``base_rate`` along the run), else []."""
    profile = scenario.parameters.get(telescope, {}).get("profile", "slew")
    turning = float(np.linalg.norm(base_rate[-1][3:]))
    if profile in ("slew", "paper") and turning > MOVING:
        return [Flag("motion_unfinished", f"the {profile} of {telescope!r} has not ended at the stop time "
                                          f"{scenario.stop_time:g} s: the base still turns at "
                                          f"{math.degrees(turning):.3g} deg/s")]
    return []


def _describe(loop, extrapolation=None):
    """The loop's master and extrapolation; ``extrapolation`` "derivatives" is named as
    the scenario says, with what the loop gets (linear)."""
    master = "gauss-seidel" if loop.gauss_seidel else "jacobi"
    if extrapolation == "derivatives":
        return f"master {master}, extrapolation derivatives (linear on the leg loop, whose signals have none)"
    return f"master {master}, extrapolation {'linear' if loop.extrapolate else 'none'}"


def _ms(seconds):
    return "no step (the gains are unstable)" if seconds == 0 else f"{seconds * 1e3:.4g} ms"


def check(scenario, prediction, allow_unstable=False):
    """Refuse a step beyond the predicted limit (ScenarioError: the limit and what would
    run), or with ``allow_unstable`` return the flags every run of it gets."""
    if prediction is None:
        return []
    flags = list(prediction.flags)
    if not prediction.beyond:
        return flags
    others = []
    for gs in (False, True):
        for ex in (False, True):
            loop = replace(prediction.loop, gauss_seidel=gs, extrapolate=ex)
            if loop != prediction.loop:
                other = design.step_limit(prediction.masses, prediction.gains, loop)
                if other >= scenario.step:
                    others.append(f"{_describe(loop)} (limit {_ms(other)})")
    if prediction.limit > 0:
        text = (f"{scenario.step * 1e3:g} ms is beyond the predicted stability limit {_ms(prediction.limit)} of "
                f"this loop ({_describe(prediction.loop, scenario.extrapolation)}, its gains and plant, along the "
                f"motion): the leg loop would oscillate and grow")
        hint = f"use a step below {_ms(prediction.limit)}"
    else:
        text = (f"no step is stable with these gains ({_describe(prediction.loop, scenario.extrapolation)}, "
                f"along the motion): the leg loop would drift or grow at {scenario.step * 1e3:g} ms as at any step")
        hint = "choose gains that stabilise the loop (controller.design)"
    if not allow_unstable:
        if others:
            hint += " or " + " or ".join(others)
        raise ScenarioError(scenario.source, "step", f"{text}. {hint[0].upper() + hint[1:]}; or run it anyway "
                                                     "with --allow-unstable (allow_unstable=True): it is then flagged")
    return flags + [Flag("step_beyond_limit", text + " (run with --allow-unstable)")]


# ------------------------------------------------------------------ during the run
class Watch:
    """Detectors fed every recorded row (``feed``, in the recorder's blocks; rows buffered
    and evaluated BLOCK at a time, as the metrics do), per ``window`` of time: the
    envelope of the leg forces' and lengths' second difference (an oscillation; a smooth
    motion keeps it small), rows with a force at its limit, the legs' extent into their
    stroke, non-finite values. Memory: a few numbers per window."""

    BLOCK = 256

    def __init__(self, force_limit=None, home_lengths=None, stroke=None, forces=None, lengths=None, window=WINDOW):
        self.force_limit, self.home, self.stroke, self.window = force_limit, home_lengths, stroke, window
        self.forces, self.lengths = forces, lengths
        self.needs = [r for r in (forces, lengths) if r]
        self.t0 = None
        self.env = {forces: np.zeros(0), lengths: np.zeros(0)}   # per window: largest |second difference|
        self.held = np.zeros(0)       # per window: rows with a force at its limit
        self.extent = 0.0             # largest |length - home| / half stroke
        self.tail = {}                # the last two rows of forces and lengths before this block
        self.non_finite = None        # time of the first non-finite row
        self.rows = 0
        self._block = None

    @classmethod
    def for_scenario(cls, scenario, descriptions, values):
        """A Watch on the scenario's hexapod loop (or on non-finite values only)."""
        found = _loop(scenario, descriptions, values)
        if found is None:
            return cls()
        plant, controller, _, gains = found
        params = plant_params(values, descriptions, plant)
        # WINDOW, or for a short run 1/40 of it but at least 20 recorded rows: enough windows to see a trend
        window = min(WINDOW, max(20 * scenario.record_interval, (scenario.stop_time - scenario.start_time) / 40))
        return cls(gains.force_limit, params.home_lengths, params.stroke[1], f"{controller}.leg_force",
                   f"{plant}.leg_length", window)

    def bind(self, slices):
        """The recorder's columns of each recorded reference."""
        self.slices = slices

    def feed(self, t, rows):
        """Recorded rows (n, the recorder's whole row, copied) at times t (n,)."""
        if self._block is None:
            self._block, self.t0 = Block(self.BLOCK, rows.shape[1]), float(t[0])
        self._block.add(t, [(rows, slice(None))], self._flush)

    def _flush(self):
        if self._block is None or not self._block.filled:
            return
        t, rows = self._block.take()
        n = len(t)
        self.rows += n
        if self.non_finite is None and not np.isfinite(rows).all():
            self.non_finite = float(t[np.argmin(np.isfinite(rows).all(axis=1))])
        window = ((t - self.t0) // self.window).astype(int)
        size = window[-1] + 1
        for ref in self.needs:
            if len(self.env[ref]) < size:
                self.env[ref] = np.r_[self.env[ref], np.zeros(size - len(self.env[ref]))]
            x = rows[:, self.slices[ref]]
            full = np.vstack([self.tail.get(ref, x[:0]), x])
            self.tail[ref] = full[-2:]
            if len(full) > 2:
                second = np.abs(full[2:] - 2 * full[1:-1] + full[:-2]).max(axis=1)
                with np.errstate(invalid="ignore"):
                    np.fmax.at(self.env[ref], window[-len(second):], second)
        if self.forces:
            self.held = np.r_[self.held, np.zeros(max(0, size - len(self.held)))]
            at_limit = np.abs(rows[:, self.slices[self.forces]]).max(axis=1) >= self.force_limit * (1 - 1e-9)
            np.add.at(self.held, window, at_limit)
        if self.lengths:
            reach = np.abs(rows[:, self.slices[self.lengths]] - self.home).max() / self.stroke
            self.extent = max(self.extent, float(np.nan_to_num(reach)))

    def flags(self, warnings=()):
        """The flags of what was fed, and ``warnings`` ((instance, FMU log line)) as flags too."""
        self._flush()
        out = []
        if self.non_finite is not None:
            out.append(Flag("non_finite", f"non-finite values recorded from t = {self.non_finite:g} s"))
        for ref, what, unit, scale, floor in ((self.forces, "leg-force oscillation", "kN", 1e-3, FLOORS[0]),
                                              (self.lengths, "leg-length oscillation", "µm", 1e6, FLOORS[1])):
            grown = ref and growth(self.t0 + self.window * np.arange(len(self.env[ref])), self.env[ref], floor)
            if grown:
                t0, t1, e0, e1 = grown
                out.append(Flag("unstable", f"the {what} (second difference of the recorded values) grows from "
                                            f"{e0 * scale:.3g} {unit} to {e1 * scale:.3g} {unit} between t = "
                                            f"{t0:g} s and {t1:g} s"))
                break
        if self.held.sum():
            first = self.t0 + self.window * np.flatnonzero(self.held)[0]
            out.append(Flag("saturated", f"leg forces at the +-{self.force_limit * 1e-3:g} kN limit "
                                         f"{100 * self.held.sum() / max(1, self.rows):.3g} % of the recorded time "
                                         f"(from t ~ {first:g} s)"))
        if self.lengths and self.extent >= NEAR_STROKE:
            out.append(Flag("stroke", f"a leg reaches {100 * self.extent:.3g} % of its +-{self.stroke * 1e3:g} mm "
                                      "stroke"))
        return merged(out + warning_flags(warnings))


def merged(flags):
    """One flag per kind: a second one of a kind (the detector's and the controller's
    warnings both say 'saturated') joins the first one's message."""
    by_kind = {}
    for flag in flags:
        first = by_kind.setdefault(flag.kind, flag)
        if first is not flag:
            by_kind[flag.kind] = Flag(flag.kind, f"{first.message}; {flag.message}")
    return list(by_kind.values())


def warning_flags(warnings):
    """The FMUs' warnings, one flag per instance: how many, the first and the last (the
    controller warns once per saturation episode: an unstable loop can log thousands)."""
    by_instance = {}
    for instance, line in warnings:
        by_instance.setdefault(instance, []).append(line)
    out = []
    for instance, lines in by_instance.items():
        kind = "saturated" if any("saturated" in line for line in lines) else "fmu_warning"
        text = f"{instance!r} logged {len(lines)} warning{'s' if len(lines) > 1 else ''}: {lines[0]}"
        out.append(Flag(kind, text + (f" ... last: {lines[-1]}" if len(lines) > 1 else "")))
    return out


def growth(times, envelope, floor):
    """(t0, t1, e0, e1) if the envelope (floored at ``floor``) grows GROWTH-fold with a
    steady exponential trend (least squares on its log, R^2 >= 0.8) over GROWTH_WINDOWS
    or more windows that end at the last window or at the envelope's peak (where a growth
    stops at the force limit, and the envelope stays near it after), else None. Steady: a
    slew's transients raise the envelope for a window or two, an unstable loop every window."""
    env = np.maximum(np.asarray(envelope[1:-1], dtype=float), floor)   # first and last window: partial
    t = np.asarray(times[1:-1], dtype=float)
    peak = int(np.argmax(env)) + 1 if len(env) else 0
    for end in dict.fromkeys((len(env), peak)):   # to the end, to the peak
        if end < GROWTH_WINDOWS:
            continue
        if end < len(env) and np.median(env[end:]) < env[end - 1] / PERSIST:
            continue   # it died away after its peak: a transient (a slew's acceleration step), not a growth
        for n in np.unique(np.geomspace(end, GROWTH_WINDOWS, 16).round().astype(int))[::-1]:   # longest first
            x, y = t[end - n:end], np.log(env[end - n:end])
            slope, icept = np.polyfit(x, y, 1)
            fit = slope * x + icept
            total = np.sum((y - y.mean()) ** 2)
            r2 = 1 - np.sum((y - fit) ** 2) / total if total > 0 else 0.0
            if slope > 0 and math.exp(slope * (x[-1] - x[0])) >= GROWTH and r2 >= 0.8 and env[end - 1] >= GROWTH * floor:
                return float(x[0]), float(x[-1]), float(env[end - n]), float(env[end - 1])
    return None


def run_flags(watch, run, instances, before=()):
    """The flags of a finished (or stopped) run: those known before it, the detectors',
    the FMUs' warnings, and a cut-short run."""
    warnings = [(name, line) for name, inst in instances.items() for line in inst.log if line.startswith("[WARNING]")]
    out = list(before) + (watch.flags(warnings) if watch else [])
    if run.failure:
        out.append(Flag("cut_short", f"stopped at t = {run.sim_time:g} s of the run: {run.failure}"))
    return out
