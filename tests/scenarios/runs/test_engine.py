"""scenarios.runs.engine: a local Dask cluster of 2 worker processes gives the sequential
numbers bit for bit, a failing run is reported while the others finish, and a campaign
whose worker is killed and whose client is interrupted resumes without losing or
repeating a run."""
import json
import os
import pathlib
import signal

import numpy as np
import pytest

from fmu_src import catalogue
from scenarios import spec
from scenarios.cosim.fmi import Instance, unpack
from scenarios.cosim.records import read_records
from scenarios.runs import engine, metrics, single
from scenarios.runs.runner import SHIPPED

ELEVATIONS = (20.0, 50.0, 80.0)


def _bound(fmus):
    scenario = spec.load(SHIPPED / "telescope_slew.toml", overrides={"stop_time": "5.4 s"})
    paths = {inst: fmus[catalogue.BY_KEY[f].script] for inst, f in scenario.fmus.items()}
    descriptions = {inst: unpack(p)[0] for inst, p in paths.items()}
    return scenario, paths, spec.bind(scenario, descriptions)


@pytest.fixture(scope="module")
def campaign(fmus, tmp_path_factory):
    """Six slews (3 start elevations x 2 feedforward modes) and their sequential results,
    from scenarios.cosim.single.run in this process."""
    scenario, paths, values = _bound(fmus)
    cases = [(f"el {el:g}, {mode}", {"base": {"start_elevation": np.radians(el),
                                              "target_elevation": np.radians(el + 5)},
                                      "controller": {"feedforward": index}})
             for el in ELEVATIONS for index, mode in ((1, "fixed_base"), (2, "moving_base"))]
    jobs, files = engine.prepared_jobs(scenario, paths, values, cases, keep_record=False)
    folder = tmp_path_factory.mktemp("sequential")
    sequential = {}
    for job in jobs:
        run = single.run(scenario, paths, job.parameters, folder, "run", [metrics.make(m) for m in scenario.metrics])
        sequential[job.key] = run
    return scenario, paths, values, jobs, files, sequential


def _same_as_sequential(store, key, run):
    record = store.read(key)
    assert record["status"] == "ok"
    assert record["metrics"] == json.loads(json.dumps(run.metrics, default=float))   # float repr: exact
    series = store.series(key)
    for name, (t, v) in run.series.items():
        assert np.array_equal(series[name][0], t) and np.array_equal(series[name][1], v)


def test_local_cluster_equals_sequential_and_reports_failures(campaign, tmp_path):
    scenario, paths, values, jobs, files, sequential = campaign
    # a 1000 km lever arm: the legs leave their stroke once the slew accelerates
    bad, _ = engine.prepared_jobs(scenario, paths, values, [("huge lever", {"base": {"lever_arm": 1e6}})])
    store = engine.Store(tmp_path)
    workers = set()
    with engine.Engine(jobs=2) as eng:
        outcome = eng.run(jobs + bad, files, store, progress=False,
                          on_result=lambda job, result: workers.add(result["worker"]))
    assert sorted(outcome.computed) == sorted(j.key for j in jobs + bad) and not outcome.skipped
    assert len(workers) == 2                     # both worker processes ran
    for key, run in sequential.items():
        _same_as_sequential(store, key, run)
    failed = store.read(bad[0].key)
    assert failed["status"] == "failed" and "'plant'" in failed["error"] and "stroke" in failed["error"]
    assert 0 < failed["steps"] < 5400 and "pose error" in failed["metrics"]   # partial results kept
    assert outcome.failed == {bad[0].key: failed["error"]}


def test_runs_batched_into_tasks_keep_each_runs_own_numbers(campaign, tmp_path):
    """Six runs in tasks of 4 and 2 on one worker: every key gets its own sequential
    numbers (a batch's results are matched to its jobs), none is lost or repeated."""
    scenario, paths, values, jobs, files, sequential = campaign
    store, seen = engine.Store(tmp_path), []
    with engine.Engine(jobs=1) as eng:
        outcome = eng.run(jobs, files, store, progress=False, batch=4, on_result=lambda job, r: seen.append(job.key))
    assert sorted(seen) == sorted(outcome.computed) == sorted(sequential) and not outcome.failed
    for key, run in sequential.items():
        _same_as_sequential(store, key, run)


def test_instances_of_one_fmu_share_its_library_not_their_state(native_fmus):
    """A worker instantiates each run's FMUs on the library it loaded once (fmi._slave):
    two live instances of one FMU with different parameters step as each does alone,
    and freeing one leaves the other stepping (the library stays loaded)."""
    scenario, paths, values = _bound(native_fmus)
    outputs = [f"base_pose[{k}]" for k in range(1, 7)]

    def started(name, elevation):
        instance = Instance(paths["base"], name)
        instance.initialize(0.0, {**values["base"], "start_elevation": elevation, "start_delay": 0.0})
        return instance

    def step(instance, first, count):
        for k in range(first, first + count):
            instance.do_step(k * 1e-3, 1e-3)
        return [instance.get_real(v) for v in outputs]

    alone = {}
    for elevation in (0.3, 0.9):
        instance = started("alone", elevation)
        alone[elevation] = (step(instance, 0, 500), step(instance, 500, 500))
        instance.terminate()
    low, high = started("low", 0.3), started("high", 0.9)
    assert low.fmu.dll is high.fmu.dll and low.fmu.component != high.fmu.component
    assert (step(low, 0, 500), step(high, 0, 500)) == (alone[0.3][0], alone[0.9][0])
    low.terminate()
    assert step(high, 500, 500) == alone[0.9][1]
    high.terminate()

def test_killed_worker_and_interrupt_resume_without_loss_or_repeat(campaign, tmp_path):
    scenario, paths, values, jobs, files, sequential = campaign
    store = engine.Store(tmp_path)
    written = []

    with engine.Engine(jobs=2) as eng:
        def kill_then_interrupt(job, result):
            written.append(job.key)
            if len(written) == 1:                 # a worker dies with a run in hand
                pid = next(p for p in eng.worker_pids().values())
                os.kill(pid, signal.SIGKILL)
            if len(written) == 3:                 # then the user presses Ctrl-C
                raise KeyboardInterrupt
        first = eng.run(jobs, files, store, progress=False, on_result=kill_then_interrupt)
    assert first.interrupted and first.computed == written and len(written) == 3
    done = {j.key for j in jobs if store.status(j.key) == "ok"}
    assert done == set(written)                   # on disk: exactly the results the client got

    with engine.Engine(jobs=2) as eng:
        second = eng.run(jobs, files, store, progress=False)
    assert sorted(second.skipped) == sorted(written)
    assert sorted(second.computed) == sorted(set(sequential) - set(written))   # no run twice
    assert not second.failed and not second.interrupted
    for key, run in sequential.items():           # none lost, each the sequential numbers
        _same_as_sequential(store, key, run)

    with engine.Engine(jobs=2) as eng:            # all on disk: nothing runs, no cluster starts
        third = eng.run(jobs, files, store, progress=False)
        assert eng.cluster is None
    assert not third.computed and len(third.skipped) == len(jobs)


def test_existing_cluster_by_address(campaign, tmp_path):
    """A scheduler and a worker started with the dask command line, as on a cluster;
    the engine given its address gives the sequential numbers."""
    import socket
    import subprocess
    import sys

    scenario, paths, values, jobs, files, sequential = campaign
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    address = f"tcp://127.0.0.1:{port}"
    dask = [sys.executable, "-m", "dask"]
    scheduler = subprocess.Popen(dask + ["scheduler", "--host", "127.0.0.1", "--port", str(port),
                                         "--dashboard-address", ":0"],
                                 stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    worker = None
    try:
        worker = subprocess.Popen(dask + ["worker", address, "--nworkers", "1", "--nthreads", "1",
                                          "--local-directory", str(tmp_path / "worker")],
                                  stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        store = engine.Store(tmp_path / "runs")
        with engine.Engine(address=address) as eng:
            outcome = eng.run(jobs[:2], files, store, progress=False)
            assert eng.cluster is None            # nothing started here
        assert len(outcome.computed) == 2 and not outcome.failed
        for job in jobs[:2]:
            _same_as_sequential(store, job.key, sequential[job.key])
    finally:
        for process in (worker, scheduler):
            if process is not None:
                process.terminate()
                process.wait(timeout=30)


def test_sweep_on_workers_writes_what_the_sequential_runner_writes(tmp_path):
    """movingbase run FILE --jobs 2: the same metrics.json numbers and bit-identical records."""
    from scenarios.runs import runner
    text = (SHIPPED / "telescope_slew.toml").read_text().replace('stop_time = "8 s"', 'stop_time = "5.2 s"')
    path = tmp_path / "slew.toml"
    path.write_text(text)
    _, sequential, _ = runner.run_scenario(path, tmp_path / "seq", ci=True, progress=False)
    _, parallel, report = runner.run_scenario(path, tmp_path / "par", ci=True, progress=False, jobs=2)
    assert [r.label for r in parallel] == [r.label for r in sequential] == ["none", "fixed_base", "moving_base"]
    for seq, par in zip(sequential, parallel):
        assert par.metrics == json.loads(json.dumps(seq.metrics, default=float))
        a, b = read_records(par.record_path), read_records(seq.record_path)
        assert a.header == b.header and a.values.tobytes() == b.values.tobytes()
    assert report.exists()


def test_damaged_results_are_named_and_recomputed_and_orphans_counted(campaign, tmp_path, capsys):
    """Issue 17 section 4: a truncated JSON or a corrupt npz once blocked resuming with a
    traceback naming no file, or was taken as good."""
    scenario, paths, values, jobs, files, sequential = campaign
    store = engine.Store(tmp_path)
    with engine.Engine(jobs=1) as eng:
        assert len(eng.run(jobs[:3], files, store, progress=False).computed) == 3
        json_file, npz_file = store.path(jobs[0].key, ".json"), store.path(jobs[1].key, ".npz")
        json_file.write_bytes(json_file.read_bytes()[:40])               # truncated mid-way
        npz_file.write_bytes(b"PK\x03\x04" + os.urandom(200))             # corrupt
        store.path("0123456789abcdef01234567", ".json").write_text('{"status": "ok"}')   # an orphan
        again = engine.Store(tmp_path)
        outcome = eng.run(jobs[:3], files, again, progress=False)
    assert sorted(outcome.computed) == sorted([jobs[0].key, jobs[1].key]) and outcome.skipped == [jobs[2].key]
    assert set(outcome.damaged) == {jobs[0].key, jobs[1].key}
    assert str(json_file) in outcome.damaged[jobs[0].key] and str(npz_file) in outcome.damaged[jobs[1].key]
    assert str(json_file) in capsys.readouterr().err
    assert outcome.orphans == 1
    for job in jobs[:3]:
        _same_as_sequential(again, job.key, sequential[job.key])


def test_a_rebuild_of_the_same_sources_keeps_the_cache_key(tmp_path):
    """The builds are not byte-reproducible (a new guid, generation time and ELF build id
    each time): the key follows the content that decides the numbers, so rebuilt FMUs
    find the results on disk. A changed member changes it."""
    import zipfile

    from fmu_src import native_build
    from fmu_src import python_build as builder
    first, second = [], []
    for folder, built in ((tmp_path / "a", first), (tmp_path / "b", second)):
        built.append(builder.ensure_built(["leg_sensor_fmu"], folder)["leg_sensor_fmu"])
        built.append(native_build.ensure_native(["leg_sensor_fmu"], folder / "native")["leg_sensor_fmu"])
    for a, b in zip(first, second):
        assert a.read_bytes() != b.read_bytes()                      # the files differ
        assert engine.file_digest(a) == engine.file_digest(b)        # what decides the numbers does not
    changed = tmp_path / "changed.fmu"
    with zipfile.ZipFile(first[0]) as source, zipfile.ZipFile(changed, "w") as target:
        for info in source.infolist():
            data = source.read(info)
            target.writestr(info, data + b"\n# edited" if info.filename.endswith("leg_sensor_fmu.py") else data)
    assert engine.file_digest(changed) != engine.file_digest(first[0])


def test_the_key_follows_the_kit_s_own_code(fmus, tmp_path, monkeypatch):
    """A pythonfmu FMU imports its model from this package at run time, and the metrics are
    computed by it: an edited kit keeps every FMU file, so the run key must change with the
    code, or a campaign would take results of the old code for the new one. A copy of the
    sources with one line added gives another digest; the digest is the key's."""
    import shutil

    from scenarios.runs import metrics as metrics_module
    copy = tmp_path / "scenarios"
    shutil.copytree(pathlib.Path(metrics_module.__file__).parent, copy, ignore=shutil.ignore_patterns("*.so",
                                                                                                      "__pycache__"))
    before = engine.code_digest([copy])
    with open(copy / "metrics.py", "a") as f:
        f.write("\n# edited\n")
    assert engine.code_digest([copy]) != before
    assert engine.code_digest([copy]) == engine.code_digest([copy])          # a digest, not a clock
    scenario, paths, values = _bound(fmus)
    job = engine.Job("a", scenario, values, {inst: engine.file_digest(p) for inst, p in paths.items()})
    assert engine.run_key(scenario, values, job.fmus) == job.key
    monkeypatch.setattr(engine, "_package_digest", lambda: before)
    assert engine.run_key(scenario, values, job.fmus) != job.key


# every field of spec.Scenario is either in the key, or decides no run's numbers (named here,
# with why); a new field fails the test below until it is placed
_NOT_IN_KEY = {"source": "the file's path", "name": "a label", "description": "a label",
               "sweep": "each run's parameters hold its value", "ci": "applied to stop_time already",
               "fidelity_tolerance": "the chosen fidelity is in the parameters", "notes": "what the runner said",
               "implementations": "in the FMU digests", "fmi_versions": "in the FMU digests",
               "short": "decides flags, computed per case by the client",
               "requirements": "judged after the run from its metrics (runner.write_results, the API, the CLI), "
                               "never stored with them: a cached run is judged by the current ones"}


def test_every_setting_that_decides_the_numbers_changes_the_run_key():
    """A setting missing from the key (extrapolation, once) lets a campaign reuse the
    results of other settings as its own."""
    import dataclasses
    base = spec.load(SHIPPED / "telescope_slew.toml")
    parameters, fmus = {"base": {"lever_arm": 25.0}}, {inst: f"digest-{inst}" for inst in base.fmus}
    key = engine.run_key(base, parameters, fmus)
    changed = {"start_time": 0.5, "stop_time": 59.0, "step": 5e-4, "master": "gauss-seidel", "extrapolation": "none",
               "fmus": {**base.fmus, "plant": "mechanism3t_plant"}, "connections": base.connections[:-1],
               "record_interval": 0.02, "record": base.record[:-1], "metric_interval": 1e-3,
               "metrics": [dataclasses.replace(base.metrics[0], start=1.0), *base.metrics[1:]],
               "parameters": {}}
    fields = {f.name for f in dataclasses.fields(spec.Scenario)}
    assert set(changed) | set(_NOT_IN_KEY) == fields and not set(changed) & set(_NOT_IN_KEY)
    for name, value in changed.items():
        if name == "parameters":    # the bound values are the key's, not the raw ones
            assert engine.run_key(base, {"base": {"lever_arm": 5.0}}, fmus) != key
            continue
        assert engine.run_key(dataclasses.replace(base, **{name: value}), parameters, fmus) != key, name
    assert engine.run_key(base, parameters, {**fmus, "plant": "another digest"}) != key
    for name in _NOT_IN_KEY:        # and what decides no number leaves it alone
        other = {"sweep": ("controller.kp", [1.0]), "ci": {"stop_time": 1.0}, "fidelity_tolerance": 3.0,
                 "notes": ["x"], "implementations": {"plant": "python"}, "fmi_versions": {"plant": 3},
                 "short": True}.get(name, "other")
        assert engine.run_key(dataclasses.replace(base, **{name: other}), parameters, fmus) == key, name
