"""Stage two: a scenario against the FMUs' model descriptions (``bind``): variables exist,
causalities, sizes and units of connections, values within the declared min/max, then
the checks of scenarios.spec.checks; and a sweep value as the FMU takes it."""
import difflib
import pathlib
import re

import numpy as np

from fmu_src.catalogue import OPTIONAL_INPUTS
from scenarios.spec.checks import check_links, check_metric, check_models, check_rates, check_wiring, feed_once
from scenarios.spec.keys import FMI_VERSIONS, IMPLEMENTATIONS, Link, Metric, enumeration, expand
from scenarios.spec.parsing import parse_quantity, parse_reference
from scenarios.spec.text import Problems, ScenarioError
from scenarios.spec.units import UNITS, split


def _check_derivatives(scenario, model_descriptions):
    """extrapolation = "derivatives" needs a connection from an FMI 3 FMU that gives output
    derivatives (maxOutputDerivativeOrder > 0: the telescope built as FMI 3)."""
    sources = dict.fromkeys(source.split(".", 1)[0] for source, _ in scenario.connections)
    giving = [inst for inst in sources if model_descriptions[inst].fmiVersion.startswith("3")
              and int(model_descriptions[inst].coSimulation.maxOutputDerivativeOrder or 0) > 0]
    if not giving:
        telescopes = [inst for inst in sources if scenario.fmus.get(inst) == "telescope"]
        if telescopes and all(scenario.implementations.get(t) == "python" for t in telescopes):
            cause = ("the telescope instance is the pythonfmu FMU (implementation python, as "
                     "--implementation python makes every instance), an FMI 2.0 FMU, which gives none: "
                     "run it native with fmi_version = 3")
        else:
            cause = "set fmi_version = 3 on the telescope instance (the FMU that gives them)"
        raise ScenarioError(scenario.source, "extrapolation",
                            '"derivatives" takes the output derivatives of FMI 3 FMUs that give them, and no '
                            f'connection starts at one: {cause}, or use "linear"')


def bind(scenario, model_descriptions):
    """Check the scenario against the FMUs' model descriptions; return the parameter values
    per instance converted to what the FMU expects (SI floats, enumeration indices)."""
    src = scenario.source
    variables = {inst: {v.name: v for v in model_descriptions[inst].modelVariables} for inst in scenario.fmus}

    def scalars(key, reference):
        inst = reference.split(".", 1)[0]
        if inst not in variables:        # a reference parse did not see (a link, a Scenario changed in Python)
            parse_reference(src, key, reference, variables)
        names = expand(variables[inst], reference)
        if not names:
            name = reference.split(".", 1)[1]
            near = difflib.get_close_matches(name, list(dict.fromkeys(n.split("[", 1)[0] for n in variables[inst])), 1,
                                             0.7)
            raise ScenarioError(src, key, f"FMU instance {inst!r} ({scenario.fmus[inst]}) has no variable {name!r}"
                                + (f"; did you mean {near[0]!r}?" if near else ""))
        return inst, [variables[inst][n] for n in names]

    problems = Problems()
    values = {inst: {} for inst in scenario.fmus}
    fed = set()
    for inst, params in scenario.parameters.items():
        owners = {}     # variable -> the key that set it: a vector and one of its elements both set, the later won
        for name, raw in params.items():
            key = f"fmus.{inst}.parameters.{name}"
            with problems.part():
                for var in scalars(key, f"{inst}.{name}")[1]:
                    if var.name in owners:
                        raise ScenarioError(src, key, f"sets {var.name}, which {owners[var.name]} sets too: "
                                                      "set each value once")
                    owners[var.name] = key
                _bind_parameter(src, key, inst, name, raw, scalars, values, fed)
    with problems.part():
        check_links(src, values)
    feeders = {}   # (instance, input) -> (connection index, "source -> target" as written, source)
    told = len(problems.errors)
    for i, (source_ref, targets) in enumerate(scenario.connections):
        key = f"connections[{i}]"
        for target in targets:
            with problems.part():
                s_inst, s_vars = scalars(f"{key}.from", source_ref)
                t_inst, t_vars = scalars(f"{key}.to", target)
                if any(v.causality != "output" for v in s_vars):
                    raise ScenarioError(src, f"{key}.from", f"{source_ref} is not an output")
                if any(v.causality != "input" for v in t_vars):
                    raise ScenarioError(src, f"{key}.to", f"{target} is not an input")
                if len(s_vars) != len(t_vars):
                    raise ScenarioError(src, key, f"{source_ref} has {len(s_vars)} values, {target} {len(t_vars)}")
                for s, t in zip(s_vars, t_vars):
                    if s.type != t.type or (s.unit or "") != (t.unit or ""):
                        raise ScenarioError(src, key, f"incompatible: {s_inst}.{s.name} ({s.type}, {s.unit}) -> "
                                            f"{t_inst}.{t.name} ({t.type}, {t.unit})")
                    feed_once(src, key, i, f"{source_ref} -> {target}", (s_inst, s.name), (t_inst, t.name),
                               feeders, fed)
    if len(problems.errors) == told:     # wiring is judged on connections that are each valid
        with problems.part():
            check_wiring(src, scenario, variables, feeders)
    if scenario.extrapolation == "derivatives":
        with problems.part():
            _check_derivatives(scenario, model_descriptions)
    for inst in scenario.fmus:
        optional = OPTIONAL_INPUTS.get(scenario.fmus[inst], ())
        missing = [n for n, v in variables[inst].items() if v.causality == "input" and (inst, n) not in fed
                   and n.split("[", 1)[0] not in optional]
        if missing:
            problems.errors.append(ScenarioError(src, f"fmus.{inst}",
                                                 f"inputs neither connected nor set: {', '.join(missing)}"))
    recorded = {}       # scalar -> the reference that records it: a column is recorded once
    for reference in scenario.record:
        with problems.part():
            inst, names = scalars("record.variables", reference)
            for var in names:
                other = recorded.setdefault(f"{inst}.{var.name}", reference)
                if other is not reference:
                    raise ScenarioError(src, "record.variables", f"{inst}.{var.name} is recorded twice ({other!r} "
                                        f"and {reference!r}): one column each; keep one")
    for i, metric in enumerate(scenario.metrics):
        with problems.part():
            check_metric(src, f"metrics[{i}]", metric, scalars)
    problems.raise_any()     # the checks below need every value bound
    with problems.part():
        check_rates(src, "fmus", scenario, variables, values)
    with problems.part():
        check_models(src, "fmus", scenario, variables, values)
    if scenario.sweep:
        inst, swept_vars = scalars("sweep.parameter", scenario.sweep[0])
        var = _swept(src, scenario.sweep[0], swept_vars, feeders)
        seen = {}
        for i, item in enumerate(scenario.sweep[1]):
            key = f"sweep.values[{i}]"
            with problems.part():
                swept = {name: dict(v) for name, v in values.items()}
                swept[inst][var.name] = _value(src, key, var, item)
                if swept[inst][var.name] in seen:
                    j = seen[swept[inst][var.name]]
                    raise ScenarioError(src, key, f"{item!r} is the same value as sweep.values[{j}] "
                                        f"({scenario.sweep[1][j]!r}): each value runs once")
                seen[swept[inst][var.name]] = i
                with problems.part():
                    check_rates(src, key, scenario, variables, swept)
                check_models(src, key, scenario, variables, swept, {(inst, var.name): item})
    problems.raise_any()
    return values


def _swept(src, reference, swept, feeders):
    """The one variable a sweep sets: a parameter, or an input no connection feeds (the
    connection would set it in every run: runs labelled by values that did not run)."""
    if len(swept) != 1:
        raise ScenarioError(src, "sweep.parameter", f"{reference} has {len(swept)} values; a sweep sets one: name an "
                            f"element, e.g. {reference}[1]")
    var, inst = swept[0], reference.split(".", 1)[0]
    if var.causality not in ("parameter", "input"):
        raise ScenarioError(src, "sweep.parameter", f"{reference} is an {var.causality}, not a parameter or input")
    if (inst, var.name) in feeders:
        index, written, _ = feeders[(inst, var.name)]
        raise ScenarioError(src, "sweep.parameter", f"{reference} is an input that connections[{index}] ({written}) "
                            "feeds: the connection would set it in every run, not the sweep values")
    return var


def _bind_parameter(src, key, inst, name, raw, scalars, values, fed):
    """One parameter as written (a value, a list for a vector, or a link "@inst.var")
    into ``values``; the inputs it sets are added to ``fed``."""
    _, targets = scalars(key, f"{inst}.{name}")
    raw = plain(raw)
    if isinstance(raw, str) and raw.startswith("@"):
        if not re.fullmatch(r"@[A-Za-z_]\w*\.[\w\[\]\.]+", raw, re.ASCII):
            raise ScenarioError(src, key, f"link {raw!r} is not '@instance.output' (the output of another FMU "
                                "at the start time, e.g. '@base.reference_pose')")
        link_inst, sources = scalars(key, raw[1:])
        if len(sources) != len(targets) or any(v.causality != "output" for v in sources):
            raise ScenarioError(src, key, f"{raw} must be an output of the same size as {name}")
        if link_inst == inst:
            raise ScenarioError(src, key, "a parameter cannot come from its own FMU")
        for var, source_var in zip(targets, sources):
            values[inst][var.name] = Link(link_inst, source_var.name)
        return
    raws = raw if isinstance(raw, list) else [raw]
    if len(raws) != len(targets):
        raise ScenarioError(src, key, f"expected {len(targets)} values, got {len(raws)}")
    for var, item in zip(targets, raws):
        if var.causality not in ("parameter", "input"):
            raise ScenarioError(src, key, f"{var.name} is an {var.causality}, not a parameter or input")
        values[inst][var.name] = _value(src, key, var, item)
        fed.add((inst, var.name))


def plain(value):
    """A value from Python as the TOML file would give it: numpy scalars as Python
    numbers, arrays and tuples as lists (a notebook's np.float32(0.5) or np.zeros(6))."""
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, (np.ndarray, tuple, list)):
        items = value.tolist() if isinstance(value, np.ndarray) else value
        return [plain(v) for v in items] if isinstance(items, list) else items
    return value


def as_data(scenario):
    """A Scenario's fields as the tables of a scenario file (times in SI seconds), so that
    parse_data checks a Scenario changed in Python exactly as it checks a file."""
    fmus = scenario.fmus if isinstance(scenario.fmus, dict) else {}
    tables = {inst: {"fmu": fmu, "implementation": scenario.implementations.get(inst, IMPLEMENTATIONS[0]),
                     "fmi_version": scenario.fmi_versions.get(inst, FMI_VERSIONS[0]),
                     "parameters": scenario.parameters.get(inst, {}) if isinstance(scenario.parameters, dict) else
                     scenario.parameters}
              for inst, fmu in fmus.items()}
    connections = [{"from": c[0], "to": plain(c[1])} if isinstance(c, (tuple, list)) and len(c) == 2 else c
                   for c in scenario.connections] if isinstance(scenario.connections, list) else scenario.connections
    metrics = [{"kind": m.kind, "name": m.name, "from": m.start, **m.args} if isinstance(m, Metric) else m
               for m in scenario.metrics] if isinstance(scenario.metrics, list) else scenario.metrics
    data = {"description": scenario.description, "start_time": plain(scenario.start_time),
            "stop_time": plain(scenario.stop_time), "step": plain(scenario.step), "master": scenario.master,
            "extrapolation": scenario.extrapolation, "fmus": tables if isinstance(scenario.fmus,
                                                                                  dict) else scenario.fmus,
            "connections": connections, "metrics": metrics,
            "record": {"interval": plain(scenario.record_interval), "variables": plain(scenario.record),
                       **({"metric_interval": plain(scenario.metric_interval)} if scenario.metric_interval else {})}}
    if scenario.name != pathlib.Path(scenario.source).stem:     # the file's own name is not checked as a name
        data["name"] = scenario.name
    if scenario.sweep is not None:
        sweep = scenario.sweep
        data["sweep"] = {"parameter": sweep[0], "values": plain(sweep[1])} \
            if isinstance(sweep, (tuple, list)) and len(sweep) == 2 else sweep
    if scenario.ci:
        data["ci"] = scenario.ci
    if scenario.fidelity_tolerance is not None:
        data["fidelity_tolerance"] = plain(scenario.fidelity_tolerance)
    if scenario.requirements:
        data["requirements"] = {r.name: r.written for r in scenario.requirements}
    return data


def _value(source, key, var, raw):
    """raw converted for var (SI float or integer index), within the FMU's declared range."""
    raw = plain(raw)
    if var.type == "String":   # a file's path (the telescope's replay_table): relative to the scenario's folder
        if not isinstance(raw, str):
            raise ScenarioError(source, key, f"{raw!r} is not text ({var.name}: {var.description})")
        folder = pathlib.Path(source).parent if pathlib.Path(source).is_file() else pathlib.Path.cwd()
        return str(folder / raw) if raw else raw
    if var.type in ("Integer", "Enumeration"):
        choices = enumeration(var)
        if isinstance(raw, str) and raw in choices:
            return choices[raw]
        if choices and (isinstance(raw, str) or raw not in choices.values()):
            raise ScenarioError(source, key, f"{raw!r} is not one of {', '.join(choices)} (or their numbers: "
                                f"{', '.join(f'{i} {n}' for n, i in choices.items())})")
        if isinstance(raw, bool) or not isinstance(raw, int):
            raise ScenarioError(source, key, f"{raw!r} is not one of the allowed values: "
                                f"{_range_text(var) or 'an integer'} ({var.name}: {var.description})")
        value = raw
    else:
        value = parse_quantity(source, key, raw, var.unit)
    low, high = _limits(var)
    if (low is not None and value < low) or (high is not None and value > high):
        converted = isinstance(raw, str) and split(raw)[1] not in (None, var.unit)
        shown = f"{raw!r} = {value:.6g} {var.unit or ''}".rstrip() if converted else repr(raw)
        hint = ""
        if _bare(raw) and var.unit:     # the rule (scenarios.spec.units): a bare number is SI
            number = float(raw) if not isinstance(raw, str) else split(raw)[0]
            other = {"rad": "deg", "rad/s": "deg/s", "rad/s2": "deg/s2", "m": "mm"}.get(var.unit)
            hint = (f" (a bare number is SI: {number:g} {var.unit}" +
                    (f"; for {other} write '{number:g} {other}'" if other else "") + ")")
        raise ScenarioError(source, key, f"{shown} is outside the range of {var.name} declared by the FMU: "
                            f"{_range_text(var, raw)}{hint}")
    return value


def _bare(raw):
    """A number written without a unit (a number, or text of one)."""
    return (isinstance(raw, (int, float)) and not isinstance(raw, bool)) or (isinstance(raw, str) and
                                                                             split(raw)[1] is None)


def _limits(var):
    """(min, max) the model description declares for var, None where it declares none."""
    return tuple(None if v is None else float(v) for v in (var.min, var.max))


def _range_text(var, raw=None):
    """'[0, 90] deg = [0, 1.5708] rad' (in the unit the user wrote, then SI) or ''."""
    low, high = _limits(var)
    if low is None and high is None:
        return ""

    def interval(factor, unit):
        text = "[" + ", ".join("-inf" if v is None and i == 0 else "inf" if v is None else f"{v / factor:.6g}"
                               for i, v in enumerate((low, high))) + "]"
        return f"{text} {unit}".rstrip()

    si = interval(1.0, var.unit or "")
    user = split(raw)[1] if isinstance(raw, str) and var.type not in ("Integer", "Enumeration") else None
    return f"{interval(UNITS[user][0], user)} = {si}" if user in UNITS and user != var.unit else si


def sweep_value(scenario, model_descriptions, item):
    """The converted value of one sweep item for its parameter."""
    inst, name = scenario.sweep[0].split(".", 1)
    var = next(v for v in model_descriptions[inst].modelVariables if v.name == name)
    return inst, name, _value(scenario.source, "sweep.values", var, item)
