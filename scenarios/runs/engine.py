"""Many independent co-simulation runs (sweep values, study grids, campaign cases) on a
Dask distributed cluster: a LocalCluster of worker processes by default, or an existing
cluster given its scheduler's address. Both go through the same code path.

Why this shape:

* A run is a ``Job``: the checked scenario, its bound parameter values, and the content
  digest of every FMU it needs (scenarios.cosim.fmi.content_digest: the same for two builds of
  the same sources). Its key is a hash of exactly what decides its numbers (time grid,
  master, connections, recording, metrics, parameters, FMU contents, the kit's own code:
  ``code_digest``), so a result on disk is found again by any later campaign that asks
  for the same run, after a rebuild too, and never by other code.
* The FMU files travel once to every worker (scattered, not per task); each worker
  process writes them to a local folder and extracts each once (``scenarios.cosim.fmi.unpack``
  caches by path). A run then instantiates its FMUs from the extracted folders: ~13 ms
  against seconds for the run, and a fresh instance is the only reset that cannot leak
  state from one run into the next.
* A worker runs one job at a time (a lock per process: pythonfmu FMUs share one GIL and
  stepping them from threads is slower), and never raises for a failed run: the failure
  comes back as a result with its message, and the other runs go on.
* Results come back to the client, which writes them (so workers need no shared disk):
  ``<key>.npz`` (metric series), ``<key>.records.npz`` (recorded variables, if kept), then
  ``<key>.json`` last, atomically: a run counts as done exactly when its JSON exists.
  An interrupted campaign (Ctrl-C, a killed worker or client) resumes by skipping the
  keys on disk. At most a few jobs per worker are in flight, so the client's memory
  does not grow with the number of runs; summaries are read back from the files.

Results are bit-for-bit those of a sequential ``scenarios.runs.single.run`` in one process:
each run is the same deterministic computation in a fresh set of instances; floats go
through JSON as their repr (exact) and series through npz.
"""
import contextlib
import dataclasses
import functools
import hashlib
import importlib.util
import json
import logging
import os
import pathlib
import re
import shutil
import signal
import socket
import sys
import threading
import time
from itertools import islice

import numpy as np

from fmu_src.atomic import replacing, write_bytes
from scenarios.cosim import fmi, master
from scenarios.cosim.fmi import content_digest
from scenarios.runs import flags, metrics, single, status
from scenarios.runs.estimates import cores
from scenarios.spec import Link, file_label, run_label

RECORDS = ".records.npz"     # a kept run's recorded variables (scenarios.cosim.records), next to <key>.json
# Runs per Dask task, at most: each task costs the client ~10 ms of CPU (scheduler and
# messages, in the client's process for a local cluster), as much as 4 % of a 30 s slew;
# in tasks of 4 runs a quarter of it. Fewer when there are few runs (every worker gets
# at least 4 tasks, so none idles long at the end); a lost task runs its batch again.
BATCH = 4

# Dask's statistical profiler samples the worker's threads every 10 ms: it took ~13 % of a
# run's CPU (benchmarks/bench_campaign.py). Its periodic housekeeping (the event loop's
# 20 ms tick, the 0.5 s system monitor, the workers' 0.1 s memory monitor, work stealing's
# 0.1 s balancing) cost the client and 2 workers 70 ms of CPU a second between them, ~8 ms
# a 30 s slew; at these intervals 13 ms a second. Set for local clusters; for a cluster's
# workers the same through DASK_* variables (docs/campaigns.md).
WORKER_CONFIG = {"distributed.worker.profile.enabled": False, "distributed.admin.tick.interval": "1s",
                 "distributed.admin.system-monitor.interval": "5s", "distributed.worker.memory.monitor-interval": "1s",
                 "distributed.scheduler.work-stealing": False}
_RUN_LOCK = threading.Lock()        # one run at a time per worker process
_FMU_DIR = None                     # this worker process's copies of the FMU files
_FMU_FILES: dict = {}                     # sha256 -> local FMU path


default_jobs = cores                # all cores this process may use


class EngineError(ValueError):
    """A cluster that cannot be used (an address that is malformed or does not answer)."""


def check_address(address, timeout=5.0):
    """EngineError naming the problem for a Dask scheduler address that is malformed or
    where nothing answers within ``timeout`` s: told before anything runs."""
    match = re.fullmatch(r"(?:(?:tcp|tls)://)?(\[[^\]]+\]|[^:/\s]+):(\d{1,5})", str(address))
    if not match or not 0 < int(match.group(2)) < 65536:
        raise EngineError(f"--dask {address!r}: expected a scheduler address tls://HOST:PORT or tcp://HOST:PORT")
    host, port = match.group(1).strip("[]"), int(match.group(2))
    try:
        socket.create_connection((host, port), timeout=timeout).close()
    except OSError as exc:
        raise EngineError(f"--dask {address}: no scheduler answers at {host}:{port} "
                          f"({exc.strerror or type(exc).__name__}); start one or check the address") from None


def file_digest(path):
    """The FMU's content digest (scenarios.cosim.fmi.content_digest): a rebuild of the same
    sources keeps every cached result's key."""
    return content_digest(path)


def _plain(value):
    """JSON-able form of a bound parameter value (a Link as its '@inst.var' text)."""
    if isinstance(value, Link):
        return f"@{value.instance}.{value.variable}"
    if isinstance(value, (np.floating, np.integer)):
        return value.item()
    return value


@dataclasses.dataclass(frozen=True)
class Job:
    """One run: scenario, bound parameters per instance, FMU digests per instance."""

    label: str
    scenario: object
    parameters: dict
    fmus: dict                      # instance -> sha256 of its FMU file
    keep_record: bool = True        # store the recorded variables too
    flags: tuple = ()               # scenarios.runs.flags.Flag known before the run (its motion's); not in the key
    key: str = ""

    def __post_init__(self):
        if not self.key:
            object.__setattr__(self, "key", run_key(self.scenario, self.parameters, self.fmus))


def code_digest(roots=None):
    """SHA-256 of the kit's own sources (.py, .c, .h under ``roots``, by default the folders of
    plant, controller, fmu_src and scenarios): what decides a run's numbers beside
    its FMUs and settings (the master, metrics and flags; for the pythonfmu FMUs the models
    themselves, which they import from this package at run time, so their FMU files stay the
    same when the physics changes). An edited or upgraded kit's results on disk are run again."""
    if roots is None:
        return _package_digest()
    digest = hashlib.sha256()
    for root in map(pathlib.Path, roots):
        for path in sorted(p for p in root.rglob("*") if p.suffix in (".py", ".c", ".h") and p.is_file()
                           and "__pycache__" not in p.parts):
            digest.update(f"{path.relative_to(root.parent)}:{path.stat().st_size}:".encode() + path.read_bytes())
    return digest.hexdigest()


@functools.cache
def _package_digest():
    return code_digest([importlib.util.find_spec(name).submodule_search_locations[0]
                        for name in ("plant", "controller", "fmu_src", "scenarios")])


def run_key(scenario, parameters, fmus):
    """Hash of what decides a run's numbers; names, descriptions and the file's path do not,
    nor the requirements: they are judged from a run's metrics after it (never stored with
    its outcome), so a cached run is judged by the scenario's current requirements."""
    s = scenario
    what = {"code": code_digest(), "time": [s.start_time, s.stop_time, s.step], "master": s.master,
            "extrapolation": s.extrapolation,
            "fmus": {inst: [s.fmus[inst], fmus[inst]] for inst in sorted(s.fmus)},
            "connections": s.connections, "record": [s.record_interval, s.record, s.metric_interval],
            "metrics": [[m.name, m.kind, m.args, m.start] for m in s.metrics],
            "parameters": {inst: {k: _plain(v) for k, v in sorted(p.items())} for inst,
                           p in sorted(parameters.items())}}
    return hashlib.sha256(json.dumps(what, sort_keys=True).encode()).hexdigest()[:24]


# ------------------------------------------------------------------------ worker side
def _local_fmu(digest, blobs):
    """This process's copy of an FMU file (written once; fmi.unpack extracts it once)."""
    global _FMU_DIR
    if digest not in _FMU_FILES:
        if _FMU_DIR is None:
            _FMU_DIR = pathlib.Path(fmi.scratch("movingbase-fmus-"))
        path = _FMU_DIR / f"{digest}.fmu"
        path.write_bytes(blobs[digest])
        _FMU_FILES[digest] = path
    return _FMU_FILES[digest]


def _outcome(run):
    return {"metrics": run.metrics, "steps": run.steps, "run_time_s": run.wall_time, "sim_time_s": run.sim_time,
            "flags": flags.as_dicts(run.flags),
            "series": {name: (np.asarray(t), np.asarray(v)) for name, (t, v) in run.series.items()}}


def execute_batch(jobs, blobs):
    """Run several jobs in one task, one after the other (execute each)."""
    return [execute(job, blobs) for job in jobs]


def execute(job, blobs):
    """Run one job where this is called; a failing run returns its message instead of raising."""
    with _RUN_LOCK:
        began, cpu = time.perf_counter(), time.process_time()
        out = {"key": job.key, "label": job.label, "worker": f"{socket.gethostname()}:{os.getpid()}"}
        partial = None
        try:
            paths = {inst: _local_fmu(digest, blobs) for inst, digest in job.fmus.items()}
            run_cpu = time.process_time()
            partial = single.run(job.scenario, paths, job.parameters, None, "run",
                                 [metrics.make(m) for m in job.scenario.metrics], flags=job.flags)
            out.update(status="ok", run_cpu_s=time.process_time() - run_cpu, **_outcome(partial))
        except Exception as exc:          # the run's failure is a result; others go on
            partial = getattr(exc, "run", None)   # what a run that stopped early did
            out.update(status="failed", error=getattr(partial, "failure", "") or f"{type(exc).__name__}: {exc}")
            if partial is not None:
                out.update(_outcome(partial))
        if job.keep_record and partial is not None and partial.records is not None:
            out["record"] = partial.records     # in memory; no record kept: nothing written
        out["task_time_s"] = time.perf_counter() - began
        out["task_cpu_s"] = time.process_time() - cpu     # this process's CPU (the worker's own threads too)
        return out


# ------------------------------------------------------------------------ results on disk
class Store:
    """One folder of run results keyed by run key: <key>.json (written last), <key>.npz,
    <key>.records.npz (scenarios.cosim.records)."""

    def path(self, key, suffix):
        return self.folder / f"{key}{suffix}"

    def __init__(self, folder):
        self.folder = pathlib.Path(folder)
        self.folder.mkdir(parents=True, exist_ok=True)
        self.damaged = {}           # key -> what is wrong with its files (run again)

    def status(self, key):
        """'ok', 'failed' or None: not run yet, or one of its files is missing, truncated or
        corrupt (every file the JSON names is checked against its digest; the fault is
        named in ``damaged`` and the run is run again, never taken as good)."""
        path = self.path(key, ".json")
        if not path.exists():
            return None
        try:
            record = json.loads(path.read_text(encoding="utf-8"))
            status = record["status"]
        except (ValueError, KeyError, TypeError, UnicodeDecodeError) as exc:
            self.damaged[key] = f"{path}: unreadable ({type(exc).__name__}: {exc})"
            return None
        if status not in ("ok", "failed"):
            self.damaged[key] = f"{path}: unknown status {status!r}"
            return None
        files = record.get("files")
        if not isinstance(files, dict) or (status == "ok" and ".npz" not in files):
            self.damaged[key] = f"{path}: names no digests of its files (written by an older kit, or damaged)"
            return None
        for suffix, digest in files.items():
            other = self.path(key, suffix)
            if not other.is_file():
                self.damaged[key] = f"{other}: missing"
                return None
            if _sha256(other) != digest:
                self.damaged[key] = f"{other}: truncated or corrupt (its SHA-256 is not the one {path.name} names)"
                return None
        return status

    def keys(self):
        """Keys of every result on disk."""
        return {p.name.removesuffix(".json") for p in self.folder.glob("*.json")}

    def read(self, key):
        return json.loads(self.path(key, ".json").read_text(encoding="utf-8"))

    def series(self, key):
        """{metric: (t, values)} of a run (a failed one: as far as it got, if at all)."""
        with np.load(self.path(key, ".npz")) as data:
            names = sorted({k.rsplit("/", 1)[0] for k in data.files})
            return {n: (data[f"{n}/t"], data[f"{n}/values"]) for n in names}

    def write(self, job, result):
        """The run's files, each atomically (fmu_src.atomic), then <key>.json last: it names
        every other file with its SHA-256 (``files``), so a file damaged later is found."""
        key, files = job.key, {}
        if "record" in result:
            files[RECORDS] = result.pop("record").save(self.path(key, RECORDS))
        if "series" in result:
            series = result.pop("series")
            with replacing(self.path(key, ".npz")) as tmp:
                np.savez(tmp, **{f"{n}/{part}": a for n, (t, v) in series.items()
                                 for part, a in (("t", t), ("values", v))})
            files[".npz"] = self.path(key, ".npz")
        record = {**result, "scenario": job.scenario.name,
                  "parameters": {i: {k: _plain(v) for k, v in p.items()} for i, p in job.parameters.items()},
                  "files": {suffix: _sha256(path) for suffix, path in files.items()}}
        write_bytes(self.path(key, ".json"), json.dumps(record, indent=1, default=float).encode())


def _sha256(path):
    digest = hashlib.sha256()
    with open(path, "rb") as file:
        for block in iter(lambda: file.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


# ------------------------------------------------------------------------ the engine
@dataclasses.dataclass
class Outcome:
    """What one call of Engine.run did: keys computed now, keys found on disk, failures."""

    total: int
    computed: list
    skipped: list
    failed: dict                    # key -> message (run failures and lost tasks)
    wall_time: float
    interrupted: bool = False
    damaged: dict = dataclasses.field(default_factory=dict)    # key -> the fault found (recomputed)
    orphans: int = 0                # results in the store that belong to none of these jobs
    statuses: dict = dataclasses.field(default_factory=dict)   # key -> status (scenarios.runs.status) of those run now


@contextlib.contextmanager
def _workers_scratch(engine):
    """The worker processes started with $MOVINGBASE_SCRATCH set to one folder of this
    process (fmi.scratch), which Engine.close removes: a worker killed (SIGTERM, SIGKILL)
    runs no exit handler, and its unpacked FMUs stayed in TMPDIR."""
    import dask
    engine.scratch = fmi.scratch("movingbase-workers-")
    previous = os.environ.get(fmi.SCRATCH)
    os.environ[fmi.SCRATCH] = engine.scratch
    try:
        with dask.config.set({"temporary-directory": engine.scratch}):    # Dask's own dask-scratch-space
            yield
    finally:
        if previous is None:
            del os.environ[fmi.SCRATCH]
        else:
            os.environ[fmi.SCRATCH] = previous


@contextlib.contextmanager
def _workers_ignore_ctrl_c():
    """SIGINT ignored while the worker processes start: they inherit the ignored SIGINT
    (a blocked one they would not), so Ctrl-C reaches the client alone and the campaign
    ends in one message, not one traceback per worker. The price: a Ctrl-C in the few
    seconds the workers take to start is not seen (press it again)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)


MAIN_GUARD = ("From a script, call the campaign under `if __name__ == \"__main__\":`: each worker is a new "
              "Python process that imports the script, and the call at its top level would start the campaign "
              "again in every worker (Python's multiprocessing rule).")


def started_by_a_worker():
    """True when a worker process, importing the user's script (as ``__mp_main__``), reaches
    a campaign call at its top level: the script has no main guard (MAIN_GUARD). (The
    worker's multiprocessing state is set only after that import: the stack tells.)"""
    frame = sys._getframe(1)
    while frame is not None:
        if frame.f_code.co_name == "<module>" and frame.f_globals.get("__name__") == "__mp_main__":
            return True
        frame = frame.f_back
    return False


CREDENTIALS = ("DASK_DISTRIBUTED__COMM__TLS__CA_FILE, DASK_DISTRIBUTED__COMM__TLS__CLIENT__CERT and "
               "DASK_DISTRIBUTED__COMM__TLS__CLIENT__KEY (python -m scenarios.runs.deploy credentials DIR prints them)")


def _connect(client, address, security):
    """A Client of the scheduler at ``address``; EngineError naming the credentials if a TLS
    scheduler is asked for without them or refuses the ones given (a handshake it ends)."""
    from distributed.security import Security
    security = security or Security()       # None: Dask's configuration, the DASK_... variables
    if str(address).startswith("tls://") and not (security.tls_client_cert and security.tls_ca_file):
        raise EngineError(f"--dask {address}: a TLS scheduler admits only clients with its credentials; this client "
                          f"has none: set {CREDENTIALS}")
    try:
        return client(address, timeout=30, security=security)
    except (OSError, TimeoutError) as exc:
        raise EngineError(f"--dask {address}: the scheduler did not take this client ({type(exc).__name__}: {exc}); "
                          f"a TLS scheduler refuses credentials of another CA and a tcp:// client: check {CREDENTIALS}"
                          ) from None


class Engine:
    """A Dask client: on a new LocalCluster of ``jobs`` worker processes (default: all
    cores), or on the existing cluster at ``address`` (``tls://host:port``, or ``tcp://``).
    A Dask scheduler runs whatever it is sent, so the LocalCluster speaks TLS with
    credentials made for it alone (Security.temporary(): a CA and certificate in this
    process's memory, handed to its workers), and admits only clients that hold them:
    another user of the machine who reaches its port on 127.0.0.1 is refused. At
    ``address``, ``security`` (a distributed.security.Security) or, if None, Dask's
    configuration (DASK_DISTRIBUTED__COMM__TLS__... variables: scenarios.runs.deploy)
    gives the client's credentials."""

    def __init__(self, jobs=None, address=None, security=None):
        jobs = jobs or default_jobs()
        if jobs < 1:
            raise ValueError(f"--jobs must be at least 1, got {jobs}")
        self.jobs, self.address, self.security = jobs, address, security
        self.cluster = self._client = None
        self.start_time = None      # seconds to start the cluster / connect, once done
        self._blobs = {}            # FMU digests -> scattered future of the FMU bytes
        self.scratch = None         # the workers' temporary folders (fmi.SCRATCH), removed at close

    @property
    def client(self):
        """The Dask client, started on first use (nothing to run: no cluster)."""
        if self._client is None:
            import dask
            from distributed import Client, LocalCluster
            began = time.perf_counter()
            if self.address:
                self._client = _connect(Client, self.address, self.security)
            else:
                from distributed.security import Security
                self.security = Security.temporary()
                with dask.config.set(WORKER_CONFIG), _workers_ignore_ctrl_c():
                    try:
                        with _workers_scratch(self):
                            self.cluster = LocalCluster(n_workers=self.jobs, threads_per_worker=1, processes=True,
                                                        dashboard_address=None, silence_logs=logging.CRITICAL,
                                                        host="127.0.0.1", security=self.security)
                    except RuntimeError as exc:     # "Nanny failed to start", after each worker's traceback
                        raise RuntimeError(f"the {self.jobs} worker processes did not start ({exc}). {MAIN_GUARD}"
                                           ) from None
                    self._client = Client(self.cluster)
            self._client.wait_for_workers(1 if self.address else self.jobs, timeout=120)
            self.start_time = time.perf_counter() - began
        return self._client

    @property
    def workers(self):
        return len(self.client.scheduler_info()["workers"])

    def worker_pids(self):
        """{worker address: process id} (tests kill one)."""
        return self.client.run(os.getpid)

    def close(self):
        if self._client is not None:
            self._client.close()
        if self.cluster is not None:
            self.cluster.close()
        self.cluster = self._client = None
        if self.scratch:    # the workers' FMU files and folders, a killed worker's too
            shutil.rmtree(self.scratch, ignore_errors=True)
            self.scratch = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def _scatter(self, fmu_files):
        """The FMU files as one broadcast future {sha256: bytes} (sent once per worker)."""
        key = tuple(sorted(fmu_files))
        if key not in self._blobs:
            blobs = {d: pathlib.Path(p).read_bytes() for d, p in fmu_files.items()}
            self._blobs[key] = self.client.scatter([blobs], broadcast=True, hash=False)[0]
        return self._blobs[key]

    def run(self, jobs, fmu_files, store, progress=True, retry_failed=False, on_result=None, name="runs",
            batch=None):
        """Run every job whose result is not in ``store`` yet. ``jobs``: a sized iterable
        of Job, iterated twice and never held (jobs made on the fly keep memory flat);
        ``fmu_files``: sha256 -> FMU path. Jobs go out in tasks of ``batch`` runs (default:
        up to BATCH), at most 2 tasks per worker in flight.
        ``on_result(job, result)`` is called after each result is on disk. Ctrl-C stops
        cleanly (finished runs stay on disk)."""
        from distributed import as_completed
        began = time.perf_counter()
        total = len(jobs)

        def to_run(record):
            """Jobs not on disk yet, each key once; ``record`` collects the others."""
            seen = set()
            for job in jobs:
                if job.key in seen:
                    continue
                seen.add(job.key)
                status = store.status(job.key)
                if status == "ok" or (status == "failed" and not retry_failed):
                    record.append(job.key)
                else:
                    yield job

        skipped = []
        count = sum(1 for _ in to_run(skipped))     # a first pass: how many, for the progress bar
        outcome = Outcome(total, [], skipped, {}, 0.0, damaged=dict(store.damaged))
        outcome.orphans = len(store.keys() - {job.key for job in jobs})
        for fault in outcome.damaged.values():
            print(f"damaged result, run again: {fault}", file=sys.stderr)
        if not count:
            return outcome
        blobs = self._scatter(fmu_files)
        threads = sum(self.client.nthreads().values())
        window, size = max(2, 2 * threads), batch or max(1, min(BATCH, count // (4 * max(threads, 1))))
        pending, queue, in_flight = as_completed(), to_run([]), {}

        def submit(batch):
            future = self.client.submit(execute_batch, batch, blobs,
                                        key=f"runs-{batch[0].key}-{len(batch)}-{time.monotonic_ns()}")
            in_flight[future.key] = batch
            pending.add(future)

        batches = iter(lambda: list(islice(queue, size)), [])

        bar = single.progress_bar(total=count, desc=f"{name} ({len(skipped)} of {total} on disk)", unit="run",
                   disable=not progress, smoothing=0.1)
        try:
            for batch in islice(batches, window):
                submit(batch)
            for future in pending:
                batch = in_flight.pop(future.key)
                try:
                    results = future.result()
                except Exception as exc:        # the engine lost the task (e.g. a worker died too often)
                    outcome.failed.update({job.key: f"not run: {type(exc).__name__}: {exc}" for job in batch})
                    outcome.statuses.update(dict.fromkeys((job.key for job in batch), status.NOT_RUN))
                else:
                    for job, result in zip(batch, results):
                        store.write(job, dict(result))
                        outcome.computed.append(job.key)
                        if result["status"] != "ok":
                            outcome.failed[job.key] = result["error"]
                        outcome.statuses[job.key] = status.of_record(result)
                        if on_result:
                            on_result(job, result)
                future.release()
                bar.update(len(batch))
                bar.set_postfix(status.counts(outcome.statuses.values()), refresh=False)   # ok=7, flagged=3
                nxt = next(batches, None)
                if nxt is not None:
                    submit(nxt)
        except KeyboardInterrupt:
            outcome.interrupted = True
            for future in list(pending.futures):
                future.cancel()
        finally:
            bar.close()
        outcome.wall_time = time.perf_counter() - began
        return outcome


def prepared_jobs(scenario, paths, values, cases, keep_record=True):
    """Jobs of one checked scenario: ``cases`` is a list of (label, {instance: {name:
    value}}) overrides of the bound parameter values (``values``, from spec.bind);
    ``paths``: instance -> FMU file. Returns (jobs, {sha256: FMU path})."""
    digests = {inst: file_digest(p) for inst, p in paths.items()}
    files = {digests[inst]: p for inst, p in paths.items()}
    jobs = []
    for label, change in cases:
        params = {inst: dict(v) for inst, v in values.items()}
        for inst, settings in change.items():
            params.setdefault(inst, {}).update(settings)
        jobs.append(Job(label, scenario, params, digests, keep_record))
    return jobs, files


def run_sweep(scenario, paths, descriptions, values, items, outdir, jobs=None, address=None, progress=True):
    """A scenario's sweep values through the engine: master.Run objects in sweep order,
    records as outdir/<label>.npz like the sequential runner; results under outdir/runs
    (an interrupted sweep resumes)."""
    from scenarios.spec import sweep_value
    cases = []
    for item in items:
        inst, name, value = sweep_value(scenario, descriptions, item) if item is not None else (None, None, None)
        cases.append(("run" if item is None else run_label(item), {inst: {name: value}} if inst else {}))
    job_list, files = prepared_jobs(scenario, paths, values, cases)
    store = Store(pathlib.Path(outdir) / "runs")
    with Engine(jobs, address) as eng:
        outcome = eng.run(job_list, files, store, progress, name=scenario.name)
    if outcome.interrupted:
        raise KeyboardInterrupt
    if outcome.orphans:
        print(f"{outcome.orphans} results in {store.folder} belong to no run of this sweep (other settings, or FMUs "
              "of other sources); they are kept: delete them to reclaim the space", file=sys.stderr)
    runs = []
    for job in job_list:
        if store.status(job.key) is None:
            raise RuntimeError(f"run {job.label} of {scenario.name} was not run: {outcome.failed.get(job.key)}")
        runs.append(stored_run(store, job, pathlib.Path(outdir) / f"{file_label(job.label)}.npz"))
    return runs


def stored_run(store, job, record_path=None):
    """A job's result in ``store`` as a master.Run (metrics, series, flags, failure); its
    records copied to ``record_path``, or without one read from the store's own file."""
    record, path = store.read(job.key), None    # no records: refused before the first row
    if store.path(job.key, RECORDS).exists():
        path = record_path or store.path(job.key, RECORDS)
        if record_path:
            write_bytes(record_path, store.path(job.key, RECORDS).read_bytes())
    run = master.Run(job.label, path, record.get("steps", 0), record.get("run_time_s", 0.0),
                     record.get("sim_time_s", 0.0), record.get("metrics", {}),
                     store.series(job.key) if store.path(job.key, ".npz").exists() else {})
    run.flags = flags.from_dicts(record.get("flags"))
    if record["status"] != "ok":
        s = job.scenario
        run.failure = f"{s.source}: scene {s.name}, run {job.label}: {record['error']}"
    return run
