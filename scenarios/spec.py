"""Scenario files: TOML, parsed and checked before anything runs.

A scenario names FMUs (by the kit's FMU names) with their parameters, the connections
between them, the time grid, the master algorithm, what to record, the metrics to report
and optionally one parameter to sweep. Every error points at the file, the key and the
problem. Quantities may carry units ("1 ms", "30 deg"); they are converted to SI here,
checked against the unit the FMU declares. The format is documented in the README's "Scenarios" section.

A parameter written "@inst.var" takes the value of that output of another FMU at the
start time (e.g. the plant's initial pose from the telescope's reference pose).

Two stages: ``load`` checks the file's own structure; ``bind`` checks it against the FMUs'
model descriptions (variables exist, causalities, sizes and units of connections, every
input fed). Both run before the master starts.
"""
import pathlib
import re
from dataclasses import dataclass, field

try:
    import tomllib
except ModuleNotFoundError:  # Python 3.10
    import tomli as tomllib

from .units import UnitError, to_si

FMU_SCRIPTS = {"hexapod_plant": "hexapod_plant_fmu", "telescope": "telescope_fmu",
               "leg_controller": "leg_controller_fmu", "mechanism3t_plant": "mechanism3t_fmu",
               "slider_controller": "slider_controller_fmu"}
# per instance: the native C FMU (no Python in the host) or the pythonfmu one; equal results
IMPLEMENTATIONS = ("native", "python")
MASTERS = ("jacobi", "gauss-seidel")
EXTRAPOLATIONS = ("none", "linear")
METRIC_KINDS = {  # kind -> required keys
    "leg_tracking": ("measured", "reference_pose"),
    "pose_tracking": ("measured", "reference"),
    "tracking": ("measured", "reference"),
    "peak": ("variable",),
    "base_effect": ("base", "reference"),
}
_TOP_KEYS = {"name", "description", "start_time", "stop_time", "step", "master", "extrapolation",
             "fmus", "connections", "record", "metrics", "sweep", "ci", "fidelity_tolerance"}


class ScenarioError(ValueError):
    """A problem in a scenario file; the message says file, key and problem."""

    def __init__(self, source, key, problem):
        super().__init__(f"{source}: {key}: {problem}")


@dataclass(frozen=True)
class Link:
    """A parameter taken from another FMU's output at the start time ("@inst.var")."""

    instance: str
    variable: str


@dataclass
class Metric:
    name: str
    kind: str
    args: dict
    start: float = 0.0     # metrics count from this time on (after a settling period)


@dataclass
class Scenario:
    source: str
    name: str
    description: str
    start_time: float
    stop_time: float
    step: float
    master: str
    extrapolation: str
    fmus: dict                  # instance -> FMU name
    parameters: dict            # instance -> {variable: raw value}
    connections: list           # (source "inst.var", [targets])
    record_interval: float
    record: list                # "inst.var" (vectors unexpanded)
    metrics: list
    sweep: tuple = None         # ("inst.var", [values])
    ci: dict = field(default_factory=dict)   # shortened settings for CI: {"stop_time": ...}
    fidelity_tolerance: float = None         # [N], for a plant with fidelity = "auto"
    notes: list = field(default_factory=list)  # what the runner decided (shown in the report)
    implementations: dict = field(default_factory=dict)  # instance -> one of IMPLEMENTATIONS


def _quantity(source, key, value, dimension):
    try:
        return to_si(value, dimension)
    except UnitError as exc:
        raise ScenarioError(source, key, str(exc)) from None


def _table(source, key, value):
    if not isinstance(value, dict):
        raise ScenarioError(source, key, f"expected a table, got {type(value).__name__}")
    return value


def _string_list(source, key, value):
    values = [value] if isinstance(value, str) else value
    if not isinstance(values, list) or not values or not all(isinstance(v, str) for v in values):
        raise ScenarioError(source, key, "expected a string or a non-empty list of strings")
    return values


def _reference(source, key, value, instances):
    if not isinstance(value, str) or not re.fullmatch(r"[A-Za-z_]\w*\.[\w\[\]\.]+", value):
        raise ScenarioError(source, key, f"expected 'instance.variable', got {value!r}")
    instance = value.split(".", 1)[0]
    if instance not in instances:
        raise ScenarioError(source, key, f"unknown FMU instance {instance!r}; declared: {', '.join(instances)}")
    return value


def parse(text, source="<string>", overrides=None):
    """Scenario from TOML text; ``overrides`` replaces top-level keys (e.g. the CI's
    shorter stop_time)."""
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ScenarioError(source, "TOML", str(exc)) from None
    data.update(overrides or {})
    unknown = set(data) - _TOP_KEYS
    if unknown:
        raise ScenarioError(source, sorted(unknown)[0], f"unknown key; allowed: {', '.join(sorted(_TOP_KEYS))}")
    for key in ("stop_time", "step", "fmus", "connections"):
        if key not in data:
            raise ScenarioError(source, key, "missing")
    start = _quantity(source, "start_time", data.get("start_time", 0.0), "s")
    stop = _quantity(source, "stop_time", data["stop_time"], "s")
    step = _quantity(source, "step", data["step"], "s")
    if not step > 0:
        raise ScenarioError(source, "step", f"must be positive, got {data['step']!r}")
    if not stop > start:
        raise ScenarioError(source, "stop_time", f"must be after start_time ({start} s)")
    master = data.get("master", "jacobi")
    if master not in MASTERS:
        raise ScenarioError(source, "master", f"unknown master {master!r}; choose one of {MASTERS}")
    extrapolation = data.get("extrapolation", "none")
    if extrapolation not in EXTRAPOLATIONS:
        raise ScenarioError(source, "extrapolation", f"unknown {extrapolation!r}; choose one of {EXTRAPOLATIONS}")

    fmus, parameters, implementations = {}, {}, {}
    for instance, table in _table(source, "fmus", data["fmus"]).items():
        key = f"fmus.{instance}"
        table = _table(source, key, table)
        extra = set(table) - {"fmu", "implementation", "parameters"}
        if extra:
            raise ScenarioError(source, f"{key}.{sorted(extra)[0]}",
                                "unknown key; allowed: fmu, implementation, parameters")
        implementations[instance] = table.get("implementation", IMPLEMENTATIONS[0])
        if implementations[instance] not in IMPLEMENTATIONS:
            raise ScenarioError(source, f"{key}.implementation", f"unknown implementation "
                                f"{implementations[instance]!r}; choose one of {', '.join(IMPLEMENTATIONS)}")
        if table.get("fmu") not in FMU_SCRIPTS:
            raise ScenarioError(source, f"{key}.fmu", f"unknown FMU {table.get('fmu')!r}; choose one of "
                                f"{', '.join(FMU_SCRIPTS)}")
        fmus[instance] = table["fmu"]
        parameters[instance] = dict(_table(source, f"{key}.parameters", table.get("parameters", {})))

    connections = []
    for i, conn in enumerate(data["connections"] if isinstance(data["connections"], list) else [None]):
        key = f"connections[{i}]"
        conn = _table(source, key, conn)
        if set(conn) != {"from", "to"}:
            raise ScenarioError(source, key, "a connection has exactly the keys 'from' and 'to'")
        targets = [_reference(source, f"{key}.to", t, fmus) for t in _string_list(source, f"{key}.to", conn["to"])]
        connections.append((_reference(source, f"{key}.from", conn["from"], fmus), targets))

    record = _table(source, "record", data.get("record", {}))
    extra = set(record) - {"interval", "variables"}
    if extra:
        raise ScenarioError(source, f"record.{sorted(extra)[0]}", "unknown key; allowed: interval, variables")
    interval = _quantity(source, "record.interval", record.get("interval", data["step"]), "s")
    ratio = interval / step
    if interval < step or abs(ratio - round(ratio)) > 1e-9 * ratio:
        raise ScenarioError(source, "record.interval", "must be a whole multiple of step")
    recorded = [_reference(source, "record.variables", v, fmus)
                for v in _string_list(source, "record.variables", record.get("variables", [])) ] \
        if record.get("variables") else []

    metrics = []
    for i, metric in enumerate(data.get("metrics", [])):
        key = f"metrics[{i}]"
        metric = dict(_table(source, key, metric))
        kind = metric.pop("kind", None)
        if kind not in METRIC_KINDS:
            raise ScenarioError(source, f"{key}.kind", f"unknown metric kind {kind!r}; choose one of "
                                f"{', '.join(METRIC_KINDS)}")
        name = metric.pop("name", kind)
        metric_start = _quantity(source, f"{key}.from", metric.pop("from", "0 s"), "s")
        for required in METRIC_KINDS[kind]:
            if required not in metric:
                raise ScenarioError(source, f"{key}.{required}", f"missing (metric kind {kind!r})")
        for arg, value in metric.items():
            if kind == "base_effect":
                if value not in fmus:
                    raise ScenarioError(source, f"{key}.{arg}", f"unknown FMU instance {value!r}")
            else:
                _reference(source, f"{key}.{arg}", value, fmus)
        metrics.append(Metric(name, kind, metric, metric_start))

    sweep = None
    if "sweep" in data:
        table = _table(source, "sweep", data["sweep"])
        if set(table) != {"parameter", "values"}:
            raise ScenarioError(source, "sweep", "a sweep has exactly the keys 'parameter' and 'values'")
        if not isinstance(table["values"], list) or not table["values"]:
            raise ScenarioError(source, "sweep.values", "expected a non-empty list")
        sweep = (_reference(source, "sweep.parameter", table["parameter"], fmus), table["values"])
    ci = _table(source, "ci", data.get("ci", {}))
    tolerance = None
    if "fidelity_tolerance" in data:
        tolerance = _quantity(source, "fidelity_tolerance", data["fidelity_tolerance"], "N")
    for inst, params in parameters.items():
        if params.get("fidelity") == "auto" and (fmus[inst] != "hexapod_plant" or tolerance is None):
            raise ScenarioError(source, f"fmus.{inst}.parameters.fidelity",
                                '"auto" needs a hexapod_plant and a top-level fidelity_tolerance (a force)')
    name = data.get("name", pathlib.Path(source).stem)
    return Scenario(source, name, data.get("description", ""), start, stop, step, master, extrapolation,
                    fmus, parameters, connections, interval, recorded, metrics, sweep, ci, tolerance,
                    implementations=implementations)


def load(path, overrides=None):
    path = pathlib.Path(path)
    if not path.exists():
        raise ScenarioError(str(path), "file", "does not exist")
    return parse(path.read_text(), str(path), overrides)


# ------------------------------------------------------------------- binding to the FMUs
def _enumeration(description):
    """{'slew': 0, ...} from an Integer parameter's description '... 0 slew, 1 sidereal'."""
    return {name: int(i) for i, name in re.findall(r"(\d+) ([A-Za-z_][\w-]*)", description or "")}


def expand(md_variables, reference):
    """Scalar names of 'inst.var' (a vector name expands to var[1..n])."""
    instance, name = reference.split(".", 1)
    if name in md_variables:
        return [name]
    names = []
    while f"{name}[{len(names) + 1}]" in md_variables:
        names.append(f"{name}[{len(names) + 1}]")
    return names


def bind(scenario, model_descriptions):
    """Check the scenario against the FMUs' model descriptions; return the parameter values
    per instance converted to what the FMU expects (SI floats, enumeration indices)."""
    src = scenario.source
    variables = {inst: {v.name: v for v in model_descriptions[inst].modelVariables} for inst in scenario.fmus}

    def scalars(key, reference):
        inst = reference.split(".", 1)[0]
        names = expand(variables[inst], reference)
        if not names:
            raise ScenarioError(src, key, f"FMU instance {inst!r} ({scenario.fmus[inst]}) has no variable "
                                f"{reference.split('.', 1)[1]!r}")
        return inst, [variables[inst][n] for n in names]

    values = {}
    fed = set()
    for inst, params in scenario.parameters.items():
        values[inst] = {}
        for name, raw in params.items():
            key = f"fmus.{inst}.parameters.{name}"
            _, targets = scalars(key, f"{inst}.{name}")
            if isinstance(raw, str) and raw.startswith("@"):
                link_inst, sources = scalars(key, raw[1:])
                if len(sources) != len(targets) or any(v.causality != "output" for v in sources):
                    raise ScenarioError(src, key, f"{raw} must be an output of the same size as {name}")
                if link_inst == inst:
                    raise ScenarioError(src, key, "a parameter cannot come from its own FMU")
                for var, source_var in zip(targets, sources):
                    values[inst][var.name] = Link(link_inst, source_var.name)
                continue
            raws = raw if isinstance(raw, list) else [raw]
            if len(raws) != len(targets):
                raise ScenarioError(src, key, f"expected {len(targets)} values, got {len(raws)}")
            for var, item in zip(targets, raws):
                if var.causality not in ("parameter", "input"):
                    raise ScenarioError(src, key, f"{var.name} is an {var.causality}, not a parameter or input")
                values[inst][var.name] = _value(src, key, var, item)
                fed.add((inst, var.name))
    for i, (source_ref, targets) in enumerate(scenario.connections):
        key = f"connections[{i}]"
        s_inst, s_vars = scalars(f"{key}.from", source_ref)
        for target in targets:
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
                fed.add((t_inst, t.name))
    for inst in scenario.fmus:
        missing = [n for n, v in variables[inst].items() if v.causality == "input" and (inst, n) not in fed]
        if missing:
            raise ScenarioError(src, f"fmus.{inst}", f"inputs neither connected nor set: {', '.join(missing)}")
    for reference in scenario.record + [r for m in scenario.metrics for r in metric_variables(m)]:
        scalars("record", reference)
    if scenario.sweep:
        inst, (var, *_) = scalars("sweep.parameter", scenario.sweep[0])
        for item in scenario.sweep[1]:
            _value(src, "sweep.values", var, item)
    return values


def metric_variables(metric):
    """The 'inst.var' references a metric reads."""
    if metric.kind == "base_effect":
        base, ref = metric.args["base"], metric.args["reference"]
        return [f"{base}.base_{x}" for x in ("pose", "rate", "acc")] + \
               [f"{ref}.reference_{x}" for x in ("pose", "rate", "acc")]
    return list(metric.args.values())


def _value(source, key, var, raw):
    if var.type == "Integer":
        choices = _enumeration(var.description)
        if isinstance(raw, str):
            if raw not in choices:
                raise ScenarioError(source, key, f"{raw!r} is not one of {', '.join(choices)}")
            return choices[raw]
        if isinstance(raw, bool) or not isinstance(raw, int):
            raise ScenarioError(source, key, f"expected an integer or a name, got {raw!r}")
        return raw
    return _quantity(source, key, raw, var.unit)


def sweep_value(scenario, model_descriptions, item):
    """The converted value of one sweep item for its parameter."""
    inst, name = scenario.sweep[0].split(".", 1)
    var = next(v for v in model_descriptions[inst].modelVariables if v.name == name)
    return inst, name, _value(scenario.source, "sweep.values", var, item)
