"""The co-simulation master: fixed-step Jacobi or Gauss-Seidel over fmpy FMU2Slave
instances, optional linear input extrapolation, results streamed to CSV.

Jacobi: every FMU gets the outputs of t_k, then all step to t_k+1 (a one-step delay on
every connection; what fmpy.ssp.simulate_ssp does too). Gauss-Seidel: FMUs step one after
the other in an order taken from the connection graph (sources first; a cycle is broken
at the FMU declared first in the file), each seeing the outputs already computed for
t_k+1. Linear extrapolation replaces a held input u_k by the mean of its linear
extrapolation over the coming step, u_k + (u_k - u_k-1) / 2, for inputs whose source has
not yet stepped.

Every FMI call is status-checked (scenarios.fmi); a Discard/Error stops the run with
RunFailed: one line naming the instance, the time and the FMU's error log line, and the
run so far (the rows recorded stay in the CSV, the metrics cover them). Memory stays
flat: rows go to disk as they come, metrics keep running sums.
"""
import csv
import re
import time
from dataclasses import dataclass, field

import numpy as np

from .fmi import FmuError, Instance, RealPort
from .spec import Link, expand


@dataclass
class Run:
    """What one run produced: where, how long, and its metrics."""

    label: str
    csv_path: object
    steps: int
    wall_time: float
    sim_time: float
    metrics: dict = field(default_factory=dict)
    series: dict = field(default_factory=dict)
    failure: str = ""       # why the run stopped early ("" if it reached stop_time)

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
    errors = [line for line in log if line.startswith(("[ERROR]", "[FATAL]"))] or log[-1:]
    return f"{head}: {errors[0]}" if errors else head


def step_order(scenario, parameters=None):
    """Gauss-Seidel and initialization order: topological over the connection graph (and
    parameter links), cycles broken by declaration order."""
    deps = {inst: set() for inst in scenario.fmus}
    for inst, values in (parameters or {}).items():
        deps[inst] |= {v.instance for v in values.values() if isinstance(v, Link)}
    for source, targets in scenario.connections:
        for target in targets:
            s, t = source.split(".", 1)[0], target.split(".", 1)[0]
            if s != t:
                deps[t].add(s)
    order, remaining = [], list(scenario.fmus)
    while remaining:
        ready = [i for i in remaining if not (deps[i] & set(remaining))]
        pick = ready[0] if ready else remaining[0]
        order.append(pick)
        remaining.remove(pick)
    return order


class Exchange:
    """The connection data path: all connected outputs in one vector y, read per instance
    with one FMI call, and each instance's inputs written with one FMI call."""

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
        self._halves = {}
        self.write_ports = {}
        for inst in scenario.fmus:
            mine = [(t, index[(s_inst, s)], s_inst) for s_inst, s, t_inst, t in pairs if t_inst == inst]
            if mine:
                port = RealPort(instances[inst], [t for t, _, _ in mine])
                self.write_ports[inst] = (port, np.array([k for _, k, _ in mine]), [s for _, _, s in mine])

    def read(self, inst=None):
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

    def extrapolated(self):
        """All connected outputs linearly extrapolated over the coming step (Jacobi)."""
        return self.y + 0.5 * (self.y - self.y_prev)

    def write(self, inst, extrapolate_from=(), source=None):
        """Write inst's inputs from ``source`` (default: the outputs y); inputs from
        instances in ``extrapolate_from`` are linearly extrapolated over the coming step."""
        if inst not in self.write_ports:
            return
        port, idx, sources = self.write_ports[inst]
        values = (self.y if source is None else source)[idx]
        if extrapolate_from:
            key = (inst, extrapolate_from)
            if key not in self._halves:   # 0.5 where the source is extrapolated, else 0
                self._halves[key] = 0.5 * np.array([s in extrapolate_from for s in sources])
            values = values + self._halves[key] * (values - self.y_prev[idx])
        port.write(values)


class Recorder:
    """Recorded variables streamed to CSV with units in the header; metrics fed at each row."""

    def __init__(self, path, scenario, instances, metrics):
        md = {inst: i.variables for inst, i in instances.items()}
        wanted = list(dict.fromkeys(scenario.record + [r for m in metrics for r in m.needs]))
        self.columns, self.ports, self.slices = [], [], {}
        offset = 0
        for reference in wanted:
            inst = reference.split(".", 1)[0]
            names = expand(md[inst], reference)
            self.ports.append((RealPort(instances[inst], names), slice(offset, offset + len(names))))
            self.slices[reference] = slice(offset, offset + len(names))
            self.columns += [f"{inst}.{n} [{md[inst][n].unit or '1'}]" for n in names]
            offset += len(names)
        self.row = np.zeros(offset)
        self.metrics = metrics
        self.file = open(path, "w", newline="")
        self.writer = csv.writer(self.file)
        self.writer.writerow(["time [s]"] + self.columns)

    def record(self, t):
        for port, where in self.ports:
            self.row[where] = port.read()
        self.writer.writerow([repr(t)] + [repr(v) for v in self.row.tolist()])
        values = {ref: self.row[s] for ref, s in self.slices.items()}
        for metric in self.metrics:
            if t >= metric.start - 1e-12:
                metric.update(t, values)

    def close(self):
        self.file.close()


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
        resolved[inst] = {name: instances[v.instance].get_real(v.variable) if isinstance(v, Link) else v
                          for name, v in parameters.get(inst, {}).items()}
        instances[inst].initialize(scenario.start_time, {**resolved[inst], **exchange.initial_inputs(inst, ready)})
        ready.add(inst)
    return exchange, resolved


def run(scenario, fmu_paths, parameters, outdir, label="run", metrics=(), progress=None):
    """Co-simulate ``scenario`` once. ``fmu_paths``: instance -> FMU file; ``parameters``:
    instance -> {variable: value} (already converted, see spec.bind); results go to
    outdir/<label>.csv. ``progress(done_fraction)`` is called about 200 times."""
    instances = {}
    recorder = None
    h, t0 = scenario.step, scenario.start_time
    steps = int(round((scenario.stop_time - t0) / h))
    done, failure, began = 0, None, time.perf_counter()
    try:
        exchange, _ = start(scenario, fmu_paths, parameters, instances)
        recorder = Recorder(outdir / f"{label}.csv", scenario, instances, list(metrics))
        every = int(round(scenario.record_interval / h))
        order = step_order(scenario, parameters) if scenario.master == "gauss-seidel" else list(scenario.fmus)
        extrapolate = scenario.extrapolation == "linear"
        not_yet = [frozenset(order[i:]) for i in range(len(order))]   # Gauss-Seidel: not stepped yet
        tick = max(1, steps // 200)
        exchange.read()
        exchange.y_prev[:] = exchange.y
        recorder.record(t0)
        began = time.perf_counter()
        for k in range(steps):
            t = t0 + k * h
            if scenario.master == "jacobi":
                source = exchange.extrapolated() if extrapolate and k else exchange.y
                for inst in order:
                    exchange.write(inst, source=source)
                exchange.y_prev[:] = exchange.y
                for inst in order:
                    instances[inst].do_step(t, h)
                exchange.read()
            else:
                previous = exchange.y.copy()
                for i, inst in enumerate(order):
                    exchange.write(inst, not_yet[i] if extrapolate and k else ())
                    instances[inst].do_step(t, h)
                    exchange.read(inst)
                exchange.y_prev[:] = previous
            done = k + 1
            if done % every == 0:
                recorder.record(t0 + done * h)
            if progress and k % tick == 0:
                progress(k / steps)
    except FmuError as error:
        failure = error
    finally:
        wall = time.perf_counter() - began
        if recorder:
            recorder.close()
        for instance in instances.values():
            instance.terminate()
    series = {m.name: m.series() for m in metrics}
    series.update({m.rotation.name: m.rotation.series() for m in metrics if hasattr(m, "rotation")})  # [rad]
    result = Run(label, outdir / f"{label}.csv" if recorder else None, done, wall, done * h,
                 {m.name: m.result() for m in metrics}, series)
    if failure is not None:
        result.failure = failure_line(failure, instances)
        raise RunFailed(str(failure), result) from None
    return result
