"""The master's stepping loop in C (scenarios/cosim/c/cosim.c) and its recording into arrays
(scenarios.cosim.records, written as npz) against the per-step numpy loop and the CSV recorder
they replaced, kept here as the independent reference (a copy of that code driving the
same FMUs through fmpy's ctypes functions): the npz file read back and exported as CSV is
byte for byte the CSV the reference streamed, for every shipped scenario's [ci] version,
Jacobi and Gauss-Seidel, with and without linear extrapolation, native and pythonfmu
FMUs; and the same failure message and partial rows when an FMU call fails mid-run
(doStep, setReal or getReal)."""
import csv
import ctypes
import dataclasses

import numpy as np
import pytest

from scenarios import spec
from scenarios.cosim import master
from scenarios.cosim.fmi import FmuError, Instance, RealPort
from scenarios.cosim.records import read_records
from scenarios.runs import metrics, runner, single
from scenarios.spec import Link, expand

MASTERS = [("jacobi", "none"), ("jacobi", "linear"), ("gauss-seidel", "none"), ("gauss-seidel", "linear")]
SHIPPED = sorted(p.stem for p in runner.SHIPPED.glob("*.toml"))


class ReferenceExchange:
    """Today's (before the C loop) connection data path, verbatim: numpy extrapolation,
    one RealPort read/write per instance."""

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
        if inst not in self.write_ports:
            return {}
        port, idx, sources = self.write_ports[inst]
        for source in set(sources) & ready:
            self.read(source)
        return {name: self.y[k] for name, k, s in zip(port.names, idx, sources) if s in ready}

    def extrapolated(self):
        return self.y + 0.5 * (self.y - self.y_prev)

    def write(self, inst, extrapolate_from=(), source=None):
        if inst not in self.write_ports:
            return
        port, idx, sources = self.write_ports[inst]
        values = (self.y if source is None else source)[idx]
        if extrapolate_from:
            key = (inst, extrapolate_from)
            if key not in self._halves:
                self._halves[key] = 0.5 * np.array([s in extrapolate_from for s in sources])
            values = values + self._halves[key] * (values - self.y_prev[idx])
        port.write(values)


class ReferenceRecorder:
    """The recorder before the arrays: every row formatted in Python (repr, CRLF) and
    streamed to CSV, verbatim; its reads made as master.Recorder makes them (one getReal
    per instance, so that the failing-call tests below count the same calls)."""

    def __init__(self, path, scenario, instances, metrics):
        md = {inst: i.variables for inst, i in instances.items()}
        wanted = list(dict.fromkeys(scenario.record + [r for m in metrics for r in m.needs]))
        self.columns, self.slices, per_instance = [], {}, {}
        offset = 0
        for reference in wanted:
            inst = reference.split(".", 1)[0]
            names = expand(md[inst], reference)
            per_instance.setdefault(inst, []).extend((n, offset + k) for k, n in enumerate(names))
            self.slices[reference] = slice(offset, offset + len(names))
            self.columns += [f"{inst}.{n} [{md[inst][n].unit or '1'}]" for n in names]
            offset += len(names)
        self.ports = [(RealPort(instances[inst], [n for n, _ in cols]), [k for _, k in cols])
                      for inst, cols in per_instance.items()]
        self.row = np.zeros(offset)
        self.metrics = metrics
        self.file = open(path, "w", newline="")
        csv.writer(self.file).writerow(["time [s]"] + self.columns)

    def record(self, t):
        for port, where in self.ports:
            self.row[where] = port.read()
        self.file.write(",".join(map(repr, [t] + self.row.tolist())) + "\r\n")
        values = {ref: self.row[s] for ref, s in self.slices.items()}
        for metric in self.metrics:
            if t >= metric.start - 1e-12:
                metric.update(t, values)

    def close(self):
        self.file.close()


def reference_run(scenario, fmu_paths, parameters, outdir, label, metric_list):
    """Today's single.run with its per-step Python loop (start included: it initialises
    through the reference exchange)."""
    instances, recorder = {}, None
    h, t0 = scenario.step, scenario.start_time
    steps = int(round((scenario.stop_time - t0) / h))
    done, failure = 0, None
    try:
        for inst in scenario.fmus:
            instances[inst] = Instance(fmu_paths[inst], inst)
        exchange = ReferenceExchange(scenario, instances)
        ready = set()
        for inst in master.step_order(scenario, parameters):
            resolved = {name: instances[v.instance].get_real(v.variable) if isinstance(v, Link) else v
                        for name, v in parameters.get(inst, {}).items()}
            instances[inst].initialize(scenario.start_time, {**resolved, **exchange.initial_inputs(inst, ready)})
            ready.add(inst)
        recorder = ReferenceRecorder(outdir / f"{label}.csv", scenario, instances, list(metric_list))
        every = int(round(scenario.record_interval / h))
        order = master.step_order(scenario, parameters) if scenario.master == "gauss-seidel" else list(scenario.fmus)
        extrapolate = scenario.extrapolation == "linear"
        not_yet = [frozenset(order[i:]) for i in range(len(order))]
        exchange.read()
        exchange.y_prev[:] = exchange.y
        recorder.record(t0)
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
    except FmuError as error:
        failure = error
    finally:
        if recorder:
            recorder.close()
        for instance in instances.values():
            instance.terminate()
    result = master.Run(label, outdir / f"{label}.csv" if recorder else None, done, 0.0, done * h,
                        {m.name: m.result() for m in metric_list})
    if failure is not None:
        result.failure = master.failure_line(failure, instances)
        raise master.RunFailed(str(failure), result) from None
    return result


def prepared(name, implementation, master_kind, extrapolation, item=0):
    """A shipped scenario's [ci] version with the given master, at its sweep value number item."""
    scenario, paths, descriptions, values = runner.prepare(runner.resolve(name), ci=True,
                                                           implementation=implementation)
    if scenario.sweep:
        inst, var, value = spec.sweep_value(scenario, descriptions, scenario.sweep[1][item])
        values[inst][var] = value
    return dataclasses.replace(scenario, master=master_kind, extrapolation=extrapolation), paths, values


def csv_text(outdir):
    """The CSV of a run in outdir: the reference's, or single.run's npz read back and exported."""
    if not (outdir / "run.npz").exists():
        return (outdir / "run.csv").read_text()
    return read_records(outdir / "run.npz").to_csv(outdir / "export.csv").read_text()


def same_records(a, b):
    """Two records files hold the same columns, bit for bit (the zip's own timestamps aside)."""
    a, b = read_records(a), read_records(b)
    return a.header == b.header and a.time.tobytes() == b.time.tobytes() and a.values.tobytes() == b.values.tobytes()


def both(scenario, paths, values, tmp_path):
    """(outcome, csv text) of the reference loop and of single.run; an outcome is the
    run's steps and metrics, or the RunFailed message, failure line and steps. The
    records single.run keeps in memory are those of its file."""
    results = []
    for which, run in (("reference", reference_run), ("c", single.run)):
        outdir = tmp_path / which
        outdir.mkdir()
        try:
            done = run(scenario, paths, values, outdir, "run", [metrics.make(m) for m in scenario.metrics])
            outcome = ("ok", done.steps, repr(done.metrics))
        except master.RunFailed as failed:
            done = failed.run
            outcome = ("failed", str(failed), failed.run.failure, failed.run.steps, repr(failed.run.metrics))
        if which == "c":
            on_disk = read_records(done.record_path)
            assert on_disk.names == done.records.names and on_disk.units == done.records.units
            assert on_disk.values.tobytes() == done.records.values.tobytes()
        results.append((outcome, csv_text(outdir)))
    return results


def _loop_cases():
    """Every shipped scene x master on the native FMUs; on the pythonfmu FMUs (~5 s each)
    one scene in the default run, all with -m slow (the default run's 10-minute budget); the
    observer scenes (the realistic loop again, with two more FMUs) on their own master only."""
    for name in SHIPPED:
        for master_kind, extrapolation in MASTERS:
            own = (master_kind, extrapolation) == ("jacobi", "linear")
            yield pytest.param(name, master_kind, extrapolation, "native",
                               marks=[pytest.mark.slow] if name.endswith("_observer") and not own else [])
            slow = [] if name == SHIPPED[0] else [pytest.mark.slow]
            yield pytest.param(name, master_kind, extrapolation, "python", marks=slow)


@pytest.mark.parametrize("name, master_kind, extrapolation, implementation", list(_loop_cases()))
def test_the_c_loop_gives_byte_identical_csvs(name, master_kind, extrapolation, implementation, tmp_path):
    scenario, paths, values = prepared(name, implementation, master_kind, extrapolation)
    (ref, ref_csv), (c, c_csv) = both(scenario, paths, values, tmp_path)
    assert ref[0] == "ok", ref      # a run that completes: the comparison covers every step
    assert c == ref
    assert len(c_csv.splitlines()) > 10
    assert c_csv == ref_csv


@pytest.mark.parametrize("master_kind, step", [("jacobi", 0.016), ("gauss-seidel", 0.032)])
def test_a_failing_dostep_stops_both_loops_alike(master_kind, step, tmp_path):
    """A 16 ms (Jacobi) or 32 ms (Gauss-Seidel) step is past the controller's stability
    limit: a leg leaves its stroke (doStep Discard with a log line) mid-run with the
    fixed-base feedforward."""
    scenario, paths, values = prepared("telescope_slew", "native", master_kind, "linear", item=1)
    scenario = dataclasses.replace(scenario, step=step, record_interval=step)
    (ref, ref_csv), (c, c_csv) = both(scenario, paths, values, tmp_path)
    assert ref[0] == "failed" and "failed in doStep at t = " in ref[1] and "StrokeError" in ref[2], ref
    assert 10 < ref[3] < 500
    assert c == ref
    assert c_csv == ref_csv


def failing_after(monkeypatch, inst, function, calls, status):
    """Make instance ``inst``'s FMI function ``function`` answer ``status`` from its
    ``calls``-th call on (counted over every caller of that instance), for every Instance
    created from now on: the reference and the C loop call it through the same kind of
    address, so both see the same failure if they make the same calls."""
    real_raw = Instance.raw
    kind = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.c_void_p, ctypes.POINTER(ctypes.c_uint), ctypes.c_size_t,
                            ctypes.POINTER(ctypes.c_double))

    def raw(self, name):
        fn = real_raw(self, name)
        if self.name != inst or name != function:
            return fn
        if not hasattr(self, "_failing"):
            count = [0]

            def wrapped(component, vr, n, values):
                count[0] += 1
                return status if count[0] >= calls else fn(component, vr, n, values)
            self._failing = kind(wrapped)    # kept alive with the instance
        return self._failing
    monkeypatch.setattr(Instance, "raw", raw)


@pytest.mark.parametrize("master_kind", ["jacobi", "gauss-seidel"])
@pytest.mark.parametrize("inst, function, calls, status", [("controller", "fmi2SetReal", 1234, 3),
                                                           ("plant", "fmi2GetReal", 777, 2),
                                                           ("base", "fmi2GetReal", 501, 4)])
def test_a_failing_get_or_set_stops_both_loops_alike(master_kind, inst, function, calls, status, monkeypatch,
                                                      tmp_path):
    """getReal/setReal answering Error/Discard/Fatal mid-run: the same message (call,
    instance, time, status, log), steps, metrics and partial CSV as the Python loop."""
    failing_after(monkeypatch, inst, function, calls, status)
    scenario, paths, values = prepared("paper_manoeuvre", "native", master_kind, "linear")
    (ref, ref_csv), (c, c_csv) = both(scenario, paths, values, tmp_path)
    call = function.removeprefix("fmi2")
    call = call[0].lower() + call[1:]
    assert ref[0] == "failed" and f"FMU instance '{inst}' failed in {call} at t = " in ref[1], ref
    assert c == ref
    assert c_csv == ref_csv


def test_progress_is_reported_as_the_python_loop_did_and_changes_nothing(tmp_path):
    """With a progress callback the C loop also stops at every progress point: the
    callback sees k / steps after each step k with k % tick == 0 (tick = steps // 200, as
    the Python loop called it) and the records are those of a run without progress."""
    scenario, paths, values = prepared("paper_manoeuvre", "native", "jacobi", "linear")
    seen = []
    for outdir, progress in ((tmp_path / "with", seen.append), (tmp_path / "without", None)):
        outdir.mkdir()
        single.run(scenario, paths, values, outdir, "run", [], progress)
    steps = round((scenario.stop_time - scenario.start_time) / scenario.step)
    tick = max(1, steps // 200)
    assert seen == [k / steps for k in range(steps) if k % tick == 0]
    assert same_records(tmp_path / "with" / "run.npz", tmp_path / "without" / "run.npz")


def test_a_long_unrecorded_run_returns_to_python_every_chunk(monkeypatch, tmp_path):
    """A run recording only its ends still leaves C every single.CHUNK steps (so Ctrl-C is
    seen within one chunk), with the records of a run stepped in one call; an interrupt
    between chunks propagates and leaves the records made so far written."""
    scenario, paths, values = prepared("paper_manoeuvre", "native", "jacobi", "linear")
    scenario = dataclasses.replace(scenario, metrics=[], record_interval=scenario.stop_time - scenario.start_time)
    steps = round((scenario.stop_time - scenario.start_time) / scenario.step)
    assert steps > 3 * 512
    counts, real_steps = [], master.Loop.steps

    def counted(self, k, count):
        counts.append(count)
        return real_steps(self, k, count)
    monkeypatch.setattr(master.Loop, "steps", counted)
    for outdir, chunk in ((tmp_path / "chunked", 512), (tmp_path / "whole", 10 * steps)):
        outdir.mkdir()
        monkeypatch.setattr(single, "CHUNK", chunk)
        counts.clear()
        single.run(scenario, paths, values, outdir, "run")
        assert sum(counts) == steps and max(counts) == min(chunk, steps)
    assert same_records(tmp_path / "chunked" / "run.npz", tmp_path / "whole" / "run.npz")

    def interrupted(self, k, count):
        if k > 0:
            raise KeyboardInterrupt
        return real_steps(self, k, count)
    monkeypatch.setattr(master.Loop, "steps", interrupted)
    monkeypatch.setattr(single, "CHUNK", 512)
    (tmp_path / "stopped").mkdir()
    with pytest.raises(KeyboardInterrupt):
        single.run(scenario, paths, values, tmp_path / "stopped", "run")
    stopped = read_records(tmp_path / "stopped" / "run.npz")
    assert stopped.time.tolist() == [0.0]   # the t0 row, on disk


def test_gauss_seidel_steps_in_source_order_whatever_the_file_lists():
    """The realistic slew with its instances listed controller, sensor, plant, base: the
    order worked out by hand from its connections is base (no inputs), then the
    controller -> plant -> sensor -> controller cycle broken at the plant (its lengths
    come from its state, not from its force of the same step), then sensor and
    controller. Its Gauss-Seidel records equal, bit for bit, those of the same scene
    listed in that order (every shipped file lists its sources first, so a reversed
    order passed the earlier tests)."""
    import movingbase
    text = (runner.SHIPPED / "telescope_slew_realistic.toml").read_text().replace(
        'master = "jacobi"', 'master = "gauss-seidel"').replace('stop_time = "60 s"', 'stop_time = "5.2 s"')
    tables = {}
    for name in ("base", "plant", "sensor", "controller"):
        start = text.index(f"[fmus.{name}]")
        end = min(i for i in (text.find("\n[", start + 1), text.find("\n[[", start + 1)) if i > 0)
        tables[name] = text[start:end + 1]
    for name in tables:
        text = text.replace(tables[name], "")
    head, tail = text.split("[[connections]]", 1)

    def listed(order):
        return head + "".join(tables[n] for n in order) + "[[connections]]" + tail

    permuted = spec.parse(listed(["controller", "sensor", "plant", "base"]), "permuted.toml")
    assert list(permuted.fmus) == ["controller", "sensor", "plant", "base"]
    assert master.step_order(permuted) == ["base", "plant", "sensor", "controller"]
    runs = {}
    for order in (["controller", "sensor", "plant", "base"], ["base", "plant", "sensor", "controller"]):
        runs[tuple(order)] = movingbase.run(spec.parse(listed(order), "s.toml"), progress=False)
    first, second = runs.values()
    for label in first.runs:
        assert first[label].sim_time == pytest.approx(5.2) and not first[label].failure
        assert first[label].values.tobytes() == second[label].values.tobytes(), label
