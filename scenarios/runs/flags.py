"""A run that went wrong says so: the stability prediction before a run, the detectors
during it, and the Flag each of them raises. Both are generic over the loops of the
scenario, as catalogue.CONTROL_LOOPS describes each controller FMU's (its plant, force output
and limits, measured output, gains, sensor, reference).

Before (``predict``, ``check``): each loop as controller.design models it, with the
scenario's master, extrapolation, gains and plant (reflected mass, actuator lag,
friction, sensor), and its modal masses along the reference motion (MODAL_MASSES per
plant: the hexapod's leg-space masses at poses of the telescope's motion, stepped alone
as fidelity="auto" does, of the payload as built (the plant's payload errors), each with
the mass its observer assumes for it; the 3T mechanism's slider-space masses along the
slider controller's reference). Its predicted step limit is the smallest over those masses, and
a scenario's the smallest over its loops. It is predicted for every run at its own
values (runner.pre_run_flags: every sweep value; campaign: every case), each distinct
loop once. A step beyond it is refused (ScenarioError naming the runs and their limits)
unless the run is asked for anyway; then exactly the runs beyond their limit are flagged.
The model is linear and leaves out gravity stiffness, Coulomb friction and saturation; a
refusal says when the plant's Coulomb friction, linearised about rest (a damper of slope
coulomb / friction_velocity), would hold the loop: the run may then stay clean, and still
the loop is unstable without it.

During (``Watch``, fed each recorded row by the master): what a prediction cannot see.
Kinds of Flag:

* ``step_beyond_limit``: run anyway beyond the predicted limit (the loop is unstable);
* ``unstable``: a loop's force oscillation (second difference of the recorded forces,
  which a smooth motion keeps small) or that of its measured output grows steadily, by
  itself (per unit of the reference's excitation so far), over windows of CYCLES periods
  of the loop's unstable oscillation;
* ``saturated``: a loop's force command at one of its limits (the controller's, the
  plant's actuator limit) for SATURATED (1 %) of the recorded time or more, or for a
  detector window on end (5 periods of the loop), with the share and the longest stay;
  a shorter touch is no flag (a stable run's transient), and the controller's
  saturation warnings then neither (with a flag, they join it); other FMU warnings;
* ``stroke``: a measured output within 10 % of the end of its stroke;
* ``non_finite``: a recorded value is NaN or infinite;
* ``cut_short``: an FMU stopped the run (RunFailed) before its stop time;
* ``undersampled``: a metric its recorded rows cannot carry (metrics are computed from the
  recorded rows): fewer than 10 counted, or an RMS over every other row 10 % off the RMS
  over all (scenarios.runs.metrics.undersampled);
* ``motion_unfinished``: a slew whose stop time comes before the motion ends.
"""
import functools
import math
from dataclasses import dataclass, replace

import numpy as np

from controller import design
from fmu_src import catalogue
from plant.errors import PlantError
from plant.hexapod.model import FIDELITIES, HOME_POSE, StewartParams, dynamics_terms
from plant.mechanism3t import model as mechanism3t
from plant.telescope import model as telescope_model
from scenarios.cosim.records import Block
from scenarios.runs import auto_fidelity
from scenarios.spec import Scenario, ScenarioError

POSES = 9             # poses along the reference motion at which the leg-space masses are taken
WINDOW = 1.0          # s: the detectors' longest envelope window
GROWTH = 10.0         # an envelope that grows by this factor ...
GROWTH_WINDOWS = 6    # ... steadily over at least this many windows is unstable
CYCLES = 5            # a window: this many periods of the loop's unstable oscillation (see Watch.for_scenario)
EXCITED = 1e-3        # the reference's excitation envelope is floored at this share of its largest
PERSIST = 3.0         # a growth that ends at its peak counts if the envelope after it stays above peak / PERSIST
FLOORS = (50.0, 1e-7)     # N, m: oscillation envelopes below these are noise, not growth
SATURATED = 0.01      # a force at a limit for this share of the recorded time or more, or for a window
                      # on end, is saturated (less: a touch)
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
            "undersampled", "motion_unfinished", "fmu_warning")


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
    leg-space masses [kg] it was taken over (with an observer: (mass, observer's mass)
    pairs), the scene's flags known before it runs, and the plant's payload errors in
    words with the limit the payload as modelled would have."""

    limit: float
    step: float
    loop: design.LoopModel
    gains: object
    masses: np.ndarray
    flags: tuple = ()
    controller: str = "controller"
    coulomb: tuple = (0.0, 1.0)   # the plant's Coulomb friction [N] and its smoothing velocity [m/s]
    payload: str = ""                  # "": the payload as modelled
    modelled_limit: float = math.nan   # nan: the payload as modelled

    @property
    def beyond(self):
        return self.step > self.limit * (1 + 1e-9)   # "1.372 ms", as shown, parses an ulp above it


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
    elements = [v.name for v in descriptions[inst].modelVariables if v.name.startswith(name + "[")]
    if elements:   # a vector: its elements' values
        return [_value(values, descriptions, inst, n) for n in elements]
    variable = next(v for v in descriptions[inst].modelVariables if v.name == name)
    if variable.type == "String":   # the Telescope's replay_table: a path, as set or its start
        return given if isinstance(given, str) else variable.start
    return float(variable.start) if name != "fidelity" else int(variable.start)


@dataclass(frozen=True)
class Loop:
    """One control loop of a scenario, as catalogue.CONTROL_LOOPS describes its controller FMU:
    the instances (``sensor`` None if the controller reads the plant directly), the
    catalogue ``entry``, the gains and the LoopModel of its master, extrapolation, plant
    and sensor."""

    controller: str
    plant: str
    sensor: str
    entry: dict
    gains: object
    model: design.LoopModel

    def limits(self, values, descriptions):
        """((what, force limit [N]), ...): the controller's and the plant's (if it has one)."""
        get = lambda inst, name: _value(values, descriptions, inst, name)
        out = [(f"{self.controller}.{self.entry['limit']}", float(get(self.controller, self.entry["limit"])))]
        if self.entry["plant_limit"] and get(self.plant, self.entry["plant_limit"]) > 0:
            out.append((f"{self.plant}.{self.entry['plant_limit']}", float(get(self.plant, self.entry["plant_limit"]))))
        return tuple(out)


def loops(scenario, descriptions, values):
    """Every loop of the scenario: a controller of catalogue.CONTROL_LOOPS whose force output
    feeds its plant's force input."""
    found = []
    for controller, fmu in scenario.fmus.items():
        entry = catalogue.CONTROL_LOOPS.get(fmu)
        if entry is None:
            continue
        force = f"{controller}.{entry['force']}"
        plant = next((inst for inst in _of_type(scenario, entry["plant"])
                      if force in _targets(scenario, f"{inst}.{entry['plant_force']}")), None)
        if plant is None:
            continue
        feeds = _sources(scenario, f"{controller}.{entry['measured']}")
        sensor = next((s for s in feeds if scenario.fmus[s] in catalogue.LOOP_SENSORS), None)
        get = lambda inst, name: _value(values, descriptions, inst, name)
        gains = design.PIDGains(*(float(get(controller, g)) for g in entry["gains"]),
                                float(get(controller, entry["limit"])))
        fields = {field: float(get(plant, name)) for field, name in entry["loop_model"].items()}
        if sensor:
            given = catalogue.LOOP_SENSORS[scenario.fmus[sensor]][2]
            fields.update({field: get(sensor, name) for field, name in given.items()})
            fields["delay_steps"] = int(fields.get("delay_steps", 0))
        fields.update(_observer_fields(scenario, controller, entry, get))
        if scenario.fmus[plant] in GRAVITY:
            fields["gravity_rate"] = GRAVITY[scenario.fmus[plant]](values, descriptions, controller, plant, entry)
        model = design.LoopModel(
            **fields, leg_sensor=sensor is not None,
            # "derivatives" extrapolates the loop's own signals (forces, lengths, rates: no FMU
            # of a loop gives derivatives) linearly, so the loop is the linear one
            extrapolate=scenario.extrapolation in ("linear", "derivatives"),
            gauss_seidel=scenario.master == "gauss-seidel")
        found.append(Loop(controller, plant, sensor, entry, gains, model))
    return found


def _observer_fields(scenario, controller, entry, get):
    """The LoopModel fields of the controller's disturbance observer (none while it is off)
    and of the load cell feeding it, if one does."""
    fields = {field: float(get(controller, name)) for field, name in entry.get("observer", {}).items()}
    if not fields.get("observer_bandwidth"):
        return {}
    if "observer_leg_space" in fields:   # observer_model: 0 scalar, 1 leg_space (the model's matrix, at home)
        fields["observer_leg_space"] = bool(fields["observer_leg_space"])
        if fields["observer_leg_space"]:
            fields["observer_model_mean"] = design.model_mean_leg_mass(StewartParams.paper())
    feeds = _sources(scenario, f"{controller}.{entry['force_measured']}")
    cell = next((s for s in feeds if scenario.fmus[s] in catalogue.LOAD_CELLS), None)
    if cell:
        fields.update({field: get(cell, name) for field, name in catalogue.LOAD_CELLS[scenario.fmus[cell]].items()},
                      load_cell=True)
        fields["load_cell_delay_steps"] = int(fields["load_cell_delay_steps"])
    return fields


def _targets(scenario, target):
    """The outputs ("inst.var") that feed the input ``target``."""
    return [s for s, targets in scenario.connections if target in targets]


PAYLOAD = ("payload_mass_error", "payload_inertia_error", "payload_com_error")   # the hexapod plant's


def plant_params(values, descriptions, plant):
    """The hexapod the plant FMU integrates: the paper's, its stroke and its payload as built
    (the payload errors added to the paper's platform, as fmu_src/hexapod_plant_fmu.py does)."""
    get = lambda name: _value(values, descriptions, plant, name)   # noqa: E731
    paper, (mass, inertia, com) = StewartParams.paper(), (np.asarray(get(n), dtype=float) for n in PAYLOAD)
    return StewartParams.paper(stroke=(-get("stroke"), get("stroke")), platform_mass=paper.platform_mass + float(mass),
                               platform_inertia=paper.platform_inertia + inertia, platform_com=paper.platform_com + com)


def _payload(values, descriptions, plant):
    """The plant's payload errors in words ("the payload's -1065 kg mass error and ..."), ''
    if it has none (or no payload parameters: the 3T mechanism)."""
    if PAYLOAD[0] not in {v.name for v in descriptions[plant].modelVariables}:
        return ""
    mass, inertia, com = (np.asarray(_value(values, descriptions, plant, n), dtype=float) for n in PAYLOAD)
    said = [f"{mass:+.4g} kg mass error"] if mass else []
    said += [f"({', '.join(f'{i:+.4g}' for i in inertia)}) kg.m2 inertia error"] if inertia.any() else []
    said += [f"centre of mass ({', '.join(f'{c * 1e3:+.4g}' for c in com)}) mm off"] if com.any() else []
    return "the payload's " + " and ".join(said) if said else ""


def _as_modelled(values, plant):
    """``values`` with the plant's payload errors dropped (their start values: 0, the paper's payload)."""
    return {**values, plant: {n: v for n, v in values.get(plant, {}).items() if n.split("[", 1)[0] not in PAYLOAD}}


def leg_masses(params, poses, loop, fidelity="full"):
    """Leg-space modal masses [kg] (M_leg + m_r I) at every pose (n, 6): one array, or with
    the loop's observer on (mass, the observer's mass) pairs (design.observer_masses) of
    its matrix M_o: observer_mass I, or (observer_model leg_space) the controller's model,
    the paper's payload, shifted by observer_mass less its mean diagonal at home
    (controller/c/observer.c). The model matrix is taken at each pose as the plant's (the
    guard's convention before payloads: that the model keeps its home matrix along a
    motion is left out, LoopModel), so a payload as modelled gives each mode its own mass."""
    m_leg = _leg_matrices(params, poses, fidelity)
    if loop.observer_bandwidth <= 0:
        return np.linalg.eigvalsh(m_leg).ravel() + loop.reflected_mass
    shift = (loop.observer_mass - loop.observer_model_mean) * np.eye(6)
    observer = _leg_matrices(StewartParams.paper(), poses, fidelity) + shift if loop.observer_leg_space else \
        [loop.observer_mass * np.eye(6)] * len(poses)
    return np.concatenate([design.observer_masses(plant, own, loop.reflected_mass)
                           for plant, own in zip(m_leg, observer)])


def _leg_matrices(params, poses, fidelity):
    """M_leg = J^-T M J^-1 at every pose (n, 6, 6) [kg]."""
    terms = dynamics_terms(params, poses, np.zeros_like(poses), fidelity=fidelity)
    inverse = np.linalg.inv(terms.jacobian)
    return np.swapaxes(inverse, -1, -2) @ terms.mass @ inverse


def _hexapod_masses(scenario, paths, descriptions, values, loop, motion):
    """The hexapod's leg-space masses at POSES poses along the telescope's reference
    (``motion``, or the home pose without one), at the plant's fidelity."""
    poses = HOME_POSE[None, :]
    if motion is not None:
        poses = motion[0][np.linspace(0, len(motion[0]) - 1, POSES).round().astype(int)]
    level = values.get(loop.plant, {}).get("fidelity", _value(values, descriptions, loop.plant, "fidelity"))
    fidelity = FIDELITIES[level] if isinstance(level, int) else level
    return leg_masses(plant_params(values, descriptions, loop.plant), poses, loop.model, fidelity)


def _refused_by_3t(function):
    """A 3T model's refusal along the reference (a singular configuration the scenario's checks,
    scenarios.spec.checks, do not test point by point) as a ScenarioError, never the model's own."""
    def told(*args):
        try:
            return function(*args)
        except PlantError as exc:
            source = args[0].source if isinstance(args[0], Scenario) else "scenario"
            raise ScenarioError(source, "fmus", f"the 3T mechanism's model refuses the slider reference of "
                                f"this run: {type(exc).__name__}: {exc}") from None
    return told


@_refused_by_3t
def _mechanism3t_masses(scenario, paths, descriptions, values, loop, motion):
    """The 3T mechanism's slider-space masses (eigenvalues of its mass matrix: the same PID
    on every slider decouples in its eigenvectors, as the hexapod's legs do) at POSES
    points of the slider controller's sine reference over the run."""
    get = lambda inst, name: _value(values, descriptions, inst, name)
    centre, amplitude, omega = (np.asarray(get(loop.controller, n), dtype=float) for n in loop.entry["motion"])
    params, mode = mechanism3t.Mechanism3TParams.paper(), int(get(loop.plant, "mode"))
    times = np.linspace(scenario.start_time, scenario.stop_time, POSES)
    return np.concatenate([np.linalg.eigvalsh(mechanism3t.mass_matrix(
        params, mechanism3t.paper_motion(t, centre, float(amplitude), float(omega))[0], mode)) for t in times])


@_refused_by_3t
def _mechanism3t_gravity(values, descriptions, controller, plant, entry):
    """The 3T sliders' largest destabilising gravity rate [1/s^2] (design.LoopModel) at the
    centre of the controller's reference, held at rest by the static forces: from central
    differences of the accelerations per slider displacement (~54, a pole at 7.4 rad/s)."""
    params, mode = mechanism3t.Mechanism3TParams.paper(), int(_value(values, descriptions, plant, "mode"))
    centre = np.asarray(_value(values, descriptions, controller, entry["motion"][0]), dtype=float)
    rest = np.zeros(3)
    hold = mechanism3t.slider_forces(params, centre, rest, rest, mode)
    step = 1e-6
    rates = np.array([(mechanism3t.forward_dynamics(params, centre + step * e, rest, hold, mode)
                       - mechanism3t.forward_dynamics(params, centre - step * e, rest, hold, mode)) / (2 * step)
                      for e in np.eye(3)]).T
    return max(0.0, float(np.linalg.eigvals(rates).real.max()))


# plant FMU -> its loop's modal masses [kg] along the scene, and its gravity rate (the physics
# the catalogue cannot carry); a plant not in MODAL_MASSES is watched but not predicted
MODAL_MASSES = {"hexapod_plant": _hexapod_masses, "mechanism3t_plant": _mechanism3t_masses}
GRAVITY = {"mechanism3t_plant": _mechanism3t_gravity}


def _merge(masses, rtol=1e-3):
    """The masses with those within ``rtol`` of a kept one left out: the limit moves
    smoothly with the mass, so near-equal modes need no evaluation of their own. (mass,
    observer's mass) pairs: a pair is left out when both are within ``rtol`` of the kept
    mode's mass of the kept pair's."""
    masses = np.asarray(masses, dtype=float)
    pairs = masses.reshape(len(masses), -1)
    kept = []
    for row in pairs[np.lexsort(pairs.T[::-1])]:
        if not kept or row[0] > kept[-1][0] * (1 + rtol) or np.abs(row[1:] - kept[-1][1:]).max(
                initial=0.0) > rtol * kept[-1][0]:
            kept.append(row)
    return np.array(kept).reshape(-1, *masses.shape[1:])


def _key(scenario, values, loop, telescope):
    """What decides a loop's limit (and its motion's flags): the time grid, master and
    extrapolation, the gains, the controller's motion parameters, every parameter of the
    plant, sensor and telescope, and the loop model they and the controller's observer (with
    its load cell) give: a field the loop model learns is in the key with it."""
    def of(inst):
        return repr(sorted(values.get(inst, {}).items())) if inst else ""
    own = {n: v for n, v in values.get(loop.controller, {}).items() if n.split("[", 1)[0] in loop.entry["motion"]}
    return repr((scenario.start_time, scenario.stop_time, scenario.step, scenario.master, scenario.extrapolation,
                 loop.controller, loop.gains, repr(sorted(own.items())), of(loop.plant), of(loop.sensor),
                 of(telescope), loop.model))


def predict(scenario, paths, descriptions, values, ci=False, cache=None):
    """The Prediction for a scenario at ``values`` (one run's: a sweep value applied): of
    its loop with the lowest limit (None if it has no loop to predict). ``cache`` (a dict
    kept over the runs of a sweep or campaign) predicts each distinct loop once, and within
    it the telescope's motion and the step limit once per distinct input of theirs: the runs
    of a sampled campaign differ in what the motion does not read (seeds, a payload's
    errors), and the limit reads the payload's masses only (the same payload: one search)."""
    cache = {} if cache is None else cache
    found = []
    for loop in loops(scenario, descriptions, values):
        masses_of = MODAL_MASSES.get(scenario.fmus[loop.plant])
        if masses_of is None:
            continue
        telescope = _telescope(scenario, loop)
        key = _key(scenario, values, loop, telescope)
        if key not in cache:
            motion, axis_rate = _motion(scenario, paths, values, telescope, cache) if telescope else (None, None)
            masses = _merge(masses_of(scenario, paths, descriptions, values, loop, motion))
            unfinished = tuple(_unfinished(scenario, telescope, axis_rate, _delay(values, descriptions, telescope),
                                           motion_end(scenario, values, descriptions, telescope))
                               ) if telescope else ()
            limit = _limit(masses, loop, cache)
            payload = _payload(values, descriptions, loop.plant)
            modelled = math.nan
            if payload:   # the limit the payload as modelled has: said where the payload moved it
                modelled = _limit(_merge(masses_of(scenario, paths, descriptions, _as_modelled(values, loop.plant),
                                                   loop, motion)), loop, cache)
            cache[key] = (Prediction(limit, scenario.step, loop.model, loop.gains, masses, unfinished,
                                     loop.controller, _coulomb(values, descriptions, loop), payload, modelled))
        found.append(cache[key])
    if not found:
        return None
    best = min(found, key=lambda p: p.limit)
    return replace(best, flags=() if ci else tuple(f for p in found for f in p.flags))


def _limit(masses, loop, cache):
    """design.step_limit of the masses in the loop, once per what it reads in ``cache``."""
    key = ("step limit", masses.tobytes(), masses.shape, repr(loop.gains), repr(loop.model))
    if key not in cache:
        cache[key] = design.step_limit(masses, loop.gains, loop.model)
    return cache[key]


def _coulomb(values, descriptions, loop):
    """(Coulomb friction [N], its smoothing velocity [m/s]) of the loop's plant, if it has
    them (the hexapod's screws), else (0, 1)."""
    names = {v.name for v in descriptions[loop.plant].modelVariables}
    if not {"coulomb_friction", "friction_velocity"} <= names:
        return (0.0, 1.0)
    return tuple(float(_value(values, descriptions, loop.plant, n)) for n in ("coulomb_friction", "friction_velocity"))


def _friction_hides(scenario, prediction):
    """Whether the plant's Coulomb friction holds the loop the linear model calls unstable:
    about rest it is a damper of slope coulomb / friction_velocity (tanh's), so the loop
    linearised there, that slope added to the viscous friction, is predicted stable at the
    scene's step and observer bandwidth. Then a run may stay clean while its oscillations
    stay below the friction velocity; without the friction (or above that speed) it grows."""
    force, velocity = prediction.coulomb
    if force <= 0:
        return False
    loop = replace(prediction.loop, viscous_friction=prediction.loop.viscous_friction + force / velocity)
    return design.modes_stable(prediction.masses, prediction.gains, scenario.step, loop)


def motion_flags(scenario, paths, descriptions, values, cache=None):
    """The flags of the scene's motion alone (a slew unfinished at the stop time): what
    ``predict`` flags per scenario, for each run of a campaign (``cache``: predict's)."""
    out = []
    for loop in loops(scenario, descriptions, values):
        telescope = _telescope(scenario, loop)
        if telescope:
            out += _unfinished(scenario, telescope, _motion(scenario, paths, values, telescope, cache)[1],
                               _delay(values, descriptions, telescope),
                               motion_end(scenario, values, descriptions, telescope))
    return out


def _motion(scenario, paths, values, telescope, cache=None):
    """auto_fidelity.scene_motion of the telescope with its axes' rates, once per what it
    reads (its FMU, its parameters, the run's start and stop time) in ``cache``."""
    cache = {} if cache is None else cache
    key = ("motion", str(paths[telescope]), scenario.start_time, scenario.stop_time,
           repr(sorted(values.get(telescope, {}).items())))
    if key not in cache:
        cache[key] = auto_fidelity.scene_motion(scenario, paths, values, telescope, axes=True)
    return cache[key]


def _telescope(scenario, loop):
    """The telescope instance feeding the loop controller's reference, or None."""
    if not loop.entry["reference"]:
        return None
    return next((s for s in _sources(scenario, f"{loop.controller}.{loop.entry['reference']}")
                 if scenario.fmus[s] == "telescope"), None)


def _delay(values, descriptions, telescope):
    """The telescope's start_delay [s]: its profile starts this late (absolute time)."""
    return float(_value(values, descriptions, telescope, "start_delay"))


def motion_end(scenario, values, descriptions, telescope):
    """When the telescope's commanded motion ends [s, absolute], from its analytic profile
    (plant/telescope/model.py): start_delay plus the slew's duration (the slower axis at
    its rate and acceleration limits) or the paper manoeuvre's; None for a profile that
    does not end (tracking). An axis servo (servo_bandwidth > 0) settles after it."""
    profile = scenario.parameters.get(telescope, {}).get("profile", "slew")
    get = lambda name: float(_value(values, descriptions, telescope, name))   # noqa: E731
    if profile == "paper":
        return get("start_delay") + get("paper_duration")
    if profile != "slew":
        return None
    params = replace(telescope_model.TelescopeParams.tianma(), **{
        k: get(k) for k in ("az_rate_max", "az_acc_max", "el_rate_max", "el_acc_max")})
    return get("start_delay") + telescope_model.slew_duration(
        params, (get("start_azimuth"), get("start_elevation")), (get("target_azimuth"), get("target_elevation")))


def _ends(profile, telescope, end, stop_time):
    """"; the slew of 'base' ends at t = 107.3 s: stop_time >= 108 s" ('' when the end is not
    known or not after the stop time: an axis servo's settling then keeps it turning)."""
    if end is None or end <= stop_time:
        return ""
    return f"; it ends at t = {end:.4g} s: stop_time >= {math.ceil(end - 1e-9):g} s"


def _unfinished(scenario, telescope, axis_rate, delay=0.0, end=None):
    """[motion_unfinished] if the slew (or paper manoeuvre) never starts (its ``delay`` at
    or after the stop time: the run holds the start pointing throughout) or still turns
    the antenna's axes at the stop time (``axis_rate`` along the run: the slew itself, not
    the sway of a flexible support, which never stops in wind), else []. ``end``: when
    the profile ends (motion_end), said with the stop time that would finish it."""
    profile = scenario.parameters.get(telescope, {}).get("profile", "slew")
    if profile not in ("slew", "paper"):
        return []
    if delay >= scenario.stop_time:
        return [Flag("motion_unfinished", f"the {profile} of {telescope!r} never starts: its start_delay "
                                          f"{delay:g} s is at or after the stop time {scenario.stop_time:g} s, "
                                          "so the base holds its start pointing for the whole run")]
    turning = float(np.linalg.norm(axis_rate[-1]))
    if turning > MOVING:
        return [Flag("motion_unfinished", f"the {profile} of {telescope!r} has not ended at the stop time "
                                          f"{scenario.stop_time:g} s: the antenna still turns at "
                                          f"{math.degrees(turning):.3g} deg/s"
                                          + _ends(profile, telescope, end, scenario.stop_time))]
    return []


def _describe(loop, extrapolation=None):
    """The loop's master and extrapolation; ``extrapolation`` "derivatives" is named as
    the scenario says, with what the loop gets (linear)."""
    master = "gauss-seidel" if loop.gauss_seidel else "jacobi"
    if extrapolation == "derivatives":
        return f"master {master}, extrapolation derivatives (linear on the leg loop, whose signals have none)"
    return f"master {master}, extrapolation {'linear' if loop.extrapolate else 'none'}"


def _ms(seconds, down=False):
    """``seconds`` in ms to 4 significant digits; ``down``: rounded down, so that a step
    written as shown is within the limit (a limit of 2.00093 ms reads 2 ms, not 2.001)."""
    if seconds == 0:
        return "no step (the gains are unstable)"
    ms = seconds * 1e3
    if down and math.isfinite(ms):
        unit = 10.0 ** (math.floor(math.log10(ms)) - 3)
        ms = math.floor(ms / unit * (1 + 1e-12)) * unit
    return f"{ms:.4g} ms"


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
                    others.append(f"{_describe(loop)} (a step of at most {_ms(other, down=True)})")
    plant = "its gains and plant"
    if prediction.payload and prediction.modelled_limit != prediction.limit:   # the payload moved it: say so
        plant += (f" with {prediction.payload} (as modelled it would be {_ms(prediction.modelled_limit)}: the "
                  "payload shifts the leg-space modes and the observer's mass for them)")
    if prediction.limit > 0:
        text = (f"{scenario.step * 1e3:g} ms is beyond the predicted stability limit {_ms(prediction.limit)} of "
                f"this loop ({_describe(prediction.loop, scenario.extrapolation)}, {plant}, along the "
                f"motion): the loop of {prediction.controller!r} would oscillate and grow")
        hint = f"use a step of at most {_ms(prediction.limit, down=True)}"
    else:
        text = (f"no step is stable with these gains ({_describe(prediction.loop, scenario.extrapolation)}, "
                f"{plant}, along the motion): the loop of {prediction.controller!r} would drift or grow at "
                f"{scenario.step * 1e3:g} ms as at any step")
        hint = "choose gains that stabilise the loop (controller.design)"
    if prediction.loop.observer_bandwidth > 0:
        observer = design.observer_limit(prediction.masses, prediction.gains, scenario.step, prediction.loop)
        text += (f"; its disturbance observer at {prediction.loop.observer_bandwidth:g} Hz is beyond its predicted "
                 f"limit {observer:.3g} Hz at this step" if observer < prediction.loop.observer_bandwidth else
                 f"; with its disturbance observer at {prediction.loop.observer_bandwidth:g} Hz")
        hint += f" or an observer_bandwidth below {observer:.3g} Hz" if observer > 0 else ""
    if _friction_hides(scenario, prediction):
        force, velocity = prediction.coulomb
        text += (f". The linear loop is unstable, and the plant's {force:g} N Coulomb friction hides it: about rest "
                 f"it damps like {force / velocity:.3g} N s/m (below {velocity * 1e3:g} mm/s), with which the loop "
                 "is predicted stable, so this run may stay clean; with the friction at 0, or once a disturbance "
                 "moves the legs faster, it grows")
    if not allow_unstable:
        if others:
            hint += " or " + " or ".join(others)
        raise ScenarioError(scenario.source, "step", f"{text}. {hint[0].upper() + hint[1:]}; or run it anyway "
                                                     "with --allow-unstable (allow_unstable=True): it is then flagged")
    return flags + [Flag("step_beyond_limit", text + " (run anyway: allow_unstable=True, --allow-unstable on the "
                                                       "command line)")]


# ------------------------------------------------------------------ during the run
@dataclass(frozen=True)
class Watched:
    """What Watch watches of one loop: its ``controller`` instance, the force command
    ``forces`` ("inst.var") and its limits ((what, N): the controller's and the plant's),
    the measured plant output ``lengths`` and, where the plant has one, each element's
    ``stroke`` (its ends: two arrays [m]); the reference it tracks, ``excitation``
    (growth driven by the reference's own changes is no instability)."""

    controller: str
    forces: str
    lengths: str
    limits: tuple = ()
    stroke: tuple | None = None
    excitation: str | None = None


class Watch:
    """Detectors fed every recorded row (``feed``, in the recorder's blocks; rows buffered
    and evaluated BLOCK at a time, as the metrics do), per ``window`` of time, for every
    ``watched`` loop: the envelope of the forces' and measured outputs' second difference
    (an oscillation; a smooth motion keeps it small), rows with a force at each of its
    limits, the outputs' extent into their stroke; and non-finite values. Memory: a few
    numbers per window."""

    BLOCK = 256

    def __init__(self, watched=(), window=WINDOW):
        self.watched, self.window = tuple(watched), window
        self.needs = list(dict.fromkeys(r for w in self.watched for r in (w.forces, w.lengths, w.excitation) if r))
        self.t0 = None
        self.env = {ref: np.zeros(0) for ref in self.needs}   # per window: largest |second difference|
        # per window: rows with the force at each limit
        self.held = {(w.forces, what): np.zeros(0) for w in self.watched for what, _ in w.limits}
        self.since = dict.fromkeys(self.held)         # time the force reached the limit, while it stays there
        self.longest = dict.fromkeys(self.held, 0.0)  # longest stay at the limit [s], first row to last
        self.extent = {w.lengths: 0.0 for w in self.watched if w.stroke}   # largest |output - middle| / half stroke
        self.tail = {}                # the last two rows of each reference before this block
        self.non_finite = None        # time of the first non-finite row
        self.rows = 0
        self._block = None

    @classmethod
    def for_scenario(cls, scenario, descriptions, values):
        """A Watch on every loop of the scenario (catalogue.CONTROL_LOOPS), or on non-finite values only."""
        watched, periods = [], []
        for loop in loops(scenario, descriptions, values):
            stroke = STROKES.get(scenario.fmus[loop.plant])
            watched.append(Watched(loop.controller, f"{loop.controller}.{loop.entry['force']}",
                                   f"{loop.plant}.{loop.entry['plant_measured']}", loop.limits(values, descriptions),
                                   stroke and stroke(values, descriptions, loop),
                                   f"{loop.controller}.{loop.entry['excitation']}"))
            masses_of = MODAL_MASSES.get(scenario.fmus[loop.plant])
            if masses_of:   # the modes at rest (no motion): the window needs the period's order only
                masses = _merge(masses_of(scenario, None, descriptions, values, loop, None))
                periods.append(_unstable_period(masses.tobytes(), loop.gains, loop.model, scenario.step))
        # CYCLES periods of the oscillation with which the loop goes unstable (its least-damped
        # pole at its step limit), but at least 20 recorded rows (an envelope needs rows) and at
        # most WINDOW; not a share of the run
        window = min(WINDOW, max(20 * scenario.read_interval, CYCLES * min(periods, default=math.inf)))
        return cls(watched, window)

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
        grow = lambda a: np.r_[a, np.zeros(max(0, size - len(a)))]
        for ref in self.needs:
            self.env[ref] = grow(self.env[ref])
            x = rows[:, self.slices[ref]]
            full = np.vstack([self.tail.get(ref, x[:0]), x])
            self.tail[ref] = full[-2:]
            if len(full) > 2:
                second = np.abs(full[2:] - 2 * full[1:-1] + full[:-2]).max(axis=1)
                with np.errstate(invalid="ignore"):
                    np.fmax.at(self.env[ref], window[-len(second):], second)
        for w in self.watched:
            force = np.abs(rows[:, self.slices[w.forces]]).max(axis=1)
            for what, limit in w.limits:
                key, at = (w.forces, what), force >= limit * (1 - 1e-9)
                self.held[key] = grow(self.held[key])
                np.add.at(self.held[key], window, at)
                edges = np.flatnonzero(np.diff(np.r_[0, at.astype(np.int8), 0]))   # each stay: first row, row after
                for begin, end in zip(edges[::2], edges[1::2]):
                    since = self.since[key] if begin == 0 and self.since[key] is not None else float(t[begin])
                    self.longest[key] = max(self.longest[key], float(t[end - 1]) - since)
                    self.since[key] = since if end == n else None
                if not at[-1]:
                    self.since[key] = None
            if w.stroke:
                low, high = w.stroke
                reach = (np.abs(rows[:, self.slices[w.lengths]] - (low + high) / 2) / ((high - low) / 2)).max()
                self.extent[w.lengths] = max(self.extent[w.lengths], float(np.nan_to_num(reach)))

    def flags(self, warnings=()):
        """The flags of what was fed, and ``warnings`` ((instance, FMU log line)) as flags
        too; a watched controller's saturation warnings join the saturated flag, and are
        no flag of their own: a touch of a limit shorter than SATURATED of the time is none."""
        self._flush()
        out = []
        if self.non_finite is not None:
            out.append(Flag("non_finite", f"non-finite values recorded from t = {self.non_finite:g} s"))
        signals = [(w.forces, "force oscillation", "kN", 1e-3, FLOORS[0], w.excitation) for w in self.watched] + \
            [(w.lengths, "oscillation", "µm", 1e6, FLOORS[1], w.excitation) for w in self.watched]
        for ref, what, unit, scale, floor, excitation in signals:
            grown = growth(self.t0 + self.window * np.arange(len(self.env[ref])), self.env[ref], floor,
                           self.env.get(excitation))
            if grown:
                t0, t1, e0, e1 = grown
                out.append(Flag("unstable", f"the {what} of {ref!r} (second difference of the recorded values) grows "
                                            f"from {e0 * scale:.3g} {unit} to {e1 * scale:.3g} {unit} between t = "
                                            f"{t0:g} s and {t1:g} s"))
                break
        saturated = False
        for w in self.watched:
            for what, limit in w.limits:
                held, longest = self.held[w.forces, what], self.longest[w.forces, what]
                share = held.sum() / max(1, self.rows)
                if share >= SATURATED or longest >= self.window:
                    saturated = True
                    first = self.t0 + self.window * np.flatnonzero(held)[0]
                    out.append(Flag("saturated", f"{w.forces!r} at the +-{limit * 1e-3:g} kN limit ({what}) "
                                                 f"{100 * share:.3g} % of the recorded time (from t ~ {first:g} s; "
                                                 f"at most {longest:.3g} s on end)"))
            if w.stroke and self.extent[w.lengths] >= NEAR_STROKE:
                half = (w.stroke[1] - w.stroke[0]) / 2
                span = f"+-{half[0] * 1e3:g} mm" if np.ptp(half) == 0 else "half"
                out.append(Flag("stroke", f"{w.lengths!r} reaches {100 * self.extent[w.lengths]:.3g} % of its "
                                          f"{span} stroke"))
        controllers = {w.controller for w in self.watched}
        told = [(inst, line) for inst, line in warnings
                if saturated or inst not in controllers or "saturated" not in line]
        return merged(out + warning_flags(told))


@functools.lru_cache(maxsize=64)
def _unstable_period(masses, gains, model, step):
    """The period [s] of the least-damped pole of the modes ``masses`` (their float64
    bytes) at their step limit (at ``step`` if none): the oscillation with which the loop
    goes unstable. Kept per process: a sweep's runs share their loops at rest, and the
    limit's search (~4 ms) is the most of a Watch's set-up."""
    masses = np.frombuffer(masses)
    limit = design.step_limit(masses, gains, model)
    return design.least_damped_period(masses, gains, limit if 0 < limit < math.inf else step, model)


def _hexapod_stroke(values, descriptions, loop):
    """The legs' ends: home length -+ the plant's half stroke."""
    half = float(_value(values, descriptions, loop.plant, loop.entry["stroke"]))
    home = plant_params(values, descriptions, loop.plant).home_lengths
    return home - half, home + half


# plant FMU -> the ends of its measured output's stroke (the 3T sliders: the actuator ranges)
STROKES = {"hexapod_plant": _hexapod_stroke,
           "mechanism3t_plant": lambda values, descriptions, loop: (
               np.array(mechanism3t.Mechanism3TParams.paper().rho_min),
               np.array(mechanism3t.Mechanism3TParams.paper().rho_max))}


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


def growth(times, envelope, floor, excitation=None):
    """(t0, t1, e0, e1) if the envelope (floored at ``floor``) grows GROWTH-fold with a
    steady exponential trend (least squares on its log, R^2 >= 0.8) over GROWTH_WINDOWS
    or more windows that end at the last window or at the envelope's peak (where a growth
    stops at the force limit, and the envelope stays near it after), else None. Steady: a
    slew's transients raise the envelope for a window or two, an unstable loop every window.
    Against the reference's own ``excitation`` (its envelope per window, floored at
    EXCITED of its largest): the envelope is judged per unit of the largest excitation so
    far (a stable loop answers what it was excited with, and its transients decay; an
    unstable loop grows by itself), so a loop answering a reference that starts to move
    does not grow."""
    raw = np.maximum(np.asarray(envelope[1:-1], dtype=float), floor)   # first and last window: partial
    t = np.asarray(times[1:-1], dtype=float)
    drive = np.ones(len(raw))
    if excitation is not None and len(raw) and np.nanmax(excitation) > 0:
        excited = np.nan_to_num(np.asarray(excitation, dtype=float)[1:-1])
        drive = np.maximum.accumulate(np.maximum(excited, EXCITED * np.nanmax(excitation)))
    env = raw / drive
    peaks = (int(np.argmax(env)) + 1, int(np.argmax(raw)) + 1) if len(env) else ()
    for end in dict.fromkeys((len(env), *peaks)):   # to the end, to the peak (per unit of excitation, or not)
        if end < GROWTH_WINDOWS:
            continue
        if end < len(env) and median(env[end:]) < env[end - 1] / PERSIST:
            continue   # it died away after its peak: a transient (a slew's acceleration step), not a growth
        for n in sorted(set(np.geomspace(end, GROWTH_WINDOWS, 16).round().astype(int).tolist()), reverse=True):
            x, y = t[end - n:end], np.log(env[end - n:end])
            dx = x - x.mean()
            slope = np.dot(dx, y - y.mean()) / np.dot(dx, dx)   # the least-squares line (np.polyfit's, 5x cheaper)
            fit = slope * dx + y.mean()
            total = np.sum((y - y.mean()) ** 2)
            r2 = 1 - np.sum((y - fit) ** 2) / total if total > 0 else 0.0
            grown = math.exp(slope * (x[-1] - x[0]))
            if slope > 0 and grown >= GROWTH and r2 >= 0.8 and raw[end - 1] >= GROWTH * floor:
                return float(x[0]), float(x[-1]), float(raw[end - n]), float(raw[end - 1])
    return None


def median(values):
    """np.median of a 1-d array (NaN if a value is NaN), without the check of np.median
    that imports numpy.ma (8 ms of a run's process, for the one median a run takes)."""
    ordered = np.sort(np.asarray(values, dtype=float))   # NaN sorts last
    n = len(ordered)
    if n == 0 or np.isnan(ordered[-1]):
        return math.nan
    return float(ordered[n // 2]) if n % 2 else float((ordered[n // 2 - 1] + ordered[n // 2]) / 2)


def sampling_flags(metrics, interval, key="record.interval"):
    """``undersampled`` for each metric its recorded rows cannot carry (metrics.undersampled):
    the metrics are computed from the recorded rows, so a coarse record interval gives a
    number with no word (a 2-row run's RMS 1e-4 of the true one)."""
    said = [(m.name, m.undersampled()) for m in metrics]
    return [Flag("undersampled", f"metric {name!r} {problem}: {key} {interval * 1e3:g} ms is too coarse "
                 "for it; record more often") for name, problem in said if problem]


def run_flags(watch, run, instances, before=()):
    """The flags of a finished (or stopped) run: those known before it, the detectors',
    the FMUs' warnings, and a cut-short run."""
    warnings = [(name, line) for name, inst in instances.items() for line in inst.log if line.startswith("[WARNING]")]
    out = list(before) + (watch.flags(warnings) if watch else [])
    if run.failure:
        out.append(Flag("cut_short", f"stopped at t = {run.sim_time:g} s of the run: {run.failure}"))
        if "StrokeError" in run.failure:   # the rows near the end, the plant's step beyond it: one story
            out = [Flag(f.kind, f"{f.message} in its recorded rows, and left it between them (cut_short)")
                   if f.kind == "stroke" else f for f in out]
    return out
