"""One run of a scenario: the master's stepping loop (scenarios.cosim.master) watched by
the guard (scenarios.runs.flags), its metrics taken from the rows as they are recorded, and
the run's flags when it ends. Here, above the co-simulation layer, so that the master
knows nothing of what watches it."""
import importlib.util
import pathlib
import sys
import time

import numpy as np

from scenarios.cosim.fmi import FmuError
from scenarios.cosim.master import Loop, Recorder, Run, RunFailed, failure_line, start, step_order
from scenarios.runs import flags as run_flags
from scenarios.spec import file_label


def progress_bar(**kwargs):
    """A tqdm bar; in a Jupyter kernel its notebook form (a widget, where ipywidgets is
    installed), else one that redraws at most every NOTEBOOK_INTERVAL s: a notebook keeps
    every carriage-return update of a terminal bar in its saved output. With ``disable``
    a Hidden bar: tqdm is not imported for it (18 ms of a run's process)."""
    if kwargs.get("disable"):
        return Hidden()
    from tqdm import tqdm
    if "ipykernel" not in sys.modules:
        return tqdm(**kwargs)
    if importlib.util.find_spec("ipywidgets"):
        from tqdm.notebook import tqdm as notebook_tqdm
        kwargs.pop("bar_format", None)     # the widget draws its own bar
        return notebook_tqdm(**kwargs)
    return tqdm(mininterval=NOTEBOOK_INTERVAL, **kwargs)


class Hidden:
    """A progress bar not shown: the calls of a tqdm bar the runs make, doing nothing."""

    n = 0

    def update(self, n=1):
        pass

    def set_description_str(self, desc=None, refresh=True):
        pass

    def set_postfix(self, ordered_dict=None, refresh=True, **kwargs):
        pass

    def close(self):
        pass


NOTEBOOK_INTERVAL = 5.0
CHUNK = 2048   # most macro steps per C call: Ctrl-C is seen within one (~10 ms native, ~0.1 s pythonfmu)


def run(scenario, fmu_paths, parameters, outdir=None, label="run", metrics=(), progress=None, flags=(),
        save_later=False):
    """Co-simulate ``scenario`` once. ``fmu_paths``: instance -> FMU file; ``parameters``:
    instance -> {variable: value} (already converted, see spec.bind). The records stay in
    memory (Run.records); with an ``outdir`` they are also written to outdir/<label>.npz (the
    label made a file name: spec.file_label)
    (also those of a run that fails or is interrupted); ``save_later``: on a thread, in
    place once fmu_src.atomic.settle() has returned (Records.save). ``progress(done_fraction)`` is
    called about 200 times. Run.flags: ``flags`` known before the run, the detectors'
    (scenarios.runs.flags.Watch, fed every row read), the FMUs' warnings and a stop before
    stop_time. The metrics and the watch read a row every record.metric_interval (default:
    record.interval); the records keep every record.interval's, so a long run's records stay
    small while its peaks are still seen at every row read."""
    instances = {}
    recorder = None
    h, t0 = scenario.step, scenario.start_time
    steps = int(round((scenario.stop_time - t0) / h))
    every = int(round(scenario.read_interval / h))            # steps between the rows the metrics read
    keep = int(round(scenario.record_interval / scenario.read_interval))   # read rows per recorded row
    path = None if outdir is None else pathlib.Path(outdir) / f"{file_label(label)}.npz"
    done, failure, began, cpu_began, watch = 0, None, time.perf_counter(), time.thread_time(), None
    try:
        exchange, _ = start(scenario, fmu_paths, parameters, instances)
        watch = run_flags.Watch.for_scenario(scenario, {k: i.md for k, i in instances.items()}, parameters)
        recorder = Recorder(scenario, instances, list(metrics), steps // every + 1, watch, keep)
        order = step_order(scenario, parameters) if scenario.master == "gauss-seidel" else list(scenario.fmus)
        loop = Loop(exchange, instances, order, scenario.master == "gauss-seidel", scenario.extrapolation, t0, h,
                    recorder, every)
        tick = max(1, steps // 200)
        exchange.read()
        exchange.y_prev[:] = exchange.y
        loop.record_row()
        recorder.take(np.array([t0]), loop.rows)
        loop.check()
        began, cpu_began = time.perf_counter(), time.thread_time()
        while done < steps:   # C runs the steps and records their rows, up to a progress point or a full block
            stop = min(steps, done + CHUNK)
            if progress:
                stop = min(stop, (done - 1) // tick * tick + tick + 1)   # after step k with k % tick == 0
            first = done // every + 1   # the record point the next row is taken at
            done += loop.steps(done, stop - done)
            recorder.take(t0 + (first + np.arange(loop.rows)) * every * h, loop.rows)
            loop.check()
            if progress and (done - 1) % tick == 0:
                progress((done - 1) / steps)
    except FmuError as error:
        failure = error
    finally:
        wall, cpu = time.perf_counter() - began, time.thread_time() - cpu_began
        if recorder and path:
            recorder.records.save(path, later=save_later)
        for instance in instances.values():
            instance.terminate()
    series = {m.name: m.series() for m in metrics}
    series.update({m.rotation.name: m.rotation.series() for m in metrics if hasattr(m, "rotation")})  # [rad]
    result = Run(label, path if recorder else None, done, wall, done * h,
                 {m.name: m.result() for m in metrics}, series, records=recorder.records if recorder else None,
                 cpu_time=cpu)
    if failure is not None:
        result.failure = failure_line(failure, instances)
    result.flags = run_flags.run_flags(watch, result, instances, flags) + (run_flags.sampling_flags(
        metrics, scenario.read_interval, "record.metric_interval" if scenario.metric_interval else "record.interval")
        if failure is None else [])   # cut short: its rows end early
    if failure is not None:
        raise RunFailed(str(failure), result) from None
    return result
