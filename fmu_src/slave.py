"""What every FMU of the kit shares: guarded stepping, vector variables with units.

Why guarded: an exception escaping do_step gives fmi2Fatal, and the next doStep then
crashes the importing process (docs/conventions/fmi-notes.md). Every error is caught here,
logged at error level with what went wrong and when, and answered with fmi2Discard
(do_step returns False); the slave then stays failed and refuses further steps.

Log level, precisely: the line carries the status the call answers (docs/fmu-rules.md), Discard
from doStep (category logStatusDiscard), Error from initialization. An output that comes
out NaN or inf is such an error (check_outputs), as in the native layer.

Units and ranges: pythonfmu writes neither, so each variable's unit and each parameter's
valid range (``valid=(min, max)``, either side None for open; FMI's min/max are inclusive,
so "> 0" is written as a tiny positive min) are recorded here, with the choice parameters'
item names (``enumerations``) and the DefaultExperiment, and build.py writes them into
modelDescription.xml (fmu_src/python_build.py): one description of each FMU that every
modelDescription writer reads from an instance of its slave class. At fmi2ExitInitializationMode every parameter
is checked against its range (and enumerations with gaps against their values), every
input must be finite, and a violation is logged naming variable, value and range.

Init failures: pythonfmu 0.7.0's wrapper ignores what exit_initialization_mode returns and
answers fmi2Fatal for any exception, so a failed initialization logs its error and raises;
the shim in front of the wrapper (fmu_src/pythonfmu_shim.c) answers that fatal with
fmi2Error, since keep-alive references make the host's later calls (doStep, terminate,
free) safe (see exit_initialization_mode). The shim also has the wrapper finalize Python
before the process's library destructors run (the crash of a C host at exit).

Outputs in initialization mode: read between fmi2EnterInitializationMode and
fmi2ExitInitializationMode, the outputs are computed from the parameters and inputs set so
far (initialize() run again whenever something was set since), as the native FMUs do
(fmu_src/native/fmi2_layer.c evaluate_initial): an importer that propagates values
during initialization (libcosim) then starts every FMU from its neighbours' initial
outputs. Such an evaluation checks the start values first (the native layer does not:
with bad values the outputs mean nothing either way, and the kernels never see them here)
and, if they are bad or initialize() fails, leaves the outputs as they were, silently:
fmi2ExitInitializationMode, which runs the check and initialize() once more, reports it.
initialize() computes from parameters and inputs only, so the outputs after exit are the
same bits with or without these evaluations.

Discarded steps: the output arrays (whole: the integrator state of every FMU lives in
them or in arrays they are views of) are put back as they were before the step,
so a host reading outputs after fmi2Discard sees the last accepted state, at the time
fmi2GetRealStatus(fmi2LastSuccessfulTime) answers (the shim's: the end of the last accepted step).

Serialized FMU state: pythonfmu writes its state dict as JSON, which takes no numpy
arrays or bytes (the integrator and sensor states), so its serialization answered fmi2Fatal
and the FMUs declared canSerializeFMUstate="false". Here the dict is JSON with those tagged
(arrays as their raw bytes, dtype and shape; floats JSON writes exactly, NaN and inf
included): a blob restores the same bits in any instance of the FMU, as the native ones do.
A header line (model identifier, CRC-32) lets the shim refuse foreign bytes with fmi2Error
before the wrapper sees them: an exception there would be its fmi2Fatal, after which it
has dropped references the instance still needs.

The FMU scripts import this module from the installed `movingbase` package (not from
the FMU's resources): one copy in the process, sharing the C kernel built at install.
"""
import base64
import json
import math
import zlib
from xml.etree import ElementTree

import numpy as np
from pythonfmu import DefaultExperiment, Fmi2Causality, Fmi2Initial, Fmi2Slave, Fmi2Variability
from pythonfmu.enums import Fmi2Status
from pythonfmu.variables import Boolean, Integer, Real, String

from plant.errors import InvalidInputError

PARAMETER, INPUT, OUTPUT = Fmi2Causality.parameter, Fmi2Causality.input, Fmi2Causality.output
# FMI min/max are inclusive: the smallest values standing for "> 0"
POSITIVE_TIME = 1e-9      # s
POSITIVE_FORCE = 1e-9     # N
POSITIVE_RATE = 1e-12     # rad/s, rad/s2
POSE_UNITS = ("m", "m", "m", "rad", "rad", "rad")


class NonFiniteOutputError(ArithmeticError):
    """An output came out NaN or inf from finite inputs (too large ones, mostly)."""


def rate_units(units):
    return tuple(u + "/s" for u in units)


def acc_units(units):
    return tuple(u + "/s2" for u in units)


def _flat_slot(values, i, flat_views):
    """(flat view of the root array, flat index) of element i of a 1-D view, so that
    inputs that are rows of one array are written with one numpy assignment."""
    root = values if values.base is None else values.base
    if not (root.flags.c_contiguous and values.ndim == 1):
        return values, i
    offset = values.__array_interface__["data"][0] - root.__array_interface__["data"][0]
    flat = flat_views.setdefault(id(root), root.reshape(-1))
    return flat, (offset + i * values.strides[0]) // values.itemsize


STATE_MAGIC = b"movingbase-state"   # first word of a serialized state (fmu_src/pythonfmu_shim.c checks it)
_SURVIVORS: list = []   # (instance, class, log queue) of instances whose initialization failed


def _root(array):
    while array.base is not None:
        array = array.base
    return array


def _quantity(value, unit):
    """``value unit``, with degrees alongside radians."""
    text = f"{value:.6g} {unit}".strip()
    if unit.startswith("rad") and math.isfinite(value):
        text += f" ({math.degrees(value):.6g} deg{unit[3:]})"
    return text


def range_text(valid, unit):
    low, high = valid
    if high is None:
        return f">= {_quantity(low, unit)}"
    if low is None:
        return f"<= {_quantity(high, unit)}"
    text = f"[{low:.6g}, {high:.6g}] {unit}".strip()
    if unit.startswith("rad"):
        text += f" ([{math.degrees(low):.6g}, {math.degrees(high):.6g}] deg{unit[3:]})"
    return text


def inside(value, valid):
    low, high = valid
    return (low is None or value >= low) and (high is None or value <= high)   # False for NaN


def _encode(value):
    """JSON for what a slave's state holds beyond JSON's own types (tuples JSON writes as lists)."""
    if isinstance(value, np.ndarray):
        return {"__ndarray__": base64.b64encode(np.ascontiguousarray(value).tobytes()).decode("ascii"),
                "dtype": value.dtype.str, "shape": list(value.shape)}
    if isinstance(value, bytes):
        return {"__bytes__": base64.b64encode(value).decode("ascii")}
    if isinstance(value, np.generic):
        return value.item()
    raise TypeError(f"FMU state cannot hold a {type(value).__name__}")


def _decode(entry):
    if "__ndarray__" in entry:
        raw = base64.b64decode(entry["__ndarray__"])
        return np.frombuffer(raw, dtype=np.dtype(entry["dtype"])).reshape(entry["shape"]).copy()
    if "__bytes__" in entry:
        return base64.b64decode(entry["__bytes__"])
    return entry


class GuardedSlave(Fmi2Slave):
    """A pythonfmu slave that never lets an exception reach the importer."""

    author = "movingbase"
    license = "MIT"
    # what a plain importer runs without arguments (fmpy.simulate_fmu): one second at 1 ms,
    # the communication step every controller's gains were designed for
    default_experiment = DefaultExperiment(start_time=0.0, stop_time=1.0, step_size=1e-3)

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.default_experiment = type(self).default_experiment   # pythonfmu's __init__ sets None
        self.units = {}
        self.ranges = {}    # parameter name -> (min, max), None for an open side
        self.allowed = {}   # integer parameter name -> the values it may take (gaps min/max cannot say)
        self.enumerations = {}   # parameter name -> item names, values 0..n-1 (FMI Enumerations, builder.py)
        self.input_names = []
        self._step_saves = []   # (root of output arrays, its copy before the step): put back on Discard
        self._set_saves = []    # (root of input and parameter arrays, its copy): kept by an evaluation
        self.failure = ""
        self.arrays = {}   # name -> numpy array saved with the FMU state
        self.slots = {}    # value reference -> (array, index) of vector elements
        self.settable = {}  # the same for vector inputs and parameters
        self._plans = {}
        self._flat_views = {}
        self._initializing = False   # between enter_ and exit_initialization_mode
        self._stale = False          # initialization mode: set since the outputs were computed
        self._stepping = False       # past fmi2ExitInitializationMode: parameters are fixed
        self._initialized = False    # initialize() has run to its end: extra_state() has a state to give

    # ---------------------------------------------------------------- variables
    def real(self, name, causality, description, unit, start=0.0, getter=None, setter=None, valid=None):
        """Register one Real; parameters are fixed, inputs/outputs continuous; ``valid``
        (min, max) the parameter's range."""
        variability = Fmi2Variability.fixed if causality == PARAMETER else Fmi2Variability.continuous
        output = causality == OUTPUT   # initial="calculated" (no start attribute): see to_xml
        var = Real(name, causality=causality, description=description, variability=variability,
                   initial=Fmi2Initial.calculated if output else None, start=None if output else start,
                   getter=getter, setter=setter)
        self.register_variable(var, nested=False)
        if unit:
            self.units[name] = unit
        if valid is not None:
            self.ranges[name] = valid
        if causality == INPUT:
            self.input_names.append(name)

    def vector(self, name, size, causality, description, units, start=None, values=None, valid=None):
        """Register name[1..size] backed by a numpy array (``values``, a view the model
        shares, or a new one) kept in self.arrays[name] and saved with the FMU state;
        ``valid``: one (min, max) for every element or a list of them."""
        if values is None:
            values = np.zeros(size) if start is None else np.array(start, dtype=float)
        self.arrays[name] = values
        if causality == OUTPUT and not any(r is _root(values) for r, _ in self._step_saves):
            self._step_saves.append((_root(values), _root(values).copy()))
        if causality != OUTPUT and not any(r is _root(values) for r, _ in self._set_saves):
            self._set_saves.append((_root(values), _root(values).copy()))
        units = (units,) * size if isinstance(units, str) else units
        valid = [valid] * size if valid is None or not isinstance(valid[0], (tuple, list)) else valid
        labels = description if isinstance(description, (list, tuple)) else [description] * size
        for i in range(size):
            setter = None if causality == OUTPUT else (lambda v, i=i: values.__setitem__(i, v))
            self.real(f"{name}[{i + 1}]", causality, labels[i], units[i], float(values[i]),
                      getter=lambda i=i: values[i], setter=setter, valid=valid[i])
            self.slots[len(self.vars) - 1] = (values, i)
            if setter:
                self.settable[len(self.vars) - 1] = _flat_slot(values, i, self._flat_views)
        return values

    def get_real(self, vrs):
        """Vector elements straight from their arrays (pythonfmu's per-variable getters
        cost ~0.6 µs a value, and the master reads dozens every step)."""
        if self._stale:
            self._evaluate_initial()
        try:
            values = [array.item(i) for array, i in map(self.slots.__getitem__, vrs)]
        except KeyError:
            if self._refused("fmi2GetReal", vrs, Real):
                return [0.0] * len(vrs)
            values = super().get_real(vrs)
        if self.failure:   # only a refused initialization leaves an output NaN/inf (a refused step puts them back)
            self._name_nonfinite_outputs(vrs, values)
        return values

    def _refused(self, call, vrs, kind, setting=False):
        """True, with an Error line, for a value reference that is not a variable of the
        type, or (``setting``) an output or a parameter after initialization: the shim then
        answers fmi2Error (pythonfmu's own methods raised: fmi2Fatal, a dead instance) and
        nothing is set (the native layer's rules, fmi2_layer.c valid_vr and settable)."""
        for vr in vrs:
            var = self.vars.get(vr)
            why = (f"no {kind.__name__} variable has value reference {vr}" if not isinstance(var, kind)
                   else f"{var.name} is an output and cannot be set" if setting and var.causality not in (INPUT,
                                                                                                          PARAMETER)
                   else f"parameter {var.name} cannot be set after initialization"
                   if setting and var.causality == PARAMETER and self._stepping else "")
            if why:
                self.log(f"{call}: {why}", Fmi2Status.error, "logStatusError")
                return True
        return False

    def _name_nonfinite_outputs(self, vrs, values):
        """An Error line naming the first output read that is not finite: the shim
        (pythonfmu_shim.c fmi2GetReal) then answers fmi2Error, as the native layer does."""
        for vr, value in zip(vrs, values):
            if self.vars[vr].causality == OUTPUT and not math.isfinite(value):
                self.log(f"fmi2GetReal: output {self.vars[vr].name} is {value!r}, not finite (after: {self.failure})",
                         Fmi2Status.error, "logStatusError")
                return

    def set_real(self, vrs, values):
        """Vector inputs written array by array; the plan per list of value references is
        made once (a master writes the same list every step)."""
        key = (tuple(vrs), self._stepping)   # parameters are settable until the initialization ends
        plan = self._plans.get(key)
        if plan is None:
            if self._refused("fmi2SetReal", vrs, Real, setting=True):
                return
            plan = self._plans[key] = self._plan(key[0])
        self._stale = self._initializing
        if plan is False:
            return super().set_real(vrs, values)
        values = np.asarray(values, dtype=float)
        for array, index, positions in plan:
            array[index] = values[positions]

    def get_integer(self, vrs):
        if self._stale:
            self._evaluate_initial()
        return [0] * len(vrs) if self._refused("fmi2GetInteger", vrs, Integer) else super().get_integer(vrs)

    def set_integer(self, vrs, values):
        if not self._refused("fmi2SetInteger", vrs, Integer, setting=True):
            self._stale = self._initializing
            super().set_integer(vrs, values)

    def get_boolean(self, vrs):
        return [False] * len(vrs) if self._refused("fmi2GetBoolean", vrs, Boolean) else super().get_boolean(vrs)

    def get_string(self, vrs):
        return [""] * len(vrs) if self._refused("fmi2GetString", vrs, String) else super().get_string(vrs)

    def set_boolean(self, vrs, values):
        if not self._refused("fmi2SetBoolean", vrs, Boolean, setting=True):
            super().set_boolean(vrs, values)

    def set_string(self, vrs, values):
        if not self._refused("fmi2SetString", vrs, String, setting=True):
            super().set_string(vrs, values)

    def _plan(self, vrs):
        """[(array, element indices, positions in vrs)] or False if some vr is not a
        vector input."""
        if not all(vr in self.settable for vr in vrs):
            return False
        groups = {}
        for position, vr in enumerate(vrs):
            array, index = self.settable[vr]
            groups.setdefault(id(array), (array, [], []))
            groups[id(array)][1].append(index)
            groups[id(array)][2].append(position)
        return [(a, np.array(i), np.array(p)) for a, i, p in groups.values()]

    def to_xml(self, model_options=None):
        """pythonfmu's modelDescription with ModelStructure/InitialUnknowns: every output.

        FMI 2.0 (2.2.7, 2.2.8): an output with initial="exact" is initialized to its start
        value, and only outputs with initial="approx" or "calculated" are unknowns of
        initialization mode, to be read from the FMU after the parameters and inputs are
        set. Ours are computed then (base pose from the start pointing, forces from the
        inputs), so they are "calculated", without a start value (FMI forbids one), and
        listed here with no dependencies attribute (each may depend on every parameter and
        input). pythonfmu 0.7.0 writes no InitialUnknowns, which is why fmpy's validation
        rejects its default (calculated) outputs."""
        root = super().to_xml(model_options or {})
        structure = root.find("ModelStructure")
        outputs = structure.find("Outputs")
        if outputs is not None:
            unknowns = ElementTree.Element("InitialUnknowns")
            for unknown in outputs:
                ElementTree.SubElement(unknowns, "Unknown", index=unknown.get("index"))
            structure.insert(list(structure).index(outputs) + 1, unknowns)
        return root

    def parameters(self, rows):
        """Real parameters (name, unit, default, description, valid range) backed by a
        dict, returned."""
        store = {}
        for name, unit, default, text, valid in rows:
            store[name] = default
            self.real(name, PARAMETER, text, unit, default, getter=lambda n=name: store[n],
                      setter=lambda v, n=name: store.__setitem__(n, v), valid=valid)
        return store

    def strings(self, rows):
        """String parameters (name, default, description) backed by a dict, returned. A
        slave registers these after every other variable (the native FMUs' core keeps
        Strings apart from the numeric variables; fmu_src/native_build.py), and their
        default is "" (the native core starts every String there)."""
        store = {}
        for name, default, text in rows:
            store[name] = default
            self.register_variable(String(name, causality=PARAMETER, description=text,
                                          variability=Fmi2Variability.fixed, start=default,
                                          getter=lambda n=name: store[n],
                                          setter=lambda v, n=name: store.__setitem__(n, v)), nested=False)
        return store

    def pid_gains(self, defaults, subject, note):
        """kp, ki, kd, force_limit parameters of a PID on ``subject`` (e.g. "leg length")."""
        return self.parameters((
            ("kp", "N/m", defaults["kp"], f"proportional gain on {subject}; default {note}", (0.0, None)),
            ("ki", "N/(m.s)", defaults["ki"], f"integral gain on {subject}; default {note}", (0.0, None)),
            ("kd", "N.s/m", defaults["kd"], f"derivative gain on the rate of {subject}; default {note}",
             (0.0, None)),
            ("force_limit", "N", defaults["force_limit"], "actuator force saturation (assumed); > 0",
             (POSITIVE_FORCE, None)),
        ))

    def integer(self, name, description, start, valid, allowed=None):
        """An Integer parameter in ``valid`` (min, max); ``allowed``: the values it may
        take when that range has gaps (e.g. -1 or +1)."""
        setattr(self, name, start)
        self.register_variable(Integer(name, causality=PARAMETER, variability=Fmi2Variability.fixed,
                                       description=description, start=start))
        self.ranges[name] = valid
        if allowed is not None:
            self.allowed[name] = tuple(allowed)

    def enumeration(self, name, what, labels, start):
        """A parameter choosing one of ``labels`` by index 0..n-1: an FMI Enumeration whose
        items are the labels (builder.py writes it; set through fmi2SetInteger)."""
        self.enumerations[name] = tuple(labels)
        self.integer(name, f"{what}: " + ", ".join(f"{i} {m}" for i, m in enumerate(labels)), start,
                     (0, len(labels) - 1))

    def check_start(self):
        """InvalidInputError naming every parameter outside its range and every input
        that is not finite; called before initialize()."""
        variables = {v.name: v for v in self.vars.values()}
        problems = []
        for name, valid in self.ranges.items():
            value = variables[name].getter()
            unit = self.units.get(name, "")
            if not inside(value, valid):
                problems.append(f"parameter {name} = {_quantity(value, unit)} is outside its valid range "
                                f"{range_text(valid, unit)}")
            elif name in self.allowed and value not in self.allowed[name]:
                problems.append(f"parameter {name} = {value} is not one of {', '.join(map(str, self.allowed[name]))}")
        for name in self.input_names:
            value = variables[name].getter()
            if not math.isfinite(value):
                problems.append(f"input {name} = {value} at initialization: inputs must be finite")
        if problems:
            raise InvalidInputError("; ".join(problems))

    # ----------------------------------------------------------------- guarding
    def fail(self, exc, when, status=Fmi2Status.error):
        """Record the failure; its log line carries the status the call answers (Error
        from initialization, Discard from doStep)."""
        self.failure = f"{type(exc).__name__} {when}: {exc}"
        self.log(self.failure, status, f"logStatus{status.name.capitalize()}")

    def enter_initialization_mode(self):
        self._initializing = self._stale = True

    def _evaluate_initial(self):
        """The outputs from the parameters and inputs set so far (see the module doc);
        on a bad start value or a failing initialize(), the outputs as they were. The inputs
        and parameters read as they were set, whatever initialize() wrote into them
        (HexapodPlant's start_equilibrium: the leg forces), as the native layer's."""
        self._stale = False
        self._keep_outputs()
        for root, saved in self._set_saves:
            np.copyto(saved, root)
        try:
            self.check_start()
            self.initialize()
            self._initialized = True
            self.check_outputs()
        except Exception:   # noqa: BLE001 - reported by exit_initialization_mode, see module doc
            self._restore_outputs()
        for root, saved in self._set_saves:
            np.copyto(root, saved)

    def exit_initialization_mode(self):
        self._initializing = self._stale = False
        self._stepping = True
        try:
            self.check_start()
            self.initialize()
            self._initialized = True
            self.check_outputs()
        except Exception as exc:   # noqa: BLE001 - reported through FMI status, see module doc
            self.fail(exc, "in initialization")
            # The wrapper answers fmi2Fatal (the shim: fmi2Error, seeing the error logged
            # above) and drops its references to this instance, its class and its log
            # queue, then drops them again in fmi2FreeInstance (pythonfmu 0.7.0,
            # PySlaveInstance::cleanPyObject): one extra reference of each keeps them
            # alive, so a later doStep (refused), terminate or free is safe.
            _SURVIVORS.append((self, type(self), self.log_queue))
            raise RuntimeError(self.failure) from None

    def do_step(self, current_time, step_size):
        if self.failure:
            self.log(f"refusing doStep at t={current_time:.6g} s after: {self.failure}",
                     Fmi2Status.discard, "logStatusDiscard")
            return False
        self._keep_outputs()
        try:
            self.step(current_time, step_size)
            self.check_outputs()
            return True
        except Exception as exc:   # noqa: BLE001 - reported through FMI status, see module doc
            self._restore_outputs()   # back to the outputs of the last accepted state
            self.fail(exc, f"at t={current_time:.6g} s", Fmi2Status.discard)
            return False

    def check_outputs(self):
        """NonFiniteOutputError if an output is NaN or inf, naming those outputs and the
        Real input or parameter of largest magnitude (a NaN counts largest), worded as the
        native layer words it (fmi2_layer.c nonfinite_outputs): no FMU answers fmi2OK
        with a non-finite output, whichever model forgot to check."""
        if all(np.isfinite(root).all() for root, _ in self._step_saves) and \
                all(math.isfinite(v.getter()) for v in self._scalar_outputs()):
            return
        bad = [(v.name, float(v.getter())) for v in self.vars.values()
               if v.causality == OUTPUT and isinstance(v, Real) and not math.isfinite(v.getter())]
        if not bad:
            return   # a non-finite state element that no output shows
        worst = None
        for v in self.vars.values():
            if v.causality in (INPUT, PARAMETER) and isinstance(v, Real):
                value = float(v.getter())
                if worst is None or (not math.isnan(worst[1]) and not abs(value) <= abs(worst[1])):
                    worst = (v.name, value)
        listed = ", ".join(f"{name} = {value!r}" for name, value in bad[:4]) + (", ..." if len(bad) > 4 else "")
        cause = f"; the input or parameter of largest magnitude is {worst[0]} = {worst[1]!r}" if worst else ""
        raise NonFiniteOutputError(f"{len(bad)} output{'s' if len(bad) > 1 else ''} not finite ({listed}){cause}")

    def _scalar_outputs(self):
        """The Real outputs outside the vector arrays (checked one by one)."""
        if not hasattr(self, "_scalars"):
            self._scalars = [v for vr, v in self.vars.items()
                             if v.causality == OUTPUT and isinstance(v, Real) and vr not in self.slots]
        return self._scalars

    def _keep_outputs(self):
        for root, saved in self._step_saves:
            np.copyto(saved, root)

    def _restore_outputs(self):
        for root, saved in self._step_saves:
            np.copyto(root, saved)

    def initialize(self):
        """Compute the outputs at the start time (after parameters are set)."""

    def step(self, t, h):
        raise NotImplementedError

    # -------------------------------------------------------------------- state
    def _get_fmu_state(self):
        """The variables, the arrays, and the model's internal state once initialize() has
        built it (before, there is none: a state saved in the instantiated state answered
        fmi2Fatal from BaseSensor's and Telescope's extra_state, fuzz.c)."""
        state = super()._get_fmu_state()
        state["__arrays__"] = {k: v.copy() for k, v in self.arrays.items()}
        # the whole arrays the outputs live in: a scalar output may read an element no
        # vector shows (Wind's gust, out[6] beside the wrench out[:6], was not restored: fuzz.c)
        state["__roots__"] = [root.copy() for root, _ in self._step_saves]
        state["__extra__"] = self.extra_state() if self._initialized else None
        state["__initialized__"] = self._initialized
        state["__failure__"] = self.failure
        state["__slave__"] = type(self).__name__   # the FMU's model identifier, for the blob's header
        state["__phase__"] = [self._initializing, self._stepping]   # restored with the shim's phase
        return state

    def _set_fmu_state(self, state):
        """Into any instance of the FMU: one never initialized runs initialize() on the
        state's parameters and inputs first, to build the objects the internal state fills."""
        state = dict(state)
        arrays, roots, extra = state.pop("__arrays__"), state.pop("__roots__"), state.pop("__extra__")
        initialized = state.pop("__initialized__")
        self.failure = state.pop("__failure__")
        state.pop("__slave__")
        self._initializing, self._stepping = state.pop("__phase__")
        self._stale = self._initializing   # initialization mode: the outputs of the restored inputs
        for k, v in arrays.items():
            self.arrays[k][:] = v
        super()._set_fmu_state(state)
        if initialized and not self._initialized:   # Wind's step needs the gust model initialize() makes
            try:
                self.initialize()   # the objects; its outputs are replaced by the state's below
                self._initialized = True
            except Exception:   # noqa: BLE001 - the state's inputs may be NaN (set after its initialization):
                pass            # its computation failed (the objects made before it stay; a step may Discard)
        for (root, _), v in zip(self._step_saves, roots):   # after initialize(), which computed outputs
            root[...] = v
        if initialized and self._initialized:
            self.set_extra_state(extra)

    @staticmethod
    def _fmu_state_to_bytes(state):
        """A header line the shim checks before the wrapper sees a blob (``movingbase-state
        <class> <crc32 of the rest>``), then the state as JSON."""
        payload = json.dumps(state, default=_encode).encode("utf-8")
        return b"%s %s %08x\n" % (STATE_MAGIC, state["__slave__"].encode(), zlib.crc32(payload)) + payload

    @staticmethod
    def _fmu_state_from_bytes(blob):   # pythonfmu calls it on the class, after the shim's check
        blob = bytes(blob)
        head, _, payload = blob.partition(b"\n")
        magic, _, rest = head.partition(b" ")
        crc = rest.rpartition(b" ")[2]
        if magic != STATE_MAGIC or crc != b"%08x" % zlib.crc32(payload):   # a host without the shim (win64)
            raise ValueError(f"the {len(blob)} bytes are not a serialized state of this FMU")
        return json.loads(payload.decode("utf-8"), object_hook=_decode)

    def extra_state(self):
        """Internal state beyond the registered variables (integrator state)."""
        return None

    def set_extra_state(self, extra):
        pass
