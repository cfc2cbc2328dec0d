"""Campaign engine speed, side by side in one run: N independent slews run sequentially
in this process (scenarios.master.run, the reference), then through scenarios.engine on
a LocalCluster of 1 and 2 worker processes; the engine's cost per run beyond the run
itself; and the wall time against the number of runs.

    python -m benchmarks.bench_campaign [--runs 8] [--stop 6] [--max-workers 2]

Every run is a different start elevation (distinct keys, nothing found on disk).
"""
import argparse
import pathlib
import statistics
import tempfile
import time

import numpy as np

from movingbase.fmu_src.builder import ensure_built
from movingbase.scenarios import engine, master, metrics, spec
from movingbase.scenarios.fmi import unpack
from movingbase.scenarios.runner import SHIPPED


def _jobs(n, stop, offset=0.0):
    scenario = spec.load(SHIPPED / "telescope_slew.toml", overrides={"stop_time": f"{stop} s"})
    scripts = ensure_built(sorted({spec.FMU_SCRIPTS[f] for f in scenario.fmus.values()}))
    paths = {inst: scripts[spec.FMU_SCRIPTS[f]] for inst, f in scenario.fmus.items()}
    values = spec.bind(scenario, {inst: unpack(p)[0] for inst, p in paths.items()})
    cases = [(f"el {el:.4f}", {"base": {"start_elevation": np.radians(el), "target_elevation": np.radians(el + 5)},
                               "controller": {"feedforward": 2}})
             for el in np.linspace(20.0, 80.0, n) + offset]
    return scenario, paths, *engine.prepared_jobs(scenario, paths, values, cases, keep_record=False)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=8)
    parser.add_argument("--stop", type=float, default=6.0, help="simulated seconds per run (the slew starts at 5 s)")
    parser.add_argument("--max-workers", type=int, default=2)
    args = parser.parse_args(argv)
    scenario, paths, jobs, files = _jobs(args.runs, args.stop)

    with tempfile.TemporaryDirectory() as tmp:
        master.run(scenario, paths, jobs[0].parameters, pathlib.Path(tmp), "warm",
                   [metrics.make(m) for m in scenario.metrics])
        began, cpu = time.perf_counter(), time.process_time()
        for job in jobs:
            master.run(scenario, paths, job.parameters, pathlib.Path(tmp), "seq",
                       [metrics.make(m) for m in scenario.metrics])
        sequential, cpu = time.perf_counter() - began, time.process_time() - cpu
    print(f"{args.runs} runs of {args.stop:g} s simulated ({int(args.stop / scenario.step)} macro steps each)")
    print(f"  sequential in this process: {sequential:.2f} s ({sequential / args.runs:.3f} s per run, "
          f"{cpu / args.runs:.3f} s CPU)")

    walls = {}
    for workers in range(1, args.max_workers + 1):
        with tempfile.TemporaryDirectory() as tmp, engine.Engine(jobs=workers) as eng:
            eng.client           # start the cluster outside the timing; warm every worker:
            eng.run(_jobs(workers, args.stop, offset=0.001 * workers)[2], files, engine.Store(tmp + "/warm"),
                    progress=False)
            results = []
            began = time.perf_counter()
            outcome = eng.run(jobs, files, engine.Store(tmp + "/runs"), progress=False,
                              on_result=lambda job, r: results.append(r))
            walls[workers] = time.perf_counter() - began
            assert not outcome.failed, outcome.failed
            overhead = [r["task_time_s"] - r["run_time_s"] for r in results]
            run = statistics.median(r["run_time_s"] for r in results)
            cpu = statistics.median(r["task_cpu_s"] for r in results)
            idle = (walls[workers] * workers - sum(r["task_time_s"] for r in results)) / args.runs
            print(f"  engine, {workers} worker(s): cluster start {eng.start_time:.2f} s; {walls[workers]:.2f} s for "
                  f"the runs = {sequential / walls[workers]:.2f}x sequential, {walls[1] / walls[workers]:.2f}x "
                  f"1 worker; per run on the worker: co-simulation loop {run:.3f} s wall, task {cpu:.3f} s CPU, "
                  f"instantiate + initialise + collect {statistics.median(overhead) * 1e3:.0f} ms; worker idle "
                  f"per run (scheduling, transfer, writing, the last run's tail) {idle * 1e3:.0f} ms")

    print("wall time against the number of runs (2 workers):")
    with tempfile.TemporaryDirectory() as tmp, engine.Engine(jobs=args.max_workers) as eng:
        eng.client
        for n in (args.runs // 4, args.runs // 2, args.runs, 2 * args.runs):
            more = _jobs(max(n, 1), args.stop, offset=0.01 * n)[2]
            began = time.perf_counter()
            eng.run(more, files, engine.Store(f"{tmp}/{n}"), progress=False)
            wall = time.perf_counter() - began
            print(f"  {len(more):3d} runs: {wall:6.2f} s, {wall / len(more):.3f} s per run")


if __name__ == "__main__":
    main()
