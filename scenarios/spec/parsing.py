"""Stage one: a file's own structure (``load``, ``parse_data``), checked before any FMU
is opened: keys, types, quantities with units, references between instances, stop_time a
whole number of steps, metrics that count something."""
import difflib
import math
import pathlib
import re

from fmu_src.catalogue import KEYS as FMU_KEYS
from scenarios.spec.keys import (
    EXTRAPOLATIONS,
    FMI_VERSIONS,
    IMPLEMENTATIONS,
    INSTANCE_NAME,
    KEYS,
    MASTERS,
    MAX_TIME_ULP,
    METRIC_KINDS,
    METRIC_NUMBERS,
    NOT_IN_FILE_NAMES,
    REQUIREMENT_RELATIONS,
    TOP_KEYS,
    TOP_LEVEL_TYPES,
    TYPE_NAMES,
    Metric,
    Requirement,
    Scenario,
)
from scenarios.spec.text import (
    Problems,
    ScenarioError,
    check_name,
    file_label,
    merged,
    read_text,
    read_toml,
    unknown_keys,
)
from scenarios.spec.units import UnitError, in_unit, to_si


def _time_span(step):
    """The largest |t| at which a double still resolves times to MAX_TIME_ULP of ``step``."""
    return 2.0 ** (math.floor(math.log2(MAX_TIME_ULP * step)) + 53)


def parse_quantity(source, key, value, dimension):
    try:
        return to_si(value, dimension)
    except UnitError as exc:
        raise ScenarioError(source, key, str(exc)) from None


def _table(source, key, value):
    if not isinstance(value, dict):
        raise ScenarioError(source, key, f"expected a table, got {TYPE_NAMES.get(type(value), type(value).__name__)}")
    return value


def _text(source, key, value, default=None):
    """A text setting (a table or number where text belongs is refused, naming it)."""
    value = default if value is None else value
    if not isinstance(value, str):
        raise ScenarioError(source, key, f"expected text, got {TYPE_NAMES.get(type(value), type(value).__name__)}"
                            f" {value!r:.60}")
    return value


def _string_list(source, key, value):
    values = [value] if isinstance(value, str) else value
    if not isinstance(values, list) or not values or not all(isinstance(v, str) for v in values):
        raise ScenarioError(source, key, "expected a string or a non-empty list of strings")
    return values


def parse_reference(source, key, value, instances):
    if isinstance(value, str) and value.split(".", 1)[0] in instances and "." in value:
        return value     # a declared instance (an invalid instance name is told at its [fmus] table)
    if not isinstance(value, str) or not re.fullmatch(r"[A-Za-z_]\w*\.[\w\[\]\.]+", value, re.ASCII):
        raise ScenarioError(source, key, f"expected 'instance.variable', got {value!r}")
    instance = value.split(".", 1)[0]
    if instance not in instances:
        near = difflib.get_close_matches(instance, list(instances), 1, 0.6)
        hint = f"did you mean {near[0]!r}? " if near else ""
        raise ScenarioError(source, key, f"unknown FMU instance {instance!r}; {hint}declared: {', '.join(instances)}")
    return value


def parse(text, source="<string>", overrides=None):
    """Scenario from TOML text; ``overrides`` replaces top-level keys (e.g. the CI's
    shorter stop_time; tables merge key by key). Every problem in the file is reported
    at once, in one ScenarioError."""
    return parse_data(read_toml(text, source), source, overrides)


def parse_data(data, source="<string>", overrides=None):
    """parse for data already read (a TOML file's tables, or a Scenario's fields as_data)."""
    needs = ("a scenario needs stop_time, step, one [fmus.<instance>] table per FMU and [[connections]] "
             "(example: scenarios/files/telescope_slew.toml)")
    if not data:
        raise ScenarioError(source, "file", f"empty (no TOML keys): {needs}")
    written_sweep = data.get("sweep")
    data = merged(data, overrides)
    if "scenario" in data and "fmus" not in data:    # not a wall of unknown keys: the other kind of file
        raise ScenarioError(source, "file", "this is a campaign file (it names a scenario and has no [fmus]), "
                                            "not a scenario: run it with `movingbase campaign FILE` "
                                            "(movingbase.campaign)")
    problems = Problems()
    for key, problem in unknown_keys(set(data) - TOP_KEYS, sorted(TOP_KEYS)):
        problems.errors.append(ScenarioError(source, key, problem))
    for key, types in TOP_LEVEL_TYPES.items():
        if key in data and (not isinstance(data[key], types) or isinstance(data[key], bool)):
            what = KEYS[key][0] if key in KEYS else " or ".join(TYPE_NAMES[t] for t in types)
            got = TYPE_NAMES.get(type(data[key]), type(data[key]).__name__)
            problems.errors.append(ScenarioError(source, key, f"expected {what}, got {got} {data[key]!r:.60}"))
    for key in ("stop_time", "step", "fmus", "connections"):
        if key not in data:
            problems.errors.append(ScenarioError(source, key, f"missing; {needs}"))
    problems.raise_any()     # the parts below rely on the keys' presence and types

    start, stop, step, steps, grid_ok = 0.0, math.inf, 1.0, 1, False
    with problems.part():       # the time grid; the checks against it below use it only if it holds
        start = parse_quantity(source, "start_time", data.get("start_time", 0.0), "s")
        stop = parse_quantity(source, "stop_time", data["stop_time"], "s")
        step = parse_quantity(source, "step", data["step"], "s")
        if not step > 0:
            raise ScenarioError(source, "step", f"must be positive, got {data['step']!r}")
        if not stop > start:
            raise ScenarioError(source, "stop_time", f"must be after start_time ({start} s)")
        resolution = math.ulp(max(abs(start), abs(stop)))
        if resolution > MAX_TIME_ULP * step:
            raise ScenarioError(source, "start_time" if abs(start) > abs(stop) else "stop_time",
                                f"at t = {max(abs(start), abs(stop)):.6g} s a time is resolved only to "
                                f"{resolution:.3g} s, "
                                f"too coarse for step {data['step']!r}: the time grid would be uneven; keep the times "
                                f"within {_time_span(step):.3g} s of 0 (an epoch belongs in a parameter such as "
                                "utc_start)")
        if abs((stop - start) / step - round((stop - start) / step)) > 1e-9 * max(1.0, (stop - start) / step):
            steps = (stop - start) / step
            nearest = " and ".join(f"{start + n * step:.12g} s" for n in sorted({max(1, int(steps)), int(steps) + 1}))
            raise ScenarioError(source, "stop_time", f"{data['stop_time']!r} is not a whole number of steps of "
                                f"{data['step']!r} after start_time ({steps:.6g} steps); nearest valid stop times: "
                                f"{nearest}")
        if round((stop - start) / step) < 1:    # within the whole-number tolerance of 0 steps
            raise ScenarioError(source, "stop_time", f"{data['stop_time']!r} is less than one step ({data['step']!r}) "
                                "after start_time: no step would run; the first valid stop time is "
                                f"{start + step:.12g} s")
        steps, grid_ok = round((stop - start) / step), True
    if not grid_ok:         # what failed is told; nothing below is measured against it
        start, stop, step, steps = 0.0, math.inf, 1.0, 1
    master = data.get("master", "jacobi")
    if master not in MASTERS:
        problems.errors.append(ScenarioError(source, "master", f"unknown master {master!r}; choose one of {MASTERS}"))
    extrapolation = data.get("extrapolation", "none")
    if extrapolation not in EXTRAPOLATIONS:
        problems.errors.append(ScenarioError(source, "extrapolation", f"unknown {extrapolation!r}; choose one of "
                                             f"{EXTRAPOLATIONS}"))
    name = data.get("name", pathlib.Path(source).stem)   # the file's own name needs no check: it is one
    if "name" in data:
        with problems.part():
            check_name(source, "name", name)

    fmus, parameters, implementations, versions = {}, {}, {}, {}
    if not data["fmus"]:
        problems.errors.append(ScenarioError(source, "fmus", f"no FMU instance: {needs}"))
    for instance, table in data["fmus"].items():
        key = f"fmus.{instance}"
        with problems.part():
            if not INSTANCE_NAME.fullmatch(instance):
                bad = sorted({c for c in instance if not re.fullmatch(r"\w", c, re.ASCII)})
                raise ScenarioError(source, key, f"instance name {instance!r} "
                                    f"{'holds ' + ', '.join(map(repr, bad)) if bad else 'is not valid'}: an instance "
                                    "name takes ASCII letters, digits and _ (not starting with a digit), at most 64")
        fmus[instance] = None        # declared: references to it are not also reported as unknown
        with problems.part():
            table = _table(source, key, table)
            for extra, problem in unknown_keys(set(table) - {"fmu", "implementation", "fmi_version", "parameters"},
                                               ["fmu", "implementation", "fmi_version", "parameters"]):
                problems.errors.append(ScenarioError(source, f"{key}.{extra}", problem))
            implementations[instance] = _text(source, f"{key}.implementation", table.get("implementation"),
                                              IMPLEMENTATIONS[0])
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
            if "fmu" not in table:
                raise ScenarioError(source, f"{key}.fmu", f"missing: which of the kit's FMUs this instance is "
                                    f"({', '.join(FMU_KEYS)})")
            fmu = _text(source, f"{key}.fmu", table.get("fmu"), "")
            if fmu not in FMU_KEYS:
                near = difflib.get_close_matches(fmu, list(FMU_KEYS), 1, 0.6)
                hint = f"did you mean {near[0]!r}? " if near else ""
                raise ScenarioError(source, f"{key}.fmu", f"unknown FMU {table.get('fmu')!r}; {hint}choose one of "
                                    f"{', '.join(FMU_KEYS)}")
            fmus[instance] = fmu
            parameters[instance] = dict(_table(source, f"{key}.parameters", table.get("parameters", {})))

    connections = []
    for i, conn in enumerate(data["connections"]):
        key = f"connections[{i}]"
        with problems.part():
            conn = _table(source, key, conn)
            if set(conn) != {"from", "to"}:
                raise ScenarioError(source, key, "a connection has exactly the keys 'from' and 'to'")
            targets = [parse_reference(source, f"{key}.to", t, fmus) for t in _string_list(source, f"{key}.to",
                                                                                           conn["to"])]
            connections.append((parse_reference(source, f"{key}.from", conn["from"], fmus), targets))

    interval, metric_interval, recorded, last_record = step, None, [], stop
    with problems.part():
        record = data.get("record", {})
        record_keys = ["interval", "variables", "metric_interval"]
        for extra, problem in unknown_keys(set(record) - set(record_keys), record_keys):
            problems.errors.append(ScenarioError(source, f"record.{extra}", problem))
        interval = parse_quantity(source, "record.interval", record.get("interval", data["step"]), "s")
        ratio = interval / step
        if grid_ok and (interval < step or abs(ratio - round(ratio)) > 1e-9 * ratio):
            raise ScenarioError(source, "record.interval", f"{record.get('interval', data['step'])!r} must be a whole "
                                f"multiple of step ({data['step']!r})")
        if "metric_interval" in record:
            metric_interval = parse_quantity(source, "record.metric_interval", record["metric_interval"], "s")
            steps_per, per_record = metric_interval / step, interval / metric_interval
            if grid_ok and (metric_interval < step or abs(steps_per - round(steps_per)) > 1e-9 * steps_per
                            or per_record < 1 - 1e-9 or abs(per_record - round(per_record)) > 1e-9 * per_record):
                raise ScenarioError(source, "record.metric_interval", f"{record['metric_interval']!r} must be a whole "
                                    f"multiple of step ({data['step']!r}) that divides record.interval "
                                    f"({record.get('interval', data['step'])!r})")
        every = max(1, int(round((metric_interval or interval) / step)))   # the rows the metrics read
        last_record = start + (steps // every) * every * step if grid_ok else math.inf
        recorded = [parse_reference(source, "record.variables", v, fmus)
                    for v in _string_list(source, "record.variables", record.get("variables", []))] \
            if record.get("variables") else []

    metrics, named = [], {}
    for i, metric in enumerate(data.get("metrics", [])):
        key = f"metrics[{i}]"
        with problems.part():
            metric = dict(_table(source, key, metric))
            kind = metric.pop("kind", None)
            if not isinstance(kind, str) or kind not in METRIC_KINDS:
                raise ScenarioError(source, f"{key}.kind", f"unknown metric kind {kind!r}; choose one of "
                                    f"{', '.join(METRIC_KINDS)}")
            name_ = _text(source, f"{key}.name", metric.pop("name", None), kind)
            bad = sorted({c for c in name_ if c in NOT_IN_FILE_NAMES or not c.isprintable()})
            if bad or not name_.strip() or name_.startswith(".") or len(name_) > 100:
                why = f"holds {', '.join(map(repr, bad))}" if bad else "is empty" if not name_.strip() else \
                    "starts with ." if name_.startswith(".") else f"is {len(name_)} characters long (at most 100)"
                raise ScenarioError(source, f"{key}.name", f"{name_[:60]!r} {why}: a metric's name also names its "
                                    "chart file and a column of the report's table")
            label = name_.replace(" ", "_").casefold()   # its chart: <name>_vs_time.png, one on macOS and Windows
            if label in named:
                j, other = named[label]
                same = "is also the name of" if name_ == other else "would write the chart file of"
                raise ScenarioError(source, f"{key}.name", f"{name_!r} {same} metrics[{j}] ({other!r}); metric "
                                    "names are the columns of the results: give each its own")
            named[label] = (i, name_)
            metric_start = parse_quantity(source, f"{key}.from", metric.get("from", "0 s"), "s")
            if metric_start >= stop or metric_start > last_record + 1e-9 * step:
                where = f"at or after stop_time ({stop:g} s)" if metric_start >= stop else \
                    f"after the last recorded time ({last_record:g} s)"
                raise ScenarioError(source, f"{key}.from",
                                    f"{metric.get('from', '0 s')!r} lies {where}: the metric would "
                                    "count nothing")
            metric.pop("from", None)
            for required in METRIC_KINDS[kind]:
                if required not in metric:
                    raise ScenarioError(source, f"{key}.{required}", f"missing (metric kind {kind!r})")
            for extra, problem in unknown_keys(set(metric) - set(METRIC_KINDS[kind]),
                                               ["kind", "name", "from", *METRIC_KINDS[kind]]):
                raise ScenarioError(source, f"{key}.{extra}", problem)
            for arg, value in metric.items():
                if kind == "base_effect":
                    if not isinstance(value, str) or value not in fmus:
                        raise ScenarioError(source, f"{key}.{arg}", f"unknown FMU instance {value!r}")
                else:
                    parse_reference(source, f"{key}.{arg}", value, fmus)
            metrics.append(Metric(name_, kind, metric, metric_start))

    sweep = None
    if "sweep" in data:
        table = data["sweep"]
        with problems.part():
            if set(table) != {"parameter", "values"}:
                raise ScenarioError(source, "sweep", "a sweep has exactly the keys 'parameter' and 'values'")
            if not isinstance(table["values"], list) or not table["values"]:
                raise ScenarioError(source, "sweep.values", "expected a non-empty list")
            for i, value in enumerate(table["values"]):
                if not isinstance(value, (str, int, float)):
                    raise ScenarioError(source, f"sweep.values[{i}]", f"expected a number or a quantity, got "
                                        f"{TYPE_NAMES.get(type(value), type(value).__name__)} {value!r:.60}")
            labels = {}
            for i, value in enumerate(table["values"]):
                label = file_label(value).casefold()   # one file on a case-insensitive disk (macOS, Windows)
                if label in labels:
                    j = labels[label]
                    what = "repeats" if value == table["values"][j] else \
                        f"would write the same files ({file_label(value)[:60]}.npz) as"
                    raise ScenarioError(source, f"sweep.values[{i}]", f"{value!r:.80} {what} sweep.values[{j}] "
                                        f"({table['values'][j]!r:.80}): each value runs once, under its own name "
                                        "(the first 100 characters, letters compared regardless of case)")
                labels[label] = i
            sweep = (parse_reference(source, "sweep.parameter", table["parameter"], fmus), table["values"])
    ci = data.get("ci", {})
    for extra, problem in unknown_keys(set(ci) - TOP_KEYS, sorted(TOP_KEYS)):
        problems.errors.append(ScenarioError(source, f"ci.{extra}", problem))
    ci_fmus = ci.get("fmus", {})
    with problems.part():
        for inst in _table(source, "ci.fmus", ci_fmus):   # [ci] changes the file's instances; a typo adds none
            if inst not in data["fmus"]:
                near = difflib.get_close_matches(str(inst), list(data["fmus"]), 1, 0.6)
                raise ScenarioError(source, f"ci.fmus.{inst}", f"no instance {inst!r} in [fmus]; "
                                    f"{f'did you mean {near[0]!r}? ' if near else ''}[ci] changes the settings "
                                    f"of the file's instances ({', '.join(data['fmus'])}), it adds none")
    tolerance = None
    if "fidelity_tolerance" in data:
        with problems.part():
            tolerance = parse_quantity(source, "fidelity_tolerance", data["fidelity_tolerance"], "N")
            if tolerance < 0:     # no level is within it (choosing one ended in StopIteration)
                raise ScenarioError(source, "fidelity_tolerance", f"{data['fidelity_tolerance']!r} is negative: "
                                    "a leg-force error is at least 0 N (0 N: the full model)")
    for inst, params in parameters.items():
        if params.get("fidelity") == "auto" and (fmus[inst] != "hexapod_plant" or "fidelity_tolerance" not in data):
            problems.errors.append(ScenarioError(source, f"fmus.{inst}.parameters.fidelity",
                                   '"auto" needs a hexapod_plant and a top-level fidelity_tolerance (a force)'))
    requirements = []
    if "requirements" in data:
        with problems.part():
            replaced = data.get("sweep") != written_sweep   # set= or [ci] gave other runs: those named may be gone
            requirements = [parse_requirement(source, name_, written, metrics, sweep, replaced)
                            for name_, written in data["requirements"].items()]
    problems.raise_any()
    return Scenario(source, name, data.get("description", ""), start, stop, step, master, extrapolation,
                    fmus, parameters, connections, interval, recorded, metrics, sweep, ci, tolerance,
                    implementations=implementations, fmi_versions=versions, requirements=requirements,
                    metric_interval=metric_interval)


_RELATION = re.compile(r"^\s*(<=|>=|<|>)\s*(.*)$")


def parse_requirement(source, name, written, metrics, sweep, sweep_replaced=False):
    """A Requirement from ``"pose error peak" = "< 10 µm"`` (or a table with ``limit`` and
    ``runs``): the metric and its number named, the limit in the number's unit; a
    ScenarioError naming an unknown metric or number, relation, unit or run. A run it names
    that a sweep replaced by ``set=`` or ``[ci]`` (``sweep_replaced``) no longer has is not an
    error: the requirement holds for the runs it names that are there."""
    key = f"requirements.{name!r}" if " " in name else f"requirements.{name}"
    numbers = {f"{m.name} {number}": (m.name, number, unit) for m in metrics
               for number, unit in METRIC_NUMBERS[m.kind].items()}
    if name not in numbers:
        near = difflib.get_close_matches(name, list(numbers), 1, 0.6)
        raise ScenarioError(source, key, f"no metric number {name!r}; "
                            + (f"did you mean {near[0]!r}? " if near else "")
                            + f"write '<metric name> <number>', one of: {', '.join(numbers) or 'none (no metrics)'}")
    metric, number, unit = numbers[name]
    runs = None
    limit = written
    if isinstance(written, dict):
        for extra, problem in unknown_keys(set(written) - {"limit", "runs"}, ["limit", "runs"]):
            raise ScenarioError(source, f"{key}.{extra}", problem)
        if "limit" not in written:
            raise ScenarioError(source, f"{key}.limit", 'missing: the spec, e.g. limit = "< 10 µm"')
        limit, runs = written["limit"], written.get("runs")
        labels = [file_label(v) for v in sweep[1]] if sweep else ["run"]
        if not isinstance(runs, list) or not runs:
            raise ScenarioError(source, f"{key}.runs", f"expected a non-empty list of the runs it holds for, of: "
                                f"{', '.join(labels)}")
        unknown = [r for r in runs if file_label(r) not in labels]
        if unknown and not sweep_replaced:
            raise ScenarioError(source, f"{key}.runs", f"no run {unknown[0]!r}; the runs: {', '.join(labels)}")
        runs = tuple(file_label(r) for r in runs)
    match = _RELATION.match(limit) if isinstance(limit, str) else None
    if not match:
        raise ScenarioError(source, key, f"expected a relation and a limit such as \"< 10 {unit}\" "
                            f"({', '.join(REQUIREMENT_RELATIONS)}), got {limit!r:.60}")
    try:
        value = in_unit(match[2], unit)
    except UnitError as exc:
        raise ScenarioError(source, key, str(exc)) from None
    return Requirement(name, metric, number, match[1], value, unit, runs, written)


def load(path, overrides=None, told_as=None):
    """Scenario from a TOML file; a missing path, a directory, a device, a huge file or
    a file that is not UTF-8 text is refused with what was expected. ``told_as``
    (sources_of) tells a problem in a key ``overrides`` replaced where its value came from."""
    try:
        return parse(read_text(path), str(pathlib.Path(path)), overrides)
    except ScenarioError as exc:
        raise with_sources(exc, told_as) from None


def sources_of(overrides, note):
    """{key path: note} of every value ``overrides`` sets ("fmus.base.parameters.lever_arm"),
    for with_sources."""
    out = {}
    for key, value in (overrides or {}).items():
        if isinstance(value, dict) and value:
            out.update({f"{key}.{k}": v for k, v in sources_of(value, note).items()})
        else:
            out[str(key)] = note
    return out


def with_sources(error, sources):
    """``error`` with each problem in a key that ``sources`` names followed by where its
    value came from (a stop_time off the grid in [ci], not in the file's top level)."""
    if not sources:
        return error
    errors = []
    for source, key, problem in error.problems:
        note = next((n for path, n in sources.items() if key == path or key.startswith((path + ".", path + "["))), None)
        errors.append(ScenarioError(source, key, problem if note is None else f"{problem} ({note})"))
    return ScenarioError.joined(errors)


# ------------------------------------------------------------------- binding to the FMUs
