"""Scenario files: TOML, parsed and checked before anything runs.

A scenario names FMUs (by the kit's FMU names) with their parameters, the connections
between them, the time grid, the master algorithm, what to record, the metrics to report
and optionally one parameter to sweep. Every error points at the file, the key and the
problem. Quantities may carry units ("1 ms", "30 deg"); they are converted to SI here,
checked against the unit the FMU declares. The format is documented in the README's "Scenarios" section.

A parameter written "@inst.var" takes the value of that output of another FMU at the
start time (e.g. the plant's initial pose from the telescope's reference pose).

Two stages: ``load`` checks the file's own structure (also: stop_time a whole number of
steps, metrics that count something); ``bind`` checks it against the FMUs' model
descriptions (variables exist, causalities, sizes and units of connections, every input
fed by exactly one source, values within the variables' declared min/max) and what the
models refuse that min/max cannot say (the telescope profile over the run). Both run
before the master starts.
"""
import dataclasses
import pathlib
import re
from dataclasses import dataclass, field
from datetime import datetime, timezone

try:
    import tomllib
except ModuleNotFoundError:  # Python 3.10
    import tomli as tomllib

import numpy as np

from movingbase.plant.errors import InvalidInputError
from movingbase.plant import telescope
from .units import UNITS, UnitError, split, to_si

FMU_SCRIPTS = {"hexapod_plant": "hexapod_plant_fmu", "telescope": "telescope_fmu",
               "leg_controller": "leg_controller_fmu", "mechanism3t_plant": "mechanism3t_fmu",
               "slider_controller": "slider_controller_fmu", "leg_sensor": "leg_sensor_fmu",
               "base_sensor": "base_sensor_fmu", "wind": "wind_fmu"}
# inputs that may stay unconnected, held at their start value (0: the effect they feed is off)
OPTIONAL_INPUTS = {"hexapod_plant": ("platform_wrench",)}
# per instance: the native C FMU (no Python in the host) or the pythonfmu one; equal results
IMPLEMENTATIONS = ("native", "python")
# per instance: the FMI version of the FMU (3: the native FMU's FMI 3.0 build; equal results)
FMI_VERSIONS = (2, 3)
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
    fmi_versions: dict = field(default_factory=dict)     # instance -> one of FMI_VERSIONS


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
    needs = ("a scenario needs stop_time, step, one [fmus.<instance>] table per FMU and [[connections]] "
             "(example: scenarios/files/telescope_slew.toml)")
    if not data:
        raise ScenarioError(source, "file", f"empty (no TOML keys): {needs}")
    data.update(overrides or {})
    unknown = set(data) - _TOP_KEYS
    if unknown:
        raise ScenarioError(source, sorted(unknown)[0], f"unknown key; allowed: {', '.join(sorted(_TOP_KEYS))}")
    for key in ("stop_time", "step", "fmus", "connections"):
        if key not in data:
            raise ScenarioError(source, key, f"missing; {needs}")
    start = _quantity(source, "start_time", data.get("start_time", 0.0), "s")
    stop = _quantity(source, "stop_time", data["stop_time"], "s")
    step = _quantity(source, "step", data["step"], "s")
    if not step > 0:
        raise ScenarioError(source, "step", f"must be positive, got {data['step']!r}")
    if not stop > start:
        raise ScenarioError(source, "stop_time", f"must be after start_time ({start} s)")
    steps = (stop - start) / step
    if abs(steps - round(steps)) > 1e-9 * max(1.0, steps):
        nearest = " and ".join(f"{start + n * step:.12g} s" for n in sorted({max(1, int(steps)), int(steps) + 1}))
        raise ScenarioError(source, "stop_time", f"{data['stop_time']!r} is not a whole number of steps of "
                            f"{data['step']!r} after start_time ({steps:.6g} steps); nearest valid stop times: "
                            f"{nearest}")
    master = data.get("master", "jacobi")
    if master not in MASTERS:
        raise ScenarioError(source, "master", f"unknown master {master!r}; choose one of {MASTERS}")
    extrapolation = data.get("extrapolation", "none")
    if extrapolation not in EXTRAPOLATIONS:
        raise ScenarioError(source, "extrapolation", f"unknown {extrapolation!r}; choose one of {EXTRAPOLATIONS}")

    fmus, parameters, implementations, versions = {}, {}, {}, {}
    for instance, table in _table(source, "fmus", data["fmus"]).items():
        key = f"fmus.{instance}"
        table = _table(source, key, table)
        extra = set(table) - {"fmu", "implementation", "fmi_version", "parameters"}
        if extra:
            raise ScenarioError(source, f"{key}.{sorted(extra)[0]}",
                                "unknown key; allowed: fmu, implementation, fmi_version, parameters")
        implementations[instance] = table.get("implementation", IMPLEMENTATIONS[0])
        if implementations[instance] not in IMPLEMENTATIONS:
            raise ScenarioError(source, f"{key}.implementation", f"unknown implementation "
                                f"{implementations[instance]!r}; choose one of {', '.join(IMPLEMENTATIONS)}")
        versions[instance] = table.get("fmi_version", FMI_VERSIONS[0])
        if versions[instance] not in FMI_VERSIONS or isinstance(versions[instance], bool):
            raise ScenarioError(source, f"{key}.fmi_version", f"unknown FMI version {versions[instance]!r}; "
                                f"choose one of {', '.join(map(str, FMI_VERSIONS))}")
        if versions[instance] == 3 and implementations[instance] != "native":
            raise ScenarioError(source, f"{key}.fmi_version", "FMI 3.0 is built for the native FMUs only; "
                                f"implementation {implementations[instance]!r} is FMI 2.0")
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
    every = int(round(ratio))
    last_record = start + (int(round(steps)) // every) * every * step
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
        metric_start = _quantity(source, f"{key}.from", metric.get("from", "0 s"), "s")
        if metric_start >= stop or metric_start > last_record + 1e-9 * step:
            where = f"at or after stop_time ({stop:g} s)" if metric_start >= stop else \
                f"after the last recorded time ({last_record:g} s)"
            raise ScenarioError(source, f"{key}.from", f"{metric.pop('from')!r} lies {where}: the metric would "
                                "count nothing")
        metric.pop("from", None)
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
                    implementations=implementations, fmi_versions=versions)


def load(path, overrides=None):
    """Scenario from a TOML file; a missing path, a directory or a file that is not
    UTF-8 text is refused with what was expected."""
    path = pathlib.Path(path)
    if path.is_dir():
        inside = sorted(p.name for p in path.glob("*.toml"))
        hint = f"; it holds {', '.join(inside)}" if inside else ""
        raise ScenarioError(str(path), "file", f"is a directory, not a scenario file (.toml){hint}")
    if not path.exists():
        raise ScenarioError(str(path), "file", "does not exist")
    data = path.read_bytes()
    if b"\0" in data:
        raise ScenarioError(str(path), "file", f"is a binary file (NUL byte at offset {data.find(0)}), "
                            "not a TOML scenario")
    try:
        text = data.decode("utf-8-sig")   # a leading BOM (some editors write one) is not TOML
    except UnicodeDecodeError as exc:
        raise ScenarioError(str(path), "file", f"is not UTF-8 text (byte 0x{data[exc.start]:02x} at offset "
                            f"{exc.start}); a scenario is a TOML file in UTF-8") from None
    return parse(text, str(path), overrides)


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
    feeders = {}   # (instance, input) -> (connection index, "source -> target" as written, source)
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
                _feed_once(src, key, i, f"{source_ref} -> {target}", (s_inst, s.name), (t_inst, t.name),
                           feeders, fed)
    for inst in scenario.fmus:
        optional = OPTIONAL_INPUTS.get(scenario.fmus[inst], ())
        missing = [n for n, v in variables[inst].items() if v.causality == "input" and (inst, n) not in fed
                   and n.split("[", 1)[0] not in optional]
        if missing:
            raise ScenarioError(src, f"fmus.{inst}", f"inputs neither connected nor set: {', '.join(missing)}")
    for reference in scenario.record:
        scalars("record.variables", reference)
    for i, metric in enumerate(scenario.metrics):
        _check_metric(src, f"metrics[{i}]", metric, scalars)
    _check_models(src, "fmus", scenario, variables, values)
    if scenario.sweep:
        inst, (var, *_) = scalars("sweep.parameter", scenario.sweep[0])
        for i, item in enumerate(scenario.sweep[1]):
            key = f"sweep.values[{i}]"
            swept = {name: dict(v) for name, v in values.items()}
            swept[inst][var.name] = _value(src, key, var, item)
            _check_models(src, key, scenario, variables, swept, {(inst, var.name): item})
    return values


def _feed_once(src, key, index, written, source, target, feeders, fed):
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


def _check_metric(src, key, metric, scalars):
    """The variables a metric reads exist, reported under the metric's own keys, with the
    sizes its kind needs."""
    if metric.kind == "base_effect":
        references = metric_variables(metric)
        for arg, reads in (("base", references[:3]), ("reference", references[3:])):
            for reference in reads:
                scalars(f"{key}.{arg}", reference)
        return
    sizes = {arg: len(scalars(f"{key}.{arg}", reference)[1]) for arg, reference in metric.args.items()}
    needed = {"leg_tracking": {"measured": 6, "reference_pose": 6},
              "pose_tracking": {"measured": 6, "reference": 6}}.get(metric.kind, {})
    for arg, size in needed.items():
        if sizes[arg] != size:
            raise ScenarioError(src, f"{key}.{arg}", f"{metric.args[arg]} has {sizes[arg]} values; "
                                f"a {metric.kind} metric needs {size}")
    if metric.kind == "tracking" and sizes["measured"] != sizes["reference"]:
        raise ScenarioError(src, key, f"measured {metric.args['measured']} has {sizes['measured']} values, "
                            f"reference {metric.args['reference']} {sizes['reference']}")


# -------------------------------------------------- ranges that min/max cannot declare
def _check_models(src, key, scenario, variables, values, written=None):
    """Checks that need several parameters at once, as the models themselves make them
    (today: the telescope's profile over the run), so the FMU does not refuse them at
    t = 0. ``written`` maps (instance, name) to the value as the file wrote it."""
    for inst, fmu in scenario.fmus.items():
        if fmu == "telescope":
            _check_telescope(src, key, scenario, inst, variables[inst], values[inst], written or {})


def _check_telescope(src, key, scenario, inst, md_variables, values, written):
    """The profile evaluated as the FMU will (plant.telescope, the same parameters) on a
    coarse grid over the run; its refusal becomes a ScenarioError naming the settings."""
    if any(isinstance(v, Link) for v in values.values()):
        return   # values known only at the start time

    def setting(name):
        if name in values:
            return values[name]
        var = md_variables[name]
        return int(var.start) if var.type == "Integer" else float(var.start)

    def shown(names):
        raws = {**scenario.parameters[inst], **{n: r for (i, n), r in written.items() if i == inst}}
        return ", ".join(f"{n} = {raws[n]!r}" if n in raws else
                         f"{n} = {setting(n):.6g} {md_variables[n].unit or ''} (default)".replace("  ", " ")
                         for n in names)

    profiles = _enumeration(md_variables["profile"].description)
    profile = next((p for p, i in profiles.items() if i == setting("profile")), None)
    names = {"slew": ("start_azimuth", "start_elevation", "target_azimuth", "target_elevation"),
             "sidereal": ("right_ascension", "declination", "utc_start", "latitude", "longitude"),
             "paper": ("paper_duration",)}.get(profile, ())
    where = f"fmus.{inst}.parameters" if key == "fmus" else key
    limits = ("lever_arm", "latitude", "longitude", "az_rate_max", "az_acc_max", "el_rate_max", "el_acc_max")
    try:
        params = dataclasses.replace(telescope.TelescopeParams.tianma(), **{n: setting(n) for n in limits})
    except InvalidInputError as exc:
        raise ScenarioError(src, where, f"{shown(limits)}: plant.telescope refuses them: {exc}") from None
    # the FMU evaluates the profile at t - start_delay; a grid of <= 1 s spacing over the run
    times = np.linspace(scenario.start_time, scenario.stop_time,
                        2 + int(np.ceil(scenario.stop_time - scenario.start_time))) - setting("start_delay")
    try:
        if profile == "slew":
            telescope.slew(params, (setting("start_azimuth"), setting("start_elevation")),
                           (setting("target_azimuth"), setting("target_elevation")), times)
        elif profile == "sidereal":
            utc = datetime.fromtimestamp(setting("utc_start"), tz=timezone.utc)
            telescope.sidereal_track(params, setting("right_ascension"), setting("declination"), utc, times)
        elif profile == "paper":
            telescope.paper_manoeuvre(times, setting("paper_duration"))
    except (InvalidInputError, OverflowError, OSError, ValueError) as exc:
        raise ScenarioError(src, where, f"profile {profile!r} with {shown(names)}: plant.telescope refuses it: "
                            f"{exc}") from None


def metric_variables(metric):
    """The 'inst.var' references a metric reads."""
    if metric.kind == "base_effect":
        base, ref = metric.args["base"], metric.args["reference"]
        return [f"{base}.base_{x}" for x in ("pose", "rate", "acc")] + \
               [f"{ref}.reference_{x}" for x in ("pose", "rate", "acc")]
    return list(metric.args.values())


def _value(source, key, var, raw):
    """raw converted for var (SI float or integer index), within the FMU's declared range."""
    if var.type == "Integer":
        choices = _enumeration(var.description)
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
        value = _quantity(source, key, raw, var.unit)
    low, high = _limits(var)
    if (low is not None and value < low) or (high is not None and value > high):
        converted = isinstance(raw, str) and split(raw)[1] not in (None, var.unit)
        shown = f"{raw!r} = {value:.6g} {var.unit or ''}".rstrip() if converted else repr(raw)
        raise ScenarioError(source, key, f"{shown} is outside the range of {var.name} declared by the FMU: "
                            f"{_range_text(var, raw)}")
    return value


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
    user = split(raw)[1] if isinstance(raw, str) and var.type != "Integer" else None
    return f"{interval(UNITS[user][0], user)} = {si}" if user in UNITS and user != var.unit else si


def sweep_value(scenario, model_descriptions, item):
    """The converted value of one sweep item for its parameter."""
    inst, name = scenario.sweep[0].split(".", 1)
    var = next(v for v in model_descriptions[inst].modelVariables if v.name == name)
    return inst, name, _value(scenario.source, "sweep.values", var, item)
