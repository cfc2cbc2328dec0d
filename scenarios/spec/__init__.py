"""Scenario files: TOML, parsed and checked before anything runs.

A scenario names FMUs (by the kit's FMU names) with their parameters, the connections
between them, the time grid, the master algorithm, what to record, the metrics to report
and optionally one parameter to sweep. Every error points at the file, the key and the
problem. Quantities may carry units ("1 ms", "30 deg"); they are converted to SI here,
checked against the unit the FMU declares. The format: docs/scenarios.md and the
scenario-file reference generated from KEYS below (docs/generate.py).

A parameter written "@inst.var" takes the value of that output of another FMU at the
start time (e.g. the plant's initial pose from the telescope's reference pose).

Two stages: ``load`` checks the file's own structure (also: stop_time a whole number of
steps, metrics that count something); ``bind`` checks it against the FMUs' model
descriptions (variables exist, causalities, sizes and units of connections, every input
fed by exactly one source, values within the variables' declared min/max) and what the
models refuse that min/max cannot say (the telescope profile over the run). Both run
before the master starts.
"""
import contextlib
import dataclasses
import difflib
import math
import pathlib
import re
import tomllib
from dataclasses import dataclass, field
from datetime import datetime, timezone

import numpy as np

from fmu_src.catalogue import ALL, CONTROL_LOOPS, FEEDTHROUGH, LOOP_SENSORS, OPTIONAL_INPUTS
from fmu_src.catalogue import KEYS as FMU_KEYS
from plant.errors import InvalidInputError
from plant.telescope import model as telescope
from scenarios.spec.units import UNITS, UnitError, split, to_si

# per instance: the native C FMU (no Python in the host) or the pythonfmu one; equal results
IMPLEMENTATIONS = ("native", "python")
# per instance: the FMI version of the FMU (3: the native FMU's FMI 3.0 build; equal results)
FMI_VERSIONS = (2, 3)
MASTERS = ("jacobi", "gauss-seidel")
EXTRAPOLATIONS = ("none", "linear", "derivatives")
METRIC_KINDS = {  # kind -> required keys
    "leg_tracking": ("measured", "reference_pose"),
    "pose_tracking": ("measured", "reference"),
    "tracking": ("measured", "reference"),
    "peak": ("variable",),
    "base_effect": ("base", "reference"),
}
_POSE = ("m", "m", "m", "rad", "rad", "rad")
# kind -> {argument: the unit of each of its values (one string: of every value)}: what the
# metric's own unit (metrics.py: µm, µrad, kN) takes its variables to be
METRIC_RESULT_UNITS = {"leg_tracking": "µm", "pose_tracking": "µm and µrad", "tracking": "µm", "peak": "kN"}
METRIC_UNITS = {
    "leg_tracking": {"measured": "m", "reference_pose": _POSE},
    "pose_tracking": {"measured": _POSE, "reference": _POSE},
    "tracking": {"measured": "m", "reference": "m"},
    "peak": {"variable": "N"},
}
_TOP_KEYS = {"name", "description", "start_time", "stop_time", "step", "master", "extrapolation",
             "fmus", "connections", "record", "metrics", "sweep", "ci", "fidelity_tolerance"}
_REQUIRED = "required"
# Every key of a scenario file: key -> (what it takes, default, meaning), in the order the
# reference lists them. The scenario-file reference is generated from this table and the
# constants above (docs/generate.py); tests/test_docs.py holds it to what parse() accepts,
# refuses and fills in, so a key added to the checker without a line here fails a test.
KEYS = {
    "name": ("string", "the file's name without .toml", "report title: letters, digits, _ . - (the output "
             "folder is named after the file run; the file's own name is taken as it is)"),
    "description": ("string", "empty", "text under the report's title"),
    "start_time": ("time", "0 s", "start of the time grid"),
    "stop_time": ("time", _REQUIRED, "end of the time grid: a whole number of steps after start_time"),
    "step": ("time", _REQUIRED, "communication step of the master"),
    "master": (" or ".join(f'"{m}"' for m in MASTERS), f'"{MASTERS[0]}"',
               "Jacobi (every FMU steps on the others' outputs of the last step) or Gauss-Seidel "
               "(in the order of the connection graph; a loop starts at its plant)"),
    "extrapolation": (" or ".join(f'"{e}"' for e in EXTRAPOLATIONS), f'"{EXTRAPOLATIONS[0]}"',
                      "inputs from FMUs not yet stepped: held, extrapolated linearly, or by the output "
                      "derivatives of FMI 3 FMUs that give them (the telescope with fmi_version = 3; "
                      "linearly where a source gives none)"),
    "fidelity_tolerance": ("force", "none", 'with a hexapod_plant fidelity = "auto": the cheapest fidelity '
                           "level whose leg-force error along the scene stays within it"),
    "fmus.<instance>.fmu": (", ".join(FMU_KEYS), _REQUIRED, "which of the kit's FMUs this instance is"),
    "fmus.<instance>.implementation": (" or ".join(f'"{i}"' for i in IMPLEMENTATIONS), f'"{IMPLEMENTATIONS[0]}"',
                                       "the native C FMU (no Python in the host) or the pythonfmu one"),
    "fmus.<instance>.parameters": ("table of values", "the FMU's start values",
                                   'values with units ("30 deg"), enumeration names ("slew"), lists for '
                                   'vectors, or "@instance.output" (that output at the start time)'),
    "connections[].from": ('"instance.output"', _REQUIRED, "the output; a vector connects element-wise"),
    "connections[].to": ('"instance.input" or a list of them', _REQUIRED,
                         "the inputs it feeds; every input has exactly one source"),
    "record.interval": ("time", "step", "recording interval: a whole multiple of step"),
    "record.variables": ('list of "instance.variable"', "none", "what the records (npz, CSV on request) hold"),
    "metrics[].kind": (", ".join(METRIC_KINDS), _REQUIRED, "what the metric computes (table below)"),
    "metrics[].name": ("string", "the kind", "the metric's name in the report and metrics.json"),
    "metrics[].from": ("time", "0 s", "the metric counts from this time on (after settling)"),
    "sweep.parameter": ('"instance.parameter"', _REQUIRED, "the parameter to sweep: one run per value"),
    "sweep.values": ("non-empty list of values", _REQUIRED, "its values, written as in parameters"),
    "ci": ("table of top-level keys", "none", "what replaces them in the short CI run (--ci)"),
}
# the TOML types each top-level key takes (checked before its value: a table where text
# belongs is told as such); what it takes in words comes from KEYS
TOP_LEVEL_TYPES = {"name": (str,), "description": (str,), "start_time": (int, float, str),
                   "stop_time": (int, float, str), "step": (int, float, str), "master": (str,),
                   "extrapolation": (str,), "fidelity_tolerance": (int, float, str), "fmus": (dict,),
                   "connections": (list,), "record": (dict,), "metrics": (list,), "sweep": (dict,), "ci": (dict,)}
_TYPE_NAMES = {str: "text", int: "integer", float: "number", dict: "table", list: "array", bool: "true/false"}
PLAIN_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.-]{0,99}")     # names that become file or folder names
INSTANCE_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]{0,63}")
_NOT_IN_FILE_NAMES = set('/\\:*?"<>|')    # nor in a Markdown table's cell ('|')
MAX_FILE_BYTES = 1 << 20       # a scenario or campaign file larger than this is not one
MAX_DEPTH = 8                  # tables and arrays nested deeper than this are no scenario's
CHECK_POINTS = 100_001        # times at which a model's profile is checked over a run, at most
MAX_INTEGER = 2 ** 53          # larger integer literals are no setting's (and lose precision as floats)
MAX_TIME_ULP = 1e-3            # a time's float resolution must stay below this fraction of the step


class ScenarioError(ValueError):
    """Problems in a scenario file; the message says file, key and problem, one line each
    (every problem found in the file, not only the first)."""

    def __init__(self, source, key, problem):
        super().__init__(f"{shown(source)}: {key}: {problem}")
        self.problems = [(source, key, problem)]

    @classmethod
    def joined(cls, errors):
        """One error carrying every problem of ``errors``, in order."""
        error = cls(*errors[0].problems[0])
        error.problems = [p for e in errors for p in e.problems]
        error.args = ("\n".join(f"{shown(s)}: {k}: {p}" for s, k, p in error.problems),)
        return error


def shown(text, most=160):
    """``text`` (a path) as a message shows it: whole up to ``most`` characters, else its
    start and end around an ellipsis (a 4,000-character path was echoed whole, each line);
    the error's ``problems`` keep it whole."""
    text = str(text)
    return text if len(text) <= most else f"{text[:most // 3]}...{text[-(most - most // 3 - 3):]}"


class _Problems:
    """Collects the problems of one file: each part is checked on its own, all are told."""

    def __init__(self, error=ScenarioError):
        self.errors = []
        self.error = error

    @contextlib.contextmanager
    def part(self):
        try:
            yield
        except self.error as exc:
            self.errors.append(exc)

    def raise_any(self):
        if self.errors:
            raise self.error.joined(self.errors)


def unknown_keys(keys, allowed):
    """'unknown key 'stop_tme'; did you mean 'stop_time'? allowed: ...' per key."""
    out = []
    for key in sorted(keys, key=str):
        near = difflib.get_close_matches(str(key), [str(a) for a in allowed], 1, 0.6)
        hint = f"did you mean {near[0]!r}? " if near else ""
        out.append((key, f"unknown key; {hint}allowed: {', '.join(map(str, allowed))}"))
    return out


def check_name(source, key, value, error=ScenarioError):
    """A name that becomes a file or folder name: text of letters, digits, _ . - (not
    starting with . or -), at most 100 characters; anything else is refused, naming it."""
    if not isinstance(value, str):
        raise error(source, key, f"expected text, got {_TYPE_NAMES.get(type(value), type(value).__name__)}")
    if not PLAIN_NAME.fullmatch(value):
        bad = sorted({c for c in value if not re.fullmatch(r"[A-Za-z0-9_.-]", c)})
        why = (f"is {len(value)} characters long (at most 100)" if len(value) > 100 else
               f"holds {', '.join(map(repr, bad))}" if bad else "starts with . or -" if value else "is empty")
        raise error(source, key, f"{value[:60]!r}{'...' if len(value) > 60 else ''} {why}: a name is also a folder "
                    "name, so it takes letters, digits, _ . - only (not a path)")
    return value


def file_label(value):
    """The label of a run made from a value as written (a sweep value): also a file name,
    so every character but letters, digits and ' _.,+=-' becomes '_' ("10 N/m" -> "10 N_m")."""
    text = value if isinstance(value, str) else repr(value)
    return re.sub(r"[^A-Za-z0-9 _.,+=-]", "_", text)[:100] or "_"


def read_toml(text, source, error=ScenarioError):
    """TOML text to data, or ``error`` naming what is wrong: a syntax error, nesting
    deeper than MAX_DEPTH, an integer beyond MAX_INTEGER (checked before any use)."""
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise error(source, "TOML", str(exc)) from None
    except RecursionError:
        raise error(source, "TOML", f"nested deeper than any scenario (at most {MAX_DEPTH} levels)") from None
    except ValueError as exc:       # an integer literal longer than Python converts
        raise error(source, "TOML", f"a value cannot be read: {exc}") from None
    stack = [(data, "", 0)]
    while stack:
        value, where, depth = stack.pop()
        if depth > MAX_DEPTH:
            raise error(source, where, f"nested {depth} levels deep; a scenario nests at most {MAX_DEPTH}")
        if isinstance(value, dict):
            stack.extend((v, f"{where}.{k}" if where else str(k), depth + 1) for k, v in value.items())
        elif isinstance(value, list):
            stack.extend((v, f"{where}[{i}]", depth + 1) for i, v in enumerate(value))
        elif isinstance(value, int) and not isinstance(value, bool) and abs(value) > MAX_INTEGER:
            raise error(source, where, f"integer {str(value)[:20]}... ({len(str(abs(value)))} digits) is too "
                        f"large (at most 2^53)")
    return data


def read_text(path, error=ScenarioError, what="scenario"):
    """A TOML file's text; ``error`` for a directory, a missing file, a device or pipe,
    a file over MAX_FILE_BYTES, a binary, UTF-16 or otherwise non-UTF-8 file."""
    path = pathlib.Path(path)
    if path.is_dir():
        inside = sorted(p.name for p in path.glob("*.toml"))
        hint = f"; it holds {', '.join(inside)}" if inside else ""
        raise error(str(path), "file", f"is a directory, not a {what} file (.toml){hint}")
    if not path.exists():
        raise error(str(path), "file", "does not exist")
    if not path.is_file():
        raise error(str(path), "file", f"is not a regular file (a device or a pipe), not a {what} file")
    try:
        with open(path, "rb") as file:
            data = file.read(MAX_FILE_BYTES + 1)
    except OSError as exc:
        raise error(str(path), "file", f"cannot be read: {exc.strerror}") from None
    if len(data) > MAX_FILE_BYTES:
        raise error(str(path), "file", f"is larger than {MAX_FILE_BYTES >> 20} MiB: not a {what} file")
    if _utf16(data):
        raise error(str(path), "file", f"is UTF-16 text; save it as UTF-8 (a {what} is a TOML file in UTF-8)")
    if b"\0" in data:
        raise error(str(path), "file", f"is a binary file (NUL byte at offset {data.find(0)}), not a TOML {what}")
    try:
        return data.decode("utf-8-sig")   # a leading BOM (some editors write one) is not TOML
    except UnicodeDecodeError as exc:
        raise error(str(path), "file", f"is not UTF-8 text (byte 0x{data[exc.start]:02x} at offset "
                    f"{exc.start}); a {what} is a TOML file in UTF-8") from None


def _utf16(data):
    """Whether bytes are UTF-16 text (a BOM, or the NUL high bytes of ASCII) that decodes."""
    if not (data[:2] in (b"\xff\xfe", b"\xfe\xff") or (len(data) >= 4 and (data[1] == data[3] == 0 or
                                                                           data[0] == data[2] == 0))):
        return False
    try:
        text = data.decode("utf-16" if data[:2] in (b"\xff\xfe", b"\xfe\xff") else
                           "utf-16-le" if data[1] == 0 else "utf-16-be")
    except UnicodeDecodeError:
        return False
    return all(c.isprintable() or c in "\r\n\t" for c in text.lstrip("\ufeff"))


def merged(data, overrides):
    """data with ``overrides`` laid over it, tables merged key by key (a [ci.fmus.plant]
    table changes that instance's keys only, not the other instances)."""
    out = dict(data)
    for key, value in (overrides or {}).items():
        out[key] = merged(out[key], value) if isinstance(value, dict) and isinstance(out.get(key), dict) else value
    return out


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
    short: bool = False         # its [ci] settings applied: a run cut short on purpose, not motion_unfinished


def _time_span(step):
    """The largest |t| at which a double still resolves times to MAX_TIME_ULP of ``step``."""
    return 2.0 ** (math.floor(math.log2(MAX_TIME_ULP * step)) + 53)


def _quantity(source, key, value, dimension):
    try:
        return to_si(value, dimension)
    except UnitError as exc:
        raise ScenarioError(source, key, str(exc)) from None


def _table(source, key, value):
    if not isinstance(value, dict):
        raise ScenarioError(source, key, f"expected a table, got {_TYPE_NAMES.get(type(value), type(value).__name__)}")
    return value


def _text(source, key, value, default=None):
    """A text setting (a table or number where text belongs is refused, naming it)."""
    value = default if value is None else value
    if not isinstance(value, str):
        raise ScenarioError(source, key, f"expected text, got {_TYPE_NAMES.get(type(value), type(value).__name__)}"
                            f" {value!r:.60}")
    return value


def _string_list(source, key, value):
    values = [value] if isinstance(value, str) else value
    if not isinstance(values, list) or not values or not all(isinstance(v, str) for v in values):
        raise ScenarioError(source, key, "expected a string or a non-empty list of strings")
    return values


def _reference(source, key, value, instances):
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
    data = merged(data, overrides)
    if "scenario" in data and "fmus" not in data:    # not a wall of unknown keys: the other kind of file
        raise ScenarioError(source, "file", "this is a campaign file (it names a scenario and has no [fmus]), "
                                            "not a scenario: run it with `movingbase campaign FILE` "
                                            "(movingbase.campaign)")
    problems = _Problems()
    for key, problem in unknown_keys(set(data) - _TOP_KEYS, sorted(_TOP_KEYS)):
        problems.errors.append(ScenarioError(source, key, problem))
    for key, types in TOP_LEVEL_TYPES.items():
        if key in data and (not isinstance(data[key], types) or isinstance(data[key], bool)):
            what = KEYS[key][0] if key in KEYS else " or ".join(_TYPE_NAMES[t] for t in types)
            got = _TYPE_NAMES.get(type(data[key]), type(data[key]).__name__)
            problems.errors.append(ScenarioError(source, key, f"expected {what}, got {got} {data[key]!r:.60}"))
    for key in ("stop_time", "step", "fmus", "connections"):
        if key not in data:
            problems.errors.append(ScenarioError(source, key, f"missing; {needs}"))
    problems.raise_any()     # the parts below rely on the keys' presence and types

    start, stop, step, steps, grid_ok = 0.0, math.inf, 1.0, 1, False
    with problems.part():       # the time grid; the checks against it below use it only if it holds
        start = _quantity(source, "start_time", data.get("start_time", 0.0), "s")
        stop = _quantity(source, "stop_time", data["stop_time"], "s")
        step = _quantity(source, "step", data["step"], "s")
        if not step > 0:
            raise ScenarioError(source, "step", f"must be positive, got {data['step']!r}")
        if not stop > start:
            raise ScenarioError(source, "stop_time", f"must be after start_time ({start} s)")
        resolution = math.ulp(max(abs(start), abs(stop)))
        if resolution > MAX_TIME_ULP * step:
            raise ScenarioError(source, "start_time" if abs(start) > abs(stop) else "stop_time",
                                f"at t = {max(abs(start), abs(stop)):.6g} s a time is resolved only to {resolution:.3g} s, "
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
                                f"after start_time: no step would run; the first valid stop time is {start + step:.12g} s")
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
            targets = [_reference(source, f"{key}.to", t, fmus) for t in _string_list(source, f"{key}.to", conn["to"])]
            connections.append((_reference(source, f"{key}.from", conn["from"], fmus), targets))

    interval, recorded, last_record = step, [], stop
    with problems.part():
        record = data.get("record", {})
        for extra, problem in unknown_keys(set(record) - {"interval", "variables"}, ["interval", "variables"]):
            problems.errors.append(ScenarioError(source, f"record.{extra}", problem))
        interval = _quantity(source, "record.interval", record.get("interval", data["step"]), "s")
        ratio = interval / step
        if grid_ok and (interval < step or abs(ratio - round(ratio)) > 1e-9 * ratio):
            raise ScenarioError(source, "record.interval", f"{record.get('interval', data['step'])!r} must be a whole "
                                f"multiple of step ({data['step']!r})")
        every = max(1, int(round(ratio)))
        last_record = start + (steps // every) * every * step if grid_ok else math.inf
        recorded = [_reference(source, "record.variables", v, fmus)
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
            bad = sorted({c for c in name_ if c in _NOT_IN_FILE_NAMES or not c.isprintable()})
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
            metric_start = _quantity(source, f"{key}.from", metric.get("from", "0 s"), "s")
            if metric_start >= stop or metric_start > last_record + 1e-9 * step:
                where = f"at or after stop_time ({stop:g} s)" if metric_start >= stop else \
                    f"after the last recorded time ({last_record:g} s)"
                raise ScenarioError(source, f"{key}.from", f"{metric.get('from', '0 s')!r} lies {where}: the metric would "
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
                    _reference(source, f"{key}.{arg}", value, fmus)
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
                                        f"{_TYPE_NAMES.get(type(value), type(value).__name__)} {value!r:.60}")
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
            sweep = (_reference(source, "sweep.parameter", table["parameter"], fmus), table["values"])
    ci = data.get("ci", {})
    for extra, problem in unknown_keys(set(ci) - _TOP_KEYS, sorted(_TOP_KEYS)):
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
            tolerance = _quantity(source, "fidelity_tolerance", data["fidelity_tolerance"], "N")
            if tolerance < 0:     # no level is within it (choosing one ended in StopIteration)
                raise ScenarioError(source, "fidelity_tolerance", f"{data['fidelity_tolerance']!r} is negative: "
                                    "a leg-force error is at least 0 N (0 N: the full model)")
    for inst, params in parameters.items():
        if params.get("fidelity") == "auto" and (fmus[inst] != "hexapod_plant" or "fidelity_tolerance" not in data):
            problems.errors.append(ScenarioError(source, f"fmus.{inst}.parameters.fidelity",
                                   '"auto" needs a hexapod_plant and a top-level fidelity_tolerance (a force)'))
    problems.raise_any()
    return Scenario(source, name, data.get("description", ""), start, stop, step, master, extrapolation,
                    fmus, parameters, connections, interval, recorded, metrics, sweep, ci, tolerance,
                    implementations=implementations, fmi_versions=versions)


def load(path, overrides=None, told_as=None):
    """Scenario from a TOML file; a missing path, a directory, a device, a huge file or
    a file that is not UTF-8 text is refused with what was expected. ``told_as``
    (sources_of) tells a problem in a key ``overrides`` replaced where its value came from."""
    try:
        return parse(read_text(path), str(pathlib.Path(path)), overrides)
    except ScenarioError as exc:
        raise retold(exc, told_as) from None


def sources_of(overrides, note):
    """{key path: note} of every value ``overrides`` sets ("fmus.base.parameters.lever_arm"),
    for retold."""
    out = {}
    for key, value in (overrides or {}).items():
        if isinstance(value, dict) and value:
            out.update({f"{key}.{k}": v for k, v in sources_of(value, note).items()})
        else:
            out[str(key)] = note
    return out


def retold(error, sources):
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
def _enumeration(var):
    """{'slew': 0, ...}: the items an Enumeration variable's type declares ({} for any
    other type: an Integer's description is prose, whose words ('+1 or -1') are no names)."""
    items = var.declaredType.items if var.type == "Enumeration" and var.declaredType else ()
    return {item.name: int(item.value) for item in items}


def expand(md_variables, reference):
    """Scalar names of 'inst.var' (a vector name expands to var[1..n])."""
    instance, name = reference.split(".", 1)
    if name in md_variables:
        return [name]
    names = []
    while f"{name}[{len(names) + 1}]" in md_variables:
        names.append(f"{name}[{len(names) + 1}]")
    return names


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
            _reference(src, key, reference, variables)
        names = expand(variables[inst], reference)
        if not names:
            name = reference.split(".", 1)[1]
            near = difflib.get_close_matches(name, list(dict.fromkeys(n.split("[", 1)[0] for n in variables[inst])), 1,
                                             0.7)
            raise ScenarioError(src, key, f"FMU instance {inst!r} ({scenario.fmus[inst]}) has no variable {name!r}"
                                + (f"; did you mean {near[0]!r}?" if near else ""))
        return inst, [variables[inst][n] for n in names]

    problems = _Problems()
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
        _check_links(src, values)
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
                    _feed_once(src, key, i, f"{source_ref} -> {target}", (s_inst, s.name), (t_inst, t.name),
                               feeders, fed)
    if len(problems.errors) == told:     # wiring is judged on connections that are each valid
        with problems.part():
            _check_wiring(src, scenario, variables, feeders)
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
            _check_metric(src, f"metrics[{i}]", metric, scalars)
    problems.raise_any()     # the checks below need every value bound
    with problems.part():
        check_rates(src, "fmus", scenario, variables, values)
    with problems.part():
        _check_models(src, "fmus", scenario, variables, values)
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
                _check_models(src, key, scenario, variables, swept, {(inst, var.name): item})
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
            "extrapolation": scenario.extrapolation, "fmus": tables if isinstance(scenario.fmus, dict) else scenario.fmus,
            "connections": connections, "metrics": metrics,
            "record": {"interval": plain(scenario.record_interval), "variables": plain(scenario.record)}}
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
    return data


def _check_links(src, values):
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
    problems = _Problems()
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


def _base(reference):
    """("inst", "var") of "inst.var" or "inst.var[k]"."""
    inst, name = reference.split(".", 1)
    return inst, name.split("[", 1)[0]


def _check_wiring(src, scenario, variables, feeders):
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


def _check_metric(src, key, metric, scalars):
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
              "pose_tracking": {"measured": 6, "reference": 6}}.get(metric.kind, {})
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
def _check_models(src, key, scenario, variables, values, written=None):
    """Checks that need several parameters at once, as the models themselves make them
    (today: the telescope's profile over the run), so the FMU does not refuse them at
    t = 0. ``written`` maps (instance, name) to the value as the file wrote it. Every
    instance is checked; their problems are told together."""
    problems = _Problems()
    for inst, fmu in scenario.fmus.items():
        if fmu == "telescope":
            with problems.part():
                _check_telescope(src, key, scenario, inst, variables[inst], values[inst], written or {})
    problems.raise_any()


def _check_telescope(src, key, scenario, inst, md_variables, values, written):
    """The profile evaluated as the FMU will (plant.telescope, the same parameters) on a
    coarse grid over the run; its refusal becomes a ScenarioError naming the settings."""
    if any(isinstance(v, Link) for v in values.values()):
        return   # values known only at the start time

    def setting(name):
        if name in values:
            return values[name]
        var = md_variables[name]
        return int(var.start) if var.type in ("Integer", "Enumeration") else float(var.start)

    def shown(names):
        raws = {**scenario.parameters[inst], **{n: r for (i, n), r in written.items() if i == inst}}
        return ", ".join(f"{n} = {raws[n]!r}" if n in raws else
                         f"{n} = {setting(n):.6g} {md_variables[n].unit or ''} (default)".replace("  ", " ")
                         for n in names)

    profiles = _enumeration(md_variables["profile"])
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
    raw = plain(raw)
    if var.type in ("Integer", "Enumeration"):
        choices = _enumeration(var)
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
        hint = ""
        if _bare(raw) and var.unit:     # the rule (scenarios.units): a bare number is SI
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
