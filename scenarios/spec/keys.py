"""The scenario file's keys and their defaults in one table (KEYS, from which the
scenario-file reference is generated: docs/generate.py), the choices a key takes, the
limits of a file, and the Scenario a file becomes."""
import re
from dataclasses import dataclass, field

from fmu_src.catalogue import KEYS as FMU_KEYS

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
    "pointing": ("measured", "reference"),
}
_POSE = ("m", "m", "m", "rad", "rad", "rad")
# kind -> {argument: the unit of each of its values (one string: of every value)}: what the
# metric's own unit (metrics.py: µm, µrad, kN) takes its variables to be
METRIC_RESULT_UNITS = {"leg_tracking": "µm", "pose_tracking": "µm and µrad", "tracking": "µm", "peak": "kN",
                       "pointing": "arcsec, µm and %"}
METRIC_UNITS = {
    "leg_tracking": {"measured": "m", "reference_pose": _POSE},
    "pose_tracking": {"measured": _POSE, "reference": _POSE},
    "tracking": {"measured": "m", "reference": "m"},
    "peak": {"variable": "N"},
    "pointing": {"measured": _POSE, "reference": _POSE},
}
# kind -> {number: its unit}: what each metric gives (scenarios.runs.metrics), which
# [requirements] bound; tests/scenarios/spec/test_requirements.py holds it to the metrics' results
METRIC_NUMBERS = {
    "leg_tracking": {"rms": "µm", "peak": "µm"},
    "pose_tracking": {"rms": "µm", "peak": "µm", "rotation_rms": "µrad", "rotation_peak": "µrad"},
    "tracking": {"rms": "µm", "peak": "µm"},
    "peak": {"rms": "kN", "peak": "kN"},
    "base_effect": {"rms": "kN", "peak": "kN", "gravity_peak": "kN", "transport_peak": "kN"},
    "pointing": {"rms": "arcsec", "peak": "arcsec", "path_rms": "µm", "path_peak": "µm",
                 **{f"efficiency_loss_{band}GHz": "%" for band in (15, 22, 31, 43)}},
}
REQUIREMENT_RELATIONS = ("<=", ">=", "<", ">")
TOP_KEYS = {"name", "description", "start_time", "stop_time", "step", "master", "extrapolation",
             "fmus", "connections", "record", "metrics", "sweep", "ci", "fidelity_tolerance", "requirements"}
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
    "record.metric_interval": ("time", "record.interval", "the interval the metrics and the guard read the loop at: "
                               "a whole multiple of step that divides record.interval (a long run kept every "
                               "second, its peaks found every step)"),
    "metrics[].kind": (", ".join(METRIC_KINDS), _REQUIRED, "what the metric computes (table below)"),
    "metrics[].name": ("string", "the kind", "the metric's name in the report and metrics.json"),
    "metrics[].from": ("time", "0 s", "the metric counts from this time on (after settling)"),
    "sweep.parameter": ('"instance.parameter"', _REQUIRED, "the parameter to sweep: one run per value"),
    "sweep.values": ("non-empty list of values", _REQUIRED, "its values, written as in parameters"),
    "ci": ("table of top-level keys", "none", "what replaces them in the short CI run (--ci)"),
    "requirements.<metric> <number>": ('"< 10 µm" (<, <=, >, >=), or a table { limit = "< 10 µm", runs = '
                                       '[sweep values] }', "none",
                                       "an absolute spec every run (or the runs named) must meet, e.g. "
                                       '"pose error peak" = "< 10 µm"; judged in every run, shown in the report '
                                       "and metrics.json; it fails `movingbase run --require` and `movingbase "
                                       "regress`"),
}
# the TOML types each top-level key takes (checked before its value: a table where text
# belongs is told as such); what it takes in words comes from KEYS
TOP_LEVEL_TYPES = {"name": (str,), "description": (str,), "start_time": (int, float, str),
                   "stop_time": (int, float, str), "step": (int, float, str), "master": (str,),
                   "extrapolation": (str,), "fidelity_tolerance": (int, float, str), "fmus": (dict,),
                   "connections": (list,), "record": (dict,), "metrics": (list,), "sweep": (dict,), "ci": (dict,),
                   "requirements": (dict,)}
TYPE_NAMES = {str: "text", int: "integer", float: "number", dict: "table", list: "array", bool: "true/false"}
PLAIN_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.-]{0,99}")     # names that become file or folder names
INSTANCE_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]{0,63}")
NOT_IN_FILE_NAMES = set('/\\:*?"<>|')    # nor in a Markdown table's cell ('|')
MAX_FILE_BYTES = 1 << 20       # a scenario or campaign file larger than this is not one
MAX_DEPTH = 8                  # tables and arrays nested deeper than this are no scenario's
CHECK_POINTS = 100_001        # times at which a model's profile is checked over a run, at most
MAX_INTEGER = 2 ** 53          # larger integer literals are no setting's (and lose precision as floats)
MAX_TIME_ULP = 1e-3            # a time's float resolution must stay below this fraction of the step


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


@dataclass(frozen=True)
class Requirement:
    """An absolute spec a run must meet: ``metric``'s number ``key`` ``relation`` ``limit``
    (in the number's ``unit``), for the runs labelled in ``runs`` (None: every run);
    ``name`` and ``written`` as in the file ("pose error peak" = "< 10 µm")."""

    name: str
    metric: str
    key: str
    relation: str
    limit: float
    unit: str
    runs: tuple | None
    written: object

    @property
    def text(self):
        return f"{self.name} {self.relation} {self.limit:g} {self.unit}"

    def met(self, value):
        """True if ``value`` meets it; False if not, or if it is no number (NaN, None: a
        run that counted nothing shows no spec met)."""
        if value is None or value != value:
            return False
        return {"<": value < self.limit, "<=": value <= self.limit, ">": value > self.limit,
                ">=": value >= self.limit}[self.relation]


def judge(requirements, label, metrics):
    """Each requirement that holds for run ``label``, judged on its ``metrics``:
    [{"requirement": text, "value": the number (None: not counted), "unit", "met"}]."""
    judged = []
    for r in requirements:
        if r.runs is not None and label not in r.runs:
            continue
        value = metrics.get(r.metric, {}).get(r.key)
        value = None if value is None or value != value else value
        judged.append({"requirement": r.text, "value": value, "unit": r.unit, "met": r.met(value)})
    return judged


def unmet(judged):
    """One line of the requirements a run did not meet ('' if it met them all)."""
    return "; ".join(f"{j['requirement']} NOT MET ({_value_text(j)})" for j in judged if not j["met"])


def _value_text(judged):
    return "not counted" if judged["value"] is None else f"{judged['value']:.3g} {judged['unit']}"


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
    sweep: tuple | None = None         # ("inst.var", [values])
    ci: dict = field(default_factory=dict)   # shortened settings for CI: {"stop_time": ...}
    fidelity_tolerance: float | None = None         # [N], for a plant with fidelity = "auto"
    notes: list = field(default_factory=list)  # what the runner decided (shown in the report)
    implementations: dict = field(default_factory=dict)  # instance -> one of IMPLEMENTATIONS
    fmi_versions: dict = field(default_factory=dict)     # instance -> one of FMI_VERSIONS
    short: bool = False         # its [ci] settings applied: a run cut short on purpose, not motion_unfinished
    requirements: list = field(default_factory=list)     # Requirement: absolute specs every run is judged by
    metric_interval: float | None = None     # [s] the metrics and the guard read this often (None: record_interval)

    @property
    def read_interval(self):
        """How often the metrics and the guard read the loop [s]: record.metric_interval, else record.interval."""
        return self.metric_interval or self.record_interval


def enumeration(var):
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


def metric_variables(metric):
    """The 'inst.var' references a metric reads."""
    if metric.kind == "base_effect":
        base, ref = metric.args["base"], metric.args["reference"]
        return [f"{base}.base_{x}" for x in ("pose", "rate", "acc")] + \
               [f"{ref}.reference_{x}" for x in ("pose", "rate", "acc")]
    return list(metric.args.values())
