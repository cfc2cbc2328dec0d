"""What a run will cost before it starts: its steps, its time, the disk its records take,
and the workers a machine can hold. A run that cannot finish (more disk than is free,
more workers than memory, months of stepping) is refused with the estimate; one that is
merely large runs, after a warning that gives the estimate. Costs are counted from the
scenario's numbers alone (no FMU is loaded), so the check is free next to the run."""
import dataclasses
import numbers
import os
import pathlib
import shutil

from scenarios.spec import expand

# seconds per instance per macro step (a 30 s slew at 1 ms, 3 instances, docs/speed.md:
# native 0.42 s, pythonfmu 2.70 s) and per recorded row (CSV formatting, ~35 us)
STEP_SECONDS = {"native": 4.7e-6, "python": 30e-6}
ROW_SECONDS = 35e-6
BYTES_PER_VALUE = 8            # a float64 in memory (Records, preallocated per run) and in its npz
WORKER_BYTES = 300 << 20       # one worker process with its FMUs loaded
REFUSE_SECONDS = 30 * 86400    # longer than this is no run anyone waits for
WARN_SECONDS = 600
WARN_BYTES = 1 << 30


class ResourceError(ValueError):
    """A run or campaign that cannot finish here; the message gives the estimate."""


@dataclasses.dataclass
class Estimate:
    runs: int
    steps: int                  # per run
    rows: int                   # recorded rows per run
    columns: int
    seconds: float              # all runs, on one core
    disk_bytes: float           # all runs' records
    run_bytes: float = 0.0      # one run's records in memory (the largest run's)

    def text(self):
        steps = f"{self.steps:,}" if self.steps < 1e15 else f"{self.steps:.3g}"    # not 300 digits
        return (f"{self.runs} run{'s' if self.runs != 1 else ''} of {steps} steps, ~{_duration(self.seconds)} "
                f"of stepping on one core, ~{_size(self.disk_bytes)} of records")


def _duration(seconds):
    for unit, size in (("days", 86400), ("h", 3600), ("min", 60)):
        if seconds >= 2 * size:
            return f"{seconds / size:.3g} {unit}"
    return f"{seconds:.3g} s"


def _size(count):
    for unit, size in (("TB", 1e12), ("GB", 1e9), ("MB", 1e6), ("kB", 1e3)):
        if count >= size:
            return f"{count / size:.3g} {unit}"
    return f"{count:.0f} B"


def estimate(scenario, descriptions=None, runs=1, keep_records=True):
    """The cost of ``runs`` runs of ``scenario``; ``descriptions`` (instance -> model
    description) sizes the recorded vectors (without: one column per name)."""
    steps = round((scenario.stop_time - scenario.start_time) / scenario.step)
    rows = steps // max(1, round(scenario.record_interval / scenario.step)) + 1 if scenario.record else 0
    columns = 0
    for reference in scenario.record:
        inst = reference.split(".", 1)[0]
        variables = {v.name: v for v in descriptions[inst].modelVariables} if descriptions else {}
        columns += len(expand(variables, reference)) if descriptions else 1
    per_step = sum(STEP_SECONDS.get(scenario.implementations.get(i, "native"), STEP_SECONDS["python"])
                   for i in scenario.fmus)
    seconds = runs * (steps * per_step + rows * ROW_SECONDS)
    memory = rows * (columns + 1) * BYTES_PER_VALUE
    return Estimate(runs, steps, rows, columns, seconds, runs * memory if keep_records else 0, memory)


def combined(estimates):
    """One Estimate of runs of several settings (a campaign's top-level settings vary per
    run): times and disk add up, steps, rows and a run's memory are the largest run's."""
    return Estimate(sum(e.runs for e in estimates), max(e.steps for e in estimates),
                    max(e.rows for e in estimates), max(e.columns for e in estimates),
                    sum(e.seconds for e in estimates), sum(e.disk_bytes for e in estimates),
                    max(e.run_bytes for e in estimates))


def free_bytes(folder):
    """Free space on the disk that holds ``folder`` (or its nearest existing parent)."""
    folder = pathlib.Path(folder).absolute()
    while not folder.exists():
        folder = folder.parent
    return shutil.disk_usage(folder).free


def check(cost, out, what):
    """ResourceError for what cannot finish; the warning text (or "") for what is large."""
    free = free_bytes(out)
    if cost.disk_bytes > free:
        raise ResourceError(f"{what}: {cost.text()}; the records need more than the {_size(free)} free under "
                            f"{out}: shorten stop_time, record fewer variables or a longer record.interval")
    memory = available_memory()
    if memory is not None and cost.run_bytes > memory:
        raise ResourceError(f"{what}: {cost.text()}; one run's records need ~{_size(cost.run_bytes)} of memory, "
                            f"{_size(memory)} is available: shorten stop_time, record fewer variables or a longer "
                            "record.interval")
    if cost.seconds > REFUSE_SECONDS:
        raise ResourceError(f"{what}: {cost.text()}: it would not finish; shorten stop_time or lengthen step")
    if cost.seconds > WARN_SECONDS or cost.disk_bytes > WARN_BYTES:
        return f"{what}: large: {cost.text()}"
    return ""


def cores():
    """All cores this process may use."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:          # not Linux
        return os.cpu_count() or 1


def available_memory():
    """Bytes of memory available for new processes (Linux /proc/meminfo), or None."""
    try:
        with open("/proc/meminfo") as file:
            for line in file:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    return None


def check_jobs(jobs, name="--jobs"):
    """ResourceError for a worker count below 1 or beyond what memory holds; the warning
    text (or "") where it exceeds the cores (the workers then share them). Any integer type
    (numpy's too) is a count; ``name`` is the argument as the caller wrote it ("--jobs" on
    the command line, "jobs" from Python), and a value that is no integer is a TypeError there."""
    if jobs is None:
        return ""
    said = f"--jobs {jobs}" if name == "--jobs" else f"{name}={jobs!r}"
    if isinstance(jobs, bool) or not isinstance(jobs, numbers.Integral):
        if name == "--jobs":
            raise ResourceError(f"{said}: the number of worker processes must be a whole number of at least 1")
        raise TypeError(f"{name} must be an integer (the number of worker processes) or None, not "
                        f"{type(jobs).__name__} {jobs!r:.60}")
    jobs = int(jobs)
    if jobs < 1:
        raise ResourceError(f"{said}: the number of worker processes must be a whole number of at least 1")
    memory = available_memory()
    if memory is not None and jobs * WORKER_BYTES > memory:
        raise ResourceError(f"{said}: {jobs} worker processes need ~{_size(jobs * WORKER_BYTES)} of memory; "
                            f"{_size(memory)} is available (at most {max(1, memory // WORKER_BYTES)} workers here)")
    if jobs > cores():
        return f"{said}: more workers than the {cores()} cores here; they share them (no faster than {cores()})"
    return ""
