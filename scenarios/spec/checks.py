"""The checks of a bound scenario that no single value shows: the wiring (every input fed
once, no algebraic loop, every control loop closed through what it measures), the
metrics' variables, and what the models refuse that min/max cannot say (the telescope
profile over the run, a payload no rigid body can have, the 3T mechanism's assembly along
its reference)."""
import dataclasses
from datetime import datetime, timezone

import numpy as np

from fmu_src import replay_table
from fmu_src.catalogue import ALL, CONTROL_LOOPS, FEEDTHROUGH, LOOP_SENSORS
from plant.errors import InvalidInputError
from plant.hexapod.model import StewartParams, body_problems
from plant.mechanism3t import model as mechanism3t
from plant.telescope import model as telescope
from scenarios.spec.keys import (
    CHECK_POINTS,
    METRIC_RESULT_UNITS,
    METRIC_UNITS,
    Link,
    enumeration,
    expand,
    metric_variables,
)
from scenarios.spec.text import Problems, ScenarioError


def check_links(src, values):
    """Parameter links ("@inst.var") are read at the start from an FMU already initialised:
    links that form a cycle have no such order, and are refused naming the cycle."""
    needs = {inst: sorted({v.instance for v in params.values() if isinstance(v, Link)})
             for inst, params in values.items()}
    state = {}

    def visit(inst, path):
        if state.get(inst) == "done":
            return
        if state.get(inst) == "open":
            cycle = path[path.index(inst):] + [inst]
            raise ScenarioError(src, f"fmus.{inst}.parameters", "parameter links form a cycle: "
                                f"{' <- '.join(cycle)} (each takes a start value from the next); break it")
        state[inst] = "open"
        for other in needs.get(inst, ()):
            visit(other, path + [inst])
        state[inst] = "done"

    for inst in needs:
        visit(inst, [])


def check_rates(src, key, scenario, variables, values):
    """A cut-off frequency (a parameter named *cutoff in 1/s) above the Nyquist frequency
    of the communication step, 1/(2 step), is no filter the FMU can run: refused."""
    nyquist = 0.5 / scenario.step
    problems = Problems()
    for inst, params in values.items():
        for name, value in params.items():
            var = variables[inst].get(name)
            if var is not None and name.endswith("cutoff") and var.unit == "1/s" and \
                    isinstance(value, float) and value > nyquist:
                where = f"fmus.{inst}.parameters.{name}" if key == "fmus" else key
                problems.errors.append(ScenarioError(src, where, f"{value:g} Hz is above the Nyquist frequency of "
                                                     f"the step ({scenario.step:g} s: {nyquist:g} Hz); lower it or "
                                                     "the step"))
    problems.raise_any()


def feed_once(src, key, index, written, source, target, feeders, fed):
    """Record that connection ``index`` feeds ``target``; refuse a second feed of the same
    input (another source, the same connection twice, or a parameter value as well):
    the master would silently keep the last one."""
    if target in feeders:
        other, other_written, other_source = feeders[target]
        what = "duplicate connection" if other_source == source else "two sources connected into one input"
        raise ScenarioError(src, key, f"{what}: connections[{other}] ({other_written}) and connections[{index}] "
                            f"({written}) both feed {target[0]}.{target[1]}; keep one")
    if target in fed:
        raise ScenarioError(src, key, f"{written} feeds {target[0]}.{target[1]}, which fmus.{target[0]}.parameters "
                            "also sets; an input takes one source")
    feeders[target] = (index, written, source)
    fed.add(target)


def _base(reference):
    """("inst", "var") of "inst.var" or "inst.var[k]"."""
    inst, name = reference.split(".", 1)
    return inst, name.split("[", 1)[0]


def check_wiring(src, scenario, variables, feeders):
    """Wiring that cannot be meant, refused naming its connections: a cycle of connections
    through outputs that follow their inputs within a step (FEEDTHROUGH; one connection:
    an output wired back into its own FMU), and a control loop (CONTROL_LOOPS) whose
    controller does not measure its plant's output, directly or through its sensors
    (LOOP_SENSORS). Either ran until a stroke error that named neither."""
    feeds = {}      # (inst, input) -> [(source (inst, output), "from -> to")]
    for source, targets in scenario.connections:
        for target in targets:
            feeds.setdefault(_base(target), []).append((_base(source), f"{source} -> {target}"))
    inputs = {inst: {n.split("[", 1)[0] for n, v in variables[inst].items() if v.causality == "input"}
              for inst in scenario.fmus}

    def follows(inst, output):
        given = FEEDTHROUGH.get(scenario.fmus[inst], {}).get(output, ())
        return sorted(inputs[inst]) if given == ALL else given

    for (inst, name), fed in feeds.items():
        if not any(name in follows(inst, out) for out in FEEDTHROUGH.get(scenario.fmus.get(inst), {})):
            continue     # no output follows this input: no loop closes through it
        for source, written in fed:
            found = _loop_through(scenario, feeds, follows, source, (inst, name), written)
            if found and len(found) == 1:
                raise ScenarioError(src, "connections", f"{found[0]} wires an output back into its own FMU's "
                                    f"input, and {scenario.fmus[inst]}'s {source[1]} follows its {name} "
                                    "within a step (no state between): it would measure itself, not the "
                                    "plant; connect the input to what it measures")
            if found:
                raise ScenarioError(src, "connections", f"{'; '.join(found)}: an algebraic loop (each output "
                                    "follows its input within a step, no state between) that the master "
                                    "cannot solve; break it with a connection from a plant's output")
    _check_loops_closed(src, scenario, feeds, feeders, variables)


def _loop_through(scenario, feeds, follows, source, start, written):
    """The connections of a feedthrough cycle that ``written`` (``source`` -> ``start``)
    closes, or None: from ``start``'s outputs that follow it, along connections and
    feedthrough, back to ``source``."""
    stack, seen = [(start, [written])], {start}
    while stack:
        (inst, name), path = stack.pop()
        for out in FEEDTHROUGH.get(scenario.fmus[inst], {}):
            if name not in follows(inst, out):
                continue
            if (inst, out) == source:
                return path
            for target, fed in feeds.items():
                for node, w in fed:
                    if node == (inst, out) and target not in seen and target[0] in scenario.fmus:
                        seen.add(target)
                        stack.append((target, [*path, w]))
    return None


def _check_loops_closed(src, scenario, feeds, feeders, variables):
    """Each controller of CONTROL_LOOPS whose force feeds its plant measures that plant's
    output in every element of its measured input, directly or through sensors of
    LOOP_SENSORS (element k of a sensor's output follows element k of its input)."""
    for controller, fmu in scenario.fmus.items():
        entry = CONTROL_LOOPS.get(fmu)
        if entry is None:
            continue
        plants = [t_inst for (t_inst, t_name), fed in feeds.items() if scenario.fmus.get(t_inst) == entry["plant"]
                  and t_name == entry["plant_force"] and any(n == (controller, entry["force"]) for n, _ in fed)]
        if not plants:
            continue
        wanted = {(p, entry["plant_measured"]) for p in plants}
        elements = expand(variables[controller], f"{controller}.{entry['measured']}")
        bad = {n: chain for n in elements if (chain := _measured_chain(scenario, feeders, (controller, n), wanted))
               is not None}
        if not bad:
            continue
        chain = next(iter(bad.values()))
        used = {source for _, _, source in feeders.values()}
        idle = []       # the plant's measured outputs that feed nothing: the whole vector, or its elements
        for p in plants:
            names = expand(variables[p], f"{p}.{entry['plant_measured']}")
            left = [f"{p}.{n}" for n in names if (p, n) not in used]
            idle += [f"{p}.{entry['plant_measured']}"] if left and len(left) == len(names) else left
        fed_by = f"is fed by {', then '.join(reversed(chain)) or 'no connection'}"
        source = f"{plants[0]}.{entry['plant_measured']} (directly or through a sensor)"
        if len(bad) == len(elements):
            told = f"{controller}.{entry['measured']} {fed_by}, not by {source}"
        else:
            told = (f"{', '.join(f'{controller}.{n}' for n in bad)} {'is' if len(bad) == 1 else 'are'} not fed by "
                    f"{source}: {controller}.{next(iter(bad))} {fed_by}")
        raise ScenarioError(src, "connections", f"the loop of {controller!r} (its {entry['force']} drives "
                            f"{plants[0]}.{entry['plant_force']}) does not measure its plant: {told}"
                            + (f"; {', '.join(idle)} {'is' if len(idle) == 1 else 'are'} connected to nothing"
                               if idle else ""))


def _measured_chain(scenario, feeders, node, wanted):
    """None if input element ``node`` is fed by an output of ``wanted`` (directly or
    through sensors of LOOP_SENSORS); else what feeds it: the connections as written, and
    the parameter that sets the input the chain ends at, if one does."""
    chain = []
    for _ in scenario.fmus:
        if node not in feeders:
            base = _base(f"{node[0]}.{node[1]}")[1]
            chain += [f"fmus.{node[0]}.parameters.{name}" for name in (base, node[1])
                      if name in scenario.parameters.get(node[0], {})]
            break
        _, written, (inst, name) = feeders[node]
        chain.append(written)
        base = _base(f"{inst}.{name}")[1]
        if (inst, base) in wanted:
            return None
        sensor = LOOP_SENSORS.get(scenario.fmus.get(inst))
        if not sensor or base != sensor[1]:
            break
        node = (inst, sensor[0] + name[len(base):])
    return chain


def check_metric(src, key, metric, scalars):
    """The variables a metric reads exist, reported under the metric's own keys, with the
    sizes and units its kind needs (a leg_tracking metric fed leg forces as its reference
    pose printed 2.6e10 µm as a result)."""
    if metric.kind == "base_effect":
        references = metric_variables(metric)
        for arg, reads in (("base", references[:3]), ("reference", references[3:])):
            for reference in reads:
                scalars(f"{key}.{arg}", reference)
        return
    sizes = {}
    for arg, reference in metric.args.items():
        _, read = scalars(f"{key}.{arg}", reference)
        fixed = [v for v in read if v.causality in ("parameter", "calculatedParameter") or
                 v.variability in ("constant", "fixed")]
        if fixed:      # its value never changes during the run: the metric would measure the setting
            raise ScenarioError(src, f"{key}.{arg}", f"{reference} is a {fixed[0].causality} (fixed for the run); "
                                "a metric measures what the run changes: an output or an input")
        sizes[arg] = len(read)
    needed = {"leg_tracking": {"measured": 6, "reference_pose": 6},
              "pose_tracking": {"measured": 6, "reference": 6},
              "pointing": {"measured": 6, "reference": 6}}.get(metric.kind, {})
    for arg, size in needed.items():
        if sizes[arg] != size:
            raise ScenarioError(src, f"{key}.{arg}", f"{metric.args[arg]} has {sizes[arg]} values; "
                                f"a {metric.kind} metric needs {size}")
    if metric.kind == "tracking" and sizes["measured"] != sizes["reference"]:
        raise ScenarioError(src, key, f"measured {metric.args['measured']} has {sizes['measured']} values, "
                            f"reference {metric.args['reference']} {sizes['reference']}")
    for arg, want in METRIC_UNITS.get(metric.kind, {}).items():
        units = tuple(v.unit or "1" for v in scalars(f"{key}.{arg}", metric.args[arg])[1])
        want = (want,) * len(units) if isinstance(want, str) else want
        if units != want:
            raise ScenarioError(src, f"{key}.{arg}", f"{metric.args[arg]} is in {_units_text(units)}; a "
                                f"{metric.kind} metric's {arg} must be in {_units_text(want)} (its result is in "
                                f"{METRIC_RESULT_UNITS[metric.kind]})")


def _units_text(units):
    """('m', 'm') as 'm'; ('m', 'rad') as 'm, rad'."""
    return units[0] if len(set(units)) == 1 else ", ".join(units)


# -------------------------------------------------- ranges that min/max cannot declare
def check_models(src, key, scenario, variables, values, written=None):
    """Checks that need several parameters at once, as the models themselves make them
    (the telescope's profile over the run; the hexapod's payload a rigid body; the 3T
    mechanism's assembly modes, initial positions and the slider reference over the run), so
    the FMU does not refuse them at t = 0 nor the model mid-run. ``written`` maps (instance,
    name) to the value as the file wrote it. Every instance is checked; their problems are
    told together."""
    problems = Problems()
    for inst, fmu in scenario.fmus.items():
        if fmu == "telescope":
            with problems.part():
                _check_telescope(src, key, scenario, inst, variables[inst], values[inst], written or {})
        elif fmu == "hexapod_plant":
            with problems.part():
                found = payload_problems(variables[inst], values[inst])
                if found:
                    where = f"fmus.{inst}.parameters" if key == "fmus" else key
                    raise ScenarioError(src, where, "; ".join(found))
    if any(fmu in MECHANISM3T for fmu in scenario.fmus.values()):
        _check_mechanism3t(src, key, scenario, variables, values, written or {}, problems)
    problems.raise_any()


def payload_problems(md_variables, values):
    """What no rigid body can have in the hexapod plant's payload as ``values`` set it (the
    paper's platform plus payload_mass_error, payload_inertia_error[1..3]; unset: the FMU's
    start), each naming the parameters: plant.hexapod.model.body_problems. Empty: admissible."""
    def setting(name):
        value = values.get(name, md_variables[name].start if name in md_variables else 0.0)
        return None if isinstance(value, Link) else float(value)

    inertia_names = [f"payload_inertia_error[{k}]" for k in (1, 2, 3)]
    mass_error, inertia_error = setting("payload_mass_error"), [setting(n) for n in inertia_names]
    if mass_error is None or None in inertia_error:
        return []   # values known only at the start time
    paper = StewartParams.paper()
    found = body_problems(paper.platform_mass + mass_error, paper.platform_inertia + np.array(inertia_error))
    if not found:
        return []
    return [f"payload_mass_error = {mass_error:.6g} kg, payload_inertia_error = "
            f"[{', '.join(f'{v:.6g}' for v in inertia_error)}] kg.m2 on the paper's platform "
            f"({paper.platform_mass:.6g} kg, [{', '.join(f'{v:.6g}' for v in paper.platform_inertia)}] kg.m2) "
            "give a payload no rigid body has: " + "; ".join(found)]


def _setting(md_variables, values, name):
    """A parameter's value as bound, else its start (the FMU's default); a vector as an array."""
    names = expand(md_variables, f"x.{name}")
    got = [values[n] if n in values else md_variables[n].start for n in names]
    if md_variables[names[0]].type in ("Integer", "Enumeration"):
        return int(got[0])
    return np.array(got, dtype=float) if len(names) > 1 or names[0] != name else float(got[0])


def _shown(scenario, inst, name, value, unit, written):
    """'inst.name = <as written>' (or the value in SI, '(default)' if nothing set it)."""
    raw = written.get((inst, name), scenario.parameters.get(inst, {}).get(name))
    if raw is not None:
        return f"{inst}.{name} = {raw!r}"
    value = np.round(np.atleast_1d(value) * 1e3, 6).tolist() if unit == "m" else [value]
    return f"{inst}.{name} = {value if len(value) > 1 else value[0]}{' mm' if unit == 'm' else unit} (default)"


MECHANISM3T = ("mechanism3t_plant", "slider_controller")
PLANTS3T = ("mechanism3t_plant",)


def _check_mechanism3t(src, key, scenario, variables, values, written, problems):
    """The 3T mechanism's settings as its model takes them (plant.mechanism3t.model): each
    assembly mode +1 or -1; the plant's initial_position assembled in its mode; and the slider
    controller's reference initial_position + amplitude sin(omega t) over the run assembled in
    its own mode (the feedforward model's) and in each plant's (the plant tracks it). Each
    problem names the key and the range that does assemble."""
    read = ("mode", "initial_position", "amplitude", "omega")
    if key != "fmus" and not any(scenario.fmus[i] in MECHANISM3T and n.split("[")[0] in read for i, n in written):
        return                      # a sweep value the mechanism does not read: checked once, with "fmus"

    def where(inst, name):
        return f"fmus.{inst}.parameters.{name}" if key == "fmus" else key

    P, modes, given = mechanism3t.Mechanism3TParams.paper(), {}, {}
    for inst, fmu in scenario.fmus.items():
        if fmu not in MECHANISM3T or any(isinstance(v, Link) for v in values[inst].values()):
            continue                # values known only at the start time
        given[inst] = {n: _setting(variables[inst], values[inst], n) for n in read[:2 if fmu in PLANTS3T else 4]}
        mode = given[inst]["mode"]
        with problems.part():
            if mode not in (1, -1):
                raise ScenarioError(src, where(inst, "mode"), f"{_shown(scenario, inst, 'mode', mode, '', written)}: "
                                    "the assembly mode is +1 or -1 (the sign before the square root of eq. 11)")
            modes[inst] = mode
    plants = [i for i in modes if scenario.fmus[i] in PLANTS3T]
    for inst in modes:
        centre = given[inst]["initial_position"]
        shown = lambda n, v, u="", inst=inst: _shown(scenario, inst, n, v, u, written)
        owners = {modes[inst]: f"{inst}.mode"}
        if scenario.fmus[inst] not in PLANTS3T:      # the plant tracks the controller's reference
            owners.update({modes[p]: f"{p}.mode" for p in plants if modes[p] not in owners})
        for mode, owner in owners.items():
            with problems.part():
                ok, reason = mechanism3t.assembled(P, centre, mode)
                if ok:
                    continue
                xs = np.arange(P.rho_min[0], P.rho_max[0], 1e-4)
                found = [xs[mechanism3t.assembled(P, np.c_[xs, np.tile(centre[1:], (len(xs), 1))], m)[0]]
                         for m in (mode, -mode)]
                span = (f"at its y_A1, y_A3 mode {mode:+d} assembles x_A2 from {found[0].min() * 1e3:.6g} to "
                        f"{found[0].max() * 1e3:.6g} mm" if found[0].size else
                        f"at its y_A1, y_A3 no x_A2 of the slider's range assembles in mode {mode:+d}")
                other = mechanism3t.assembled(P, centre, -mode)[0]
                name = "mode" if other and owner == f"{inst}.mode" else "initial_position"
                at = shown('initial_position', centre, 'm')
                raise ScenarioError(src, where(inst, name), (
                    f"{owner} = {mode:+d}: the 3T mechanism does not assemble at {at}"
                    if name == "mode" else f"{shown('initial_position', centre, 'm')}: the 3T mechanism does not "
                    f"assemble there in assembly mode {mode:+d} ({owner})") + f" ({reason}); {span}; "
                    + (f"mode {-mode:+d} assembles it" if other else f"mode {-mode:+d} does not either"))
        if scenario.fmus[inst] in PLANTS3T or not mechanism3t.assembled(P, centre, modes[inst])[0]:
            continue
        amplitude, omega = given[inst]["amplitude"], given[inst]["omega"]
        low, high = _sine_range(omega * scenario.start_time, omega * scenario.stop_time)
        for mode, owner in owners.items():    # the reference sweeps the offsets [amplitude low, amplitude high]
            span = mechanism3t.reach(P, centre, mode)
            if span is None or span[0] <= amplitude * low and amplitude * high <= span[1]:
                continue            # the centre told above, or the reference assembles (to the reach's 0.1 mm)
            beyond = span[1] + 1e-4 if amplitude * high > span[1] else span[0] - 1e-4
            reason = mechanism3t.assembled(P, centre + beyond, mode)[1] or "beyond the reach's 1 m"
            largest = min(span[1] / high if high > 0 else np.inf, span[0] / low if low < 0 else np.inf)
            problems.errors.append(ScenarioError(
                src, where(inst, "amplitude"),
                f"{shown('amplitude', amplitude, 'm')}: the reference initial_position + amplitude sin(omega t) "
                f"(sin from {low:.4g} to {high:.4g} over {scenario.start_time:g}..{scenario.stop_time:g} s, "
                f"{shown('omega', omega, ' rad/s')}) leaves the 3T mechanism's workspace in assembly mode "
                f"{mode:+d} ({owner}; {reason}): along it the sliders assemble from {span[0] * 1e3:+.4g} to "
                f"{span[1] * 1e3:+.4g} mm "
                f"about initial_position, so this run's amplitude is at most {largest * 1e3:.4g} mm"))


def _sine_range(start, stop):
    """(min, max) of sin over the phases [start, stop]."""
    ends = np.sin([start, stop])
    low, high = float(ends.min()), float(ends.max())
    turns = lambda phase: np.floor((stop - phase) / (2 * np.pi)) >= np.ceil((start - phase) / (2 * np.pi))
    return (-1.0 if turns(-np.pi / 2) else low), (1.0 if turns(np.pi / 2) else high)


def _check_telescope(src, key, scenario, inst, md_variables, values, written):
    """The profile evaluated as the FMU will (plant.telescope.model, the same parameters) on a
    coarse grid over the run; its refusal becomes a ScenarioError naming the settings."""
    if any(isinstance(v, Link) for v in values.values()):
        return   # values known only at the start time

    def setting(name):
        if name in values:
            return values[name]
        var = md_variables[name]
        return (var.start if var.type == "String" else int(var.start) if var.type in ("Integer", "Enumeration")
                else float(var.start))

    def shown(names):
        raws = {**scenario.parameters[inst], **{n: r for (i, n), r in written.items() if i == inst}}
        return ", ".join(f"{n} = {raws[n]!r}" if n in raws else
                         f"{n} = {setting(n):.6g} {md_variables[n].unit or ''} (default)".replace("  ", " ")
                         for n in names)

    profiles = enumeration(md_variables["profile"])
    profile = next((p for p, i in profiles.items() if i == setting("profile")), None)
    names = {"slew": ("start_azimuth", "start_elevation", "target_azimuth", "target_elevation"),
             "sidereal": ("right_ascension", "declination", "utc_start", "latitude", "longitude"),
             "paper": ("paper_duration",), "replay": ("replay_table", "replay_smoothing")}.get(profile, ())
    where = f"fmus.{inst}.parameters" if key == "fmus" else key
    limits = ("lever_arm", "latitude", "longitude", "az_rate_max", "az_acc_max", "el_rate_max", "el_acc_max")
    try:
        params = dataclasses.replace(telescope.TelescopeParams.tianma(), **{n: setting(n) for n in limits})
    except InvalidInputError as exc:
        raise ScenarioError(src, where, f"{shown(limits)}: plant.telescope refuses them: {exc}") from None
    # the FMU evaluates the profile at t - start_delay; a grid of <= 1 s spacing over the run
    # (at most CHECK_POINTS points: the check of a run of years costs no more than a day's)
    points = min(CHECK_POINTS, 2 + int(np.ceil(scenario.stop_time - scenario.start_time)))
    times = np.linspace(scenario.start_time, scenario.stop_time, points) - setting("start_delay")
    try:
        if profile == "slew":
            telescope.slew(params, (setting("start_azimuth"), setting("start_elevation")),
                           (setting("target_azimuth"), setting("target_elevation")), times)
        elif profile == "sidereal":
            utc = datetime.fromtimestamp(setting("utc_start"), tz=timezone.utc)
            telescope.sidereal_track(params, setting("right_ascension"), setting("declination"), utc, times)
        elif profile == "paper":
            telescope.paper_manoeuvre(times, setting("paper_duration"))
        elif profile == "replay":   # read, checked, smoothed and prepared before the run (the FMUs get it: for_fmu)
            replay_table.prepared(setting("replay_table"), params, setting("replay_smoothing"))
    except (InvalidInputError, OverflowError, OSError, ValueError) as exc:
        raise ScenarioError(src, where, f"profile {profile!r} with {shown(names)}: plant.telescope refuses it: "
                            f"{exc}") from None
