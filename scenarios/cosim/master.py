"""The co-simulation master: fixed-step Jacobi or Gauss-Seidel over fmpy FMU2Slave
instances, optional linear input extrapolation, results recorded into numpy arrays.

Jacobi: every FMU gets the outputs of t_k, then all step to t_k+1 (a one-step delay on
every connection; what fmpy.ssp.simulate_ssp does too). Gauss-Seidel: FMUs step one after
the other in an order taken from the connection graph (sources first; a cycle is broken
at a plant: an FMU with a state between its inputs and connected outputs, see
step_order), each seeing the outputs already computed for t_k+1. Linear extrapolation
replaces a held input u_k by the mean of its linear extrapolation over the coming step,
u_k + (u_k - u_k-1) / 2, for inputs whose source has not yet stepped. The stepping and
the reading of the recorded values run in C (scenarios/cosim/c/cosim.c, class Loop), many
record points per call; Python sets up, hands the blocks of rows to the records, the
metrics and the watch, and reports.

Every FMI call is status-checked (scenarios.cosim.fmi); a Discard/Error stops the run with
RunFailed: one line naming the instance, the time and the FMU's error log line, and the
run so far (the rows recorded so far are kept and written, the metrics cover them).
Records go into arrays preallocated for the record grid (scenarios.cosim.records), written once
as npz; metrics keep running sums. A failed read of a recorded value stops the run as a
failed step does, the rows before it kept.
"""
import ctypes
import re
from dataclasses import dataclass, field

import numpy as np

from fmu_src import replay_table
from fmu_src.catalogue import CONTROL_LOOPS, FEEDTHROUGH
from scenarios.cosim._cosim import ffi, lib
from scenarios.cosim.fmi import _LABELS, FmuError, Instance, Instance3, RealPort
from scenarios.cosim.records import Records
from scenarios.spec import Link, expand


@dataclass
class Run:
    """What one run produced: where, how long, and its metrics."""

    label: str
    record_path: object     # the records' npz file (None: not written)
    steps: int
    wall_time: float
    sim_time: float
    metrics: dict = field(default_factory=dict)
    series: dict = field(default_factory=dict)
    failure: str = ""       # why the run stopped early ("" if it reached stop_time)
    records: object = None  # scenarios.cosim.records.Records (None: the run failed before recording began)
    flags: list = field(default_factory=list)  # scenarios.runs.flags.Flag: what went wrong ([]: nothing seen)
    cpu_time: float = float(
        "nan"
    )  # this thread's CPU time over the stepping: what a cost comparison on a shared machine uses

    @property
    def real_time_factor(self):
        return self.sim_time / self.wall_time if self.wall_time > 0 else float("nan")


class RunFailed(FmuError):
    """An FMU stopped the run; ``run`` holds what was done up to then."""

    def __init__(self, message, run):
        super().__init__(message)
        self.run = run


def failure_line(error, instances):
    """One line from an FmuError: what failed when, and the failing FMU's first error log
    line (the cause; what follows are refusals of later calls)."""
    head = str(error).split(" Log:", 1)[0].rstrip(".")
    named = re.match(r"FMU instance '(.+?)'", head)
    log = instances[named.group(1)].log if named and named.group(1) in instances else []
    errors = [line for line in log if line.startswith(("[ERROR]", "[FATAL]", "[DISCARD]"))] or log[-1:]
    return f"{head}: {errors[0]}" if errors else head


LOOP_PLANTS = {entry["plant"] for entry in CONTROL_LOOPS.values()}


def step_order(scenario, parameters=None):
    """Gauss-Seidel and initialization order: topological over the connection graph (and
    parameter links). A cycle is broken at an FMU on it whose connected outputs hold a
    state between them and its inputs (no FEEDTHROUGH: a plant), the first declared such:
    its outputs at t need no input of t, also at initialization. Broken at a sensor or a
    controller, that FMU would start from its inputs' defaults (a leg sensor listed first:
    12.9 mm off, a 13-16 kN kick), so the file's listing order would change the numbers.
    On a cycle whose every FMU feeds an output through (a plant whose delivered force is read
    by a load cell), the loop's plant is first: its motion outputs hold its state, and the
    guard's loop model (controller.design, Gauss-Seidel) steps it first."""
    deps = {inst: set() for inst in scenario.fmus}
    for inst, values in (parameters or {}).items():
        deps[inst] |= {v.instance for v in values.values() if isinstance(v, Link)}
    feeds = {inst: False for inst in scenario.fmus}     # a connected output follows an input within a step
    for source, targets in scenario.connections:
        s, output = source.split(".", 1)
        feeds[s] |= output.split("[", 1)[0] in FEEDTHROUGH.get(scenario.fmus[s], {})
        for target in targets:
            t = target.split(".", 1)[0]
            if s != t:
                deps[t].add(s)
    def on_cycle(inst, among):
        seen, todo = set(), [inst]
        while todo:
            for source in deps[todo.pop()] & among:
                if source == inst:
                    return True
                if source not in seen:
                    seen.add(source)
                    todo.append(source)
        return False

    order, remaining = [], list(scenario.fmus)
    while remaining:
        ready = [i for i in remaining if not (deps[i] & set(remaining))]
        cycle = [] if ready else [i for i in remaining if on_cycle(i, set(remaining))]
        plants = [i for i in cycle if scenario.fmus[i] in LOOP_PLANTS]
        pick = ready[0] if ready else next((i for i in cycle if not feeds[i]), (plants or cycle)[0])
        order.append(pick)
        remaining.remove(pick)
    return order


class Exchange:
    """The connection data path: all connected outputs in one vector y; per instance its
    connected outputs (read with one FMI call into a slice of y) and its connected inputs
    (written with one FMI call, input j fed by y[idx[j]] from instance sources[j])."""

    def __init__(self, scenario, instances):
        md = {inst: i.variables for inst, i in instances.items()}
        sources = {}
        pairs = []
        for source, targets in scenario.connections:
            s_inst = source.split(".", 1)[0]
            for target in targets:
                t_inst = target.split(".", 1)[0]
                for s, t in zip(expand(md[s_inst], source), expand(md[t_inst], target)):
                    sources.setdefault(s_inst, [])
                    if s not in sources[s_inst]:
                        sources[s_inst].append(s)
                    pairs.append((s_inst, s, t_inst, t))
        self.read_ports, offset, index = {}, 0, {}
        for inst, names in sources.items():
            self.read_ports[inst] = (RealPort(instances[inst], names), slice(offset, offset + len(names)))
            index.update({(inst, n): offset + k for k, n in enumerate(names)})
            offset += len(names)
        self.y = np.zeros(offset)
        self.y_prev = np.zeros(offset)
        self.write_ports = {}
        for inst in scenario.fmus:
            mine = [(t, index[(s_inst, s)], s_inst) for s_inst, s, t_inst, t in pairs if t_inst == inst]
            if mine:
                port = RealPort(instances[inst], [t for t, _, _ in mine])
                self.write_ports[inst] = (port, np.array([k for _, k, _ in mine]), [s for _, _, s in mine])

    def read(self, inst=None):
        """Read the connected outputs (of inst, default all) into y: before stepping."""
        for name, (port, where) in self.read_ports.items():
            if inst is None or name == inst:
                self.y[where] = port.read()

    def initial_inputs(self, inst, ready):
        """{input: value} of inst fed by instances in ``ready`` (already initialised)."""
        if inst not in self.write_ports:
            return {}
        port, idx, sources = self.write_ports[inst]
        for source in set(sources) & ready:
            self.read(source)
        return {name: self.y[k] for name, k, s in zip(port.names, idx, sources) if s in ready}


def _address(function):
    """The address of one of fmpy's loaded ctypes FMI functions."""
    return ctypes.cast(function, ctypes.c_void_p).value


class Loop:
    """The stepping of the master, in C (scenarios/cosim/c/cosim.c through cffi): each macro
    step writes the connected inputs, steps the FMUs and reads their outputs with the
    FMUs' own fmi2SetReal/fmi2DoStep/fmi2GetReal (FMI 3.0: fmi3SetFloat64/fmi3DoStep/
    fmi3GetFloat64 on whole arrays, as RealPort3 plans them), for Jacobi (inputs from the outputs
    of t_k, optionally extrapolated) or Gauss-Seidel (in ``order``, inputs whose source
    has not stepped yet extrapolated). A Python loop making the same calls cost ~16 us
    more per macro step of three FMUs (benchmarks/bench_scenarios.py); this adds under
    0.3 us to the FMUs' own work (benchmarks/bench_native.py, empty FMUs). With a
    ``recorder`` it also reads the recorded values after every ``every``-th step into
    the recorder's block, one getReal (getFloat64) per instance, as Python read them at
    ~13 us a row."""

    _CALLS = ("setReal", "doStep", "getReal")

    EXTRAPOLATIONS = {"none": 0, "linear": 1, "derivatives": 2}   # cosim_master.extrapolate

    def __init__(self, exchange, instances, order, gauss_seidel, extrapolate, t0, h, recorder=None, every=0):
        self.instances = [instances[inst] for inst in order]
        self._keep = [exchange.y, exchange.y_prev]          # everything the C structs point into
        order_of = np.zeros(max(1, exchange.y.size), dtype=np.intc)   # per y: derivatives its source gives
        fmus = self._new("cosim_fmu[]", len(order))
        for i, (inst, instance) in enumerate(zip(order, self.instances)):
            f = fmus[i]
            f.component = ffi.cast("void *", instance.fmu.component)
            fmi3 = isinstance(instance, Instance3)
            if fmi3:
                f.fmi3 = g = self._new("cosim_fmi3 *")
                g.do_step = ffi.cast("cosim_do_step3_fn", _address(instance.raw("fmi3DoStep")))
                g.get_float64 = ffi.cast("cosim_get_float64_fn", _address(instance.raw("fmi3GetFloat64")))
                g.set_float64 = ffi.cast("cosim_set_float64_fn", _address(instance.raw("fmi3SetFloat64")))
            else:
                f.do_step = ffi.cast("cosim_do_step_fn", _address(instance.raw("fmi2DoStep")))
                f.get_real = ffi.cast("cosim_get_real_fn", _address(instance.raw("fmi2GetReal")))
                f.set_real = ffi.cast("cosim_set_real_fn", _address(instance.raw("fmi2SetReal")))
            f.time = instance.time
            if inst in exchange.read_ports:
                port, where = exchange.read_ports[inst]
                f.read_vr = self._new("unsigned int[]", [instance.vr(n) for n in port.names])
                f.n_read, f.read_at = port.n, where.start
                if fmi3:
                    g.read_vr, g.n_read_vr = self._new("unsigned int[]", port.vrs3), len(port.vrs3)
                    g.read_index, g.n_read_values = self._new("size_t[]", port.index.tolist()), port.total
                    g.read_values = self._new("double[]", port.total)
                    if extrapolate == "derivatives":
                        self._derivatives(g, instance, port, where.start, order_of)
            if inst in exchange.write_ports:
                port, idx, sources = exchange.write_ports[inst]
                if fmi3:
                    g.write_vr, g.n_write_vr = self._new("unsigned int[]", port.vrs3), len(port.vrs3)
                    g.write_index, g.n_write_values = self._new("size_t[]", port.index.tolist()), port.total
                    g.write_values, g.write_partial = self._new("double[]", port.total), port.partial
                f.write_vr = self._new("unsigned int[]", [instance.vr(n) for n in port.names])
                f.n_write = port.n
                f.write_from = self._new("size_t[]", idx.tolist())
                # Gauss-Seidel: 0.5 where the source steps at or after inst (not yet stepped), else 0
                f.write_half = self._new("double[]", (0.5 * np.array([s in order[i:] for s in sources])).tolist())
                f.write_buf = self._new("double[]", port.n)
        m = self._new("cosim_master *")
        m.fmus, m.n_fmus = fmus, len(order)
        m.read_order = self._new("size_t[]", [order.index(inst) for inst in exchange.read_ports])
        m.n_read_order = len(exchange.read_ports)
        m.y = ffi.cast("double *", self._view(exchange.y))
        m.y_prev = ffi.cast("double *", self._view(exchange.y_prev))
        m.y_start = self._new("double[]", max(1, exchange.y.size))
        m.n_y = exchange.y.size
        m.gauss_seidel, m.extrapolate, m.t0, m.h = gauss_seidel, self.EXTRAPOLATIONS[extrapolate], t0, h
        m.y_order = ffi.cast("int *", self._view(order_of))
        m.y_d1, m.y_d2 = self._new("double[]", order_of.size), self._new("double[]", order_of.size)
        self.master, self.fmus = m, fmus
        if recorder:
            self._recording(recorder, every)
        self.derivatives = int(np.count_nonzero(order_of))     # how many outputs are extrapolated by them

    def _derivatives(self, g, instance, port, at, order_of):
        """Set up the FMI 3 instance's output derivatives (orders 1, 2) of the read
        elements whose variables have them (fmi.derivative_orders)."""
        g.get_derivatives = ffi.cast("cosim_get_derivatives_fn", _address(instance.raw("fmi3GetOutputDerivatives")))
        elements = [instance.arrays[instance.vr(n)] for n in port.names]   # (variable, offset, count)
        for j, (array, _, _) in enumerate(elements):
            order_of[at + j] = instance.derivative_order.get(array, 0)
        for o in (1, 2):
            arrays = [a for a in port.vrs3 if instance.derivative_order.get(a, 0) >= o]
            if not arrays:
                continue
            starts = np.cumsum([0] + [instance.arrays[a][2] for a in arrays])
            pairs = [(int(starts[arrays.index(a)]) + k, at + j) for j, (a, k, _) in enumerate(elements) if a in arrays]
            d = g.derivatives[o - 1]
            d.vr, d.n_vr = self._new("unsigned int[]", arrays), len(arrays)
            d.orders = self._new("int[]", [o] * len(arrays))
            d.values, d.n_values = self._new("double[]", int(starts[-1])), int(starts[-1])
            d.src, d.dst = self._new("size_t[]", [p[0] for p in pairs]), self._new("size_t[]", [p[1] for p in pairs])
            d.n = len(pairs)

    def _recording(self, recorder, every):
        """Point the C loop at the recorder's reads (cosim_record: per instance its
        elements, FMI 3 planned as RealPort3 plans them) and at its block of rows."""
        m = self.master
        records = self._new("cosim_record[]", len(recorder.reads))
        for r, (instance, names, columns) in zip(records, recorder.reads):
            vrs = [instance.vr(n) for n in names]
            total, index = len(vrs), range(len(vrs))
            if isinstance(instance, Instance3):
                vrs, total, index = instance.plan(vrs)
            r.fmu = self.instances.index(instance)
            r.vr, r.n_vr = self._new("unsigned int[]", list(vrs)), len(vrs)
            r.values, r.n_values = self._new("double[]", total), total
            r.index, r.column = self._new("size_t[]", list(index)), self._new("size_t[]", columns)
            r.n = len(names)
        m.records, m.n_records, m.every = records, len(recorder.reads), every
        m.rows = ffi.cast("double *", self._view(recorder.block))
        m.capacity, m.n_columns = recorder.block.shape

    def _view(self, array):
        value = ffi.from_buffer(array)
        self._keep.append(value)
        return value

    def _new(self, kind, init=None):
        value = ffi.new(kind, init)
        self._keep.append(value)
        return value

    def steps(self, k, count):
        """Run macro steps k .. k+count-1; returns how many completed (fewer: a call
        answered above Warning, see ``check``, or the recorder's block is full). Each
        instance's time becomes that of its last doStep, as Instance.do_step sets it, for
        the error message."""
        done = lib.cosim_steps(self.master, k, count)
        for f, instance in zip(self.fmus, self.instances):
            instance.time = f.time
        return done

    def record_row(self):
        """Read one row now (the run's first) into the recorder's block."""
        lib.cosim_record_row(self.master)

    @property
    def rows(self):
        """How many rows the last ``steps`` or ``record_row`` put into the recorder's block."""
        return self.master.n_rows

    def check(self):
        """Raise the FmuError of the call that stopped the last ``steps``, if any, as the
        Python call would have (Instance.fail: instance, call, time, status, log)."""
        m = self.master
        if m.failed_fmu >= 0:
            self.instances[m.failed_fmu].fail(self._CALLS[m.failed_call], f"status {_LABELS[m.failed_status]}")


class Recorder:
    """Recorded variables, read by the C loop (Loop) into ``block`` a row per record
    point, one FMI call per instance, and handed over a block at a time (``take``) to
    preallocated arrays (scenarios.cosim.records: one row per record point, units with the
    names), the metrics and the watch (scenarios.runs.flags.Watch). What only the watch needs
    is read but not recorded. With ``keep`` > 1 the records keep every keep-th row read (the
    run's first among them), while the metrics and the watch get every row: a peak between
    two recorded rows is still counted."""

    ROWS = 256   # the most rows one C call records before it returns them

    def __init__(self, scenario, instances, metrics, rows, watch=None, keep=1):
        md = {inst: i.variables for inst, i in instances.items()}
        wanted = list(dict.fromkeys(scenario.record + [r for m in metrics for r in m.needs]))
        watched = [r for r in dict.fromkeys(watch.needs if watch else []) if r not in wanted]
        names, units, columns, self.slices = [], [], {}, {}
        for reference in wanted + watched:
            inst = reference.split(".", 1)[0]
            expanded = expand(md[inst], reference)
            self.slices[reference] = slice(len(names), len(names) + len(expanded))
            for n in expanded:
                columns.setdefault(inst, []).append((n, len(names)))
                names.append(f"{inst}.{n}")
                units.append(md[inst][n].unit or "1")
        self.kept = self.slices[wanted[-1]].stop if wanted else 0
        self.reads = [(instances[inst], [n for n, _ in cols], [j for _, j in cols]) for inst, cols in columns.items()]
        self.keep, self.read = keep, 0     # rows read so far (every keep-th is recorded)
        self.records = Records(names[:self.kept], units[:self.kept], (rows - 1) // keep + 1)
        self.block = np.zeros((min(self.ROWS, rows), len(names)))
        self.metrics = [(m, [self.slices[n] for n in m.needs]) for m in metrics]
        self.watch = watch
        if watch:
            watch.bind(self.slices)

    def take(self, t, n):
        """The block's first n rows, recorded at times t (n,): into the records, to each
        metric from its start time, to the watch."""
        if not n:
            return
        rows = self.block[:n]
        kept = slice((-self.read) % self.keep, n, self.keep)     # the rows whose count is a multiple of keep
        self.records.extend(t[kept], rows[kept, :self.kept])
        self.read += n
        for metric, where in self.metrics:
            first = int(np.searchsorted(t, metric.start - 1e-12))   # t >= start - 1e-12 from here
            if first < n:
                metric.feed(t[first:], [rows[first:, s] for s in where])
        if self.watch:
            self.watch.feed(t, rows)


def start(scenario, fmu_paths, parameters, instances):
    """Instantiate every FMU into ``instances`` (the caller frees them, also on failure)
    and initialise them in dependency order: parameters, links ("@inst.var") read from
    instances already initialised, and connected inputs fed by them. Returns the
    Exchange and the parameters with every Link replaced by its number."""
    for inst in scenario.fmus:
        instances[inst] = Instance(fmu_paths[inst], inst)
    exchange = Exchange(scenario, instances)
    ready, resolved = set(), {}
    for inst in step_order(scenario, parameters):
        resolved[inst] = replay_table.for_fmu({name: instances[v.instance].get_real(v.variable) if isinstance(v, Link)
                                               else v for name, v in parameters.get(inst, {}).items()})
        instances[inst].initialize(scenario.start_time, {**resolved[inst], **exchange.initial_inputs(inst, ready)})
        ready.add(inst)
    return exchange, resolved
