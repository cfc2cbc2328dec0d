"""Campaign engine speed, side by side in one run: N independent slews (the sky-coverage
campaign's runs: telescope_slew, native FMUs, 30 s) run sequentially in this process
(scenarios.runs.single.run, the reference), then through scenarios.runs.engine on a LocalCluster
of 1 and 2 worker processes.

The machine is shared, so wall times measure its free CPU as much as the engine. The
engine's own cost is therefore counted in CPU seconds, which other work does not
inflate: the client process (scheduler, result transfer, writing the files) and every
worker process, before and after, against the same runs' CPU in one process. From the
CPU per run it estimates what a 500-run campaign takes on 2 idle workers, and prints
the wall times measured (with the load) beside it.

    python -m benchmarks.bench_campaign [--runs 8] [--stop 30] [--max-workers 2] [--campaign 500]

--campaign N also runs a real N-run campaign (``movingbase campaign``'s path,
scenarios.runs.campaign.run_campaign) on 1 worker, then on 2, and prints their wall times, the
load, and the parallel efficiency (1 worker's time over 2 x 2 workers', and the sequential
runs' over 2 x 2 workers').
Every run is a different start elevation (distinct keys, nothing found on disk).

--samples N (issue 30's scale): a sampled campaign of N runs of a very short scene (the
dynamic budget's, --sample-stop s, default 0.1 s) on 2 workers, first on a LocalCluster,
then on a multi-process cluster started apart (`dask scheduler` + 2 `dask worker`
processes, with the variables docs/campaigns.md gives a cluster), side by side: wall
time, the engine's overhead per sample (both workers' wall time minus the runs' own
time, over N), the check's time per sample, the scheduler's throughput of empty tasks,
and a projection to 64 and 1,000 cores (the model is printed with it).
"""
import argparse
import contextlib
import os
import pathlib
import socket
import subprocess
import sys
import tempfile
import time

import numpy as np

from scenarios import spec
from scenarios.cosim.fmi import unpack
from scenarios.runs import campaign, engine, metrics, single
from scenarios.runs.runner import SHIPPED, fmu_paths


def _jobs(n, stop, offset=0.0):
    scenario = spec.load(SHIPPED / "telescope_slew.toml", overrides={"stop_time": f"{stop} s"})
    paths = fmu_paths(scenario)          # the implementation the scenario names (native)
    values = spec.bind(scenario, {inst: unpack(p)[0] for inst, p in paths.items()})
    cases = [(f"el {el:.4f}", {"base": {"start_elevation": np.radians(el), "target_elevation": np.radians(el + 5)},
                               "controller": {"feedforward": 2}})
             for el in np.linspace(20.0, 80.0, n) + offset]
    return scenario, paths, *engine.prepared_jobs(scenario, paths, values, cases, keep_record=False)


def _worker_cpu(eng):
    """CPU seconds each worker process has used so far (all its threads)."""
    return sum(eng.client.run(time.process_time).values())


def _engine_run(eng, jobs, files, store):
    """Wall, client CPU and workers' CPU of one Engine.run; its results."""
    results = []
    workers, client = _worker_cpu(eng), time.process_time()
    began = time.perf_counter()
    outcome = eng.run(jobs, files, store, progress=False, on_result=lambda job, r: results.append(r))
    wall = time.perf_counter() - began
    client, workers = time.process_time() - client, _worker_cpu(eng) - workers
    assert not outcome.failed, outcome.failed
    return wall, client, workers, results


def _sky_campaign(n, folder):
    """A sky-slews campaign file of about ``n`` runs (the shipped one has 96): start
    azimuths x start elevations x the two feedforwards, 30 s each."""
    per_axis = max(1, round((n / 2) ** 0.5))
    az = np.linspace(0.0, 350.0, per_axis)
    el = np.linspace(10.0, 80.0, max(1, round(n / 2 / per_axis)))
    quote = lambda values, plus: "[" + ", ".join(f'"{v + plus:.3f} deg"' for v in values) + "]"
    text = (f'name = "sky_{n}"\nscenario = "telescope_slew"\nset = {{ stop_time = "30 s" }}\n'
            f'[[grid]]\n"base.start_azimuth" = {quote(az, 0)}\n"base.target_azimuth" = {quote(az, 10)}\n'
            f'[[grid]]\n"base.start_elevation" = {quote(el, 0)}\n"base.target_elevation" = {quote(el, 5)}\n'
            '[[grid]]\n"controller.feedforward" = ["fixed_base", "moving_base"]\n')
    path = pathlib.Path(folder) / f"sky_{n}.toml"
    path.write_text(text)
    return path


def _sampled_campaign(n, stop, folder, seed=30):
    """The dynamic budget's campaign at ``n`` samples from ``seed`` over its scene cut to
    ``stop`` s (metrics from 0 s), written to ``folder``."""
    pathlib.Path(folder).mkdir(parents=True, exist_ok=True)
    scene = (campaign.SHIPPED / "scenes" / "dynamic_budget.toml").read_text()
    scene = scene.replace('from = "1 s"', 'from = "0 s"').replace('start_delay = "1 s"', 'start_delay = "0 s"')
    (pathlib.Path(folder) / "scene.toml").write_text(scene)
    text = (campaign.SHIPPED / "dynamic_budget.toml").read_text().split("[ci]")[0]
    text = text.replace('scenario = "scenes/dynamic_budget.toml"',
                        f'scenario = "scene.toml"\nset = {{ stop_time = "{stop} s" }}')
    path = pathlib.Path(folder) / "samples.toml"
    path.write_text(text.replace("samples = 256", f"samples = {n}").replace("seed = 30", f"seed = {seed}"))
    return path


@contextlib.contextmanager
def _cluster_apart(workers, folder):
    """A `dask scheduler` and ``workers`` `dask worker` processes of one thread, started as
    docs/campaigns.md starts them on a cluster; yields the scheduler's address."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    env = {**os.environ, **{"DASK_" + k.upper().replace(".", "__").replace("-", "_"): str(v)
                            for k, v in engine.WORKER_CONFIG.items()}}
    dask, quiet = [sys.executable, "-m", "dask"], {"stdout": subprocess.DEVNULL, "stderr": subprocess.DEVNULL}
    address = f"tcp://127.0.0.1:{port}"
    processes = [subprocess.Popen(dask + ["scheduler", "--host", "127.0.0.1", "--port", str(port),
                                          "--dashboard-address", ":0"], env=env, **quiet)]
    try:
        processes += [subprocess.Popen(dask + ["worker", address, "--nthreads", "1", "--no-dashboard",
                                               "--local-directory", f"{folder}/w{i}"], env=env, **quiet)
                      for i in range(workers)]
        yield address
    finally:
        for process in processes[::-1]:
            process.terminate()
            process.wait(timeout=60)


def _throughput(eng, tasks=2000):
    """Empty tasks a second through the scheduler and back (submit, run, gather)."""
    began = time.perf_counter()
    eng.client.gather(eng.client.map(abs, range(tasks), pure=False))
    return tasks / (time.perf_counter() - began)


def _scale(n, stop, workers=2):
    with tempfile.TemporaryDirectory() as tmp:
        path = _sampled_campaign(n, stop, tmp)
        began = time.perf_counter()
        made = campaign.CampaignJobs(campaign.load(path))
        made.check()
        check = time.perf_counter() - began
        jobs, files = made, made.files
        print(f"{n} samples of {stop:g} s of the dynamic budget's scene on {workers} workers, load "
              f"{os.getloadavg()[0]:.1f} on {os.cpu_count()} cores; checking them: {check:.1f} s "
              f"({check / n * 1e3:.1f} ms a sample, before anything runs)")
        measured = {}
        for kind in ("LocalCluster", "dask scheduler + workers"):
            with contextlib.ExitStack() as stack:
                address = stack.enter_context(_cluster_apart(workers, tmp)) if kind != "LocalCluster" else None
                eng = stack.enter_context(engine.Engine(jobs=workers, address=address))
                eng.client.wait_for_workers(workers, timeout=120)
                start = eng.start_time
                warm = campaign.CampaignJobs(campaign.load(_sampled_campaign(2 * workers, stop, f"{tmp}/w{kind[0]}",
                                                                             seed=31)))
                eng.run(warm, warm.files, engine.Store(f"{tmp}/warm-{kind}"), progress=False)
                throughput = _throughput(eng)
                wall, client, worker_cpu, results = _engine_run(eng, jobs, files, engine.Store(f"{tmp}/{kind}"))
                runs = sum(r["run_time_s"] for r in results) / n       # the stepping loop (single.run's wall_time)
                setup = sum(r["task_time_s"] for r in results) / n - runs   # instantiate, initialise, metrics, free
                overhead = workers * wall / n - runs - setup            # scheduling, transfer, files, idle
                cpu_runs = sum(r["task_cpu_s"] for r in results) / n
                size = max(1, min(engine.BATCH, n // (4 * workers)))   # as Engine.run batches them
                measured[kind] = (wall, runs + setup, overhead, throughput, start)
                ms = lambda seconds: f"{seconds * 1e3:.1f} ms"
                print(f"  {kind}: start {start:.1f} s; {wall:.1f} s for the samples ({-(-n // size)} tasks of {size} "
                      f"runs); per sample: stepping {ms(runs)}, its FMUs' set-up and metrics {ms(setup)}, the "
                      f"engine's overhead {ms(overhead)} ({workers} x wall / N minus both); by CPU: the run's "
                      f"{ms(cpu_runs)}, the client's {ms(client / n)}, the workers' beyond the runs "
                      f"{ms(worker_cpu / n - cpu_runs)}; scheduler throughput {throughput:.0f} empty tasks/s")
        (w_local, *_), (w_apart, t_run, o_run, x, t_start) = measured.values()
        print(f"  the cluster started apart took {w_apart / w_local:.3f}x the LocalCluster's wall time "
              f"({100 * (w_apart / w_local - 1):+.1f} %)")
        batch = engine.BATCH
        print(f"projection, model T(P) = max(N (t_run + o) / P, (N / {batch}) / X) + t_start: N runs in tasks of "
              f"{batch}, each run t_run = {t_run * 1e3:.1f} ms (stepping and set-up) plus o = {o_run * 1e3:.1f} ms of "
              f"engine overhead, the scheduler passing at most X = {x:.0f} tasks/s (measured here, empty tasks), "
              f"t_start = {t_start:.1f} s; it saturates at P* = X {batch} (t_run + o) = "
              f"{x * batch * (t_run + o_run):.0f} cores")
        for cores in (workers, 64, 1000):
            for count in sorted({n, 10_000, 100_000}):
                parallel, serial = count * (t_run + o_run) / cores, count / batch / x
                print(f"  P = {cores:5d}, N = {count:7d}: {max(parallel, serial) + t_start:8.1f} s "
                      f"({'scheduler-bound' if serial > parallel else 'worker-bound'})")


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=8)
    parser.add_argument("--stop", type=float, default=30.0, help="simulated seconds per run (the slew starts at 5 s)")
    parser.add_argument("--max-workers", type=int, default=2)
    parser.add_argument("--campaign", type=int, default=0, help="also run a real campaign of about this many runs")
    parser.add_argument("--samples", type=int, default=0, help="only the scale benchmark: this many samples")
    parser.add_argument("--sample-stop", type=float, default=0.1, help="simulated seconds per sample")
    args = parser.parse_args(argv)
    if args.samples:
        return _scale(args.samples, args.sample_stop, args.max_workers)
    scenario, paths, jobs, files = _jobs(args.runs, args.stop)
    print(f"{args.runs} runs of {args.stop:g} s simulated ({int(args.stop / scenario.step)} macro steps each), "
          f"load {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")

    single.run(scenario, paths, jobs[0].parameters, None, "warm", [metrics.make(m) for m in scenario.metrics])
    began, cpu = time.perf_counter(), time.process_time()
    for job in jobs:
        single.run(scenario, paths, job.parameters, None, "seq", [metrics.make(m) for m in scenario.metrics])
    sequential, seq_cpu = time.perf_counter() - began, (time.process_time() - cpu) / args.runs
    print(f"  sequential in this process: {sequential:.2f} s, {sequential / args.runs:.3f} s per run, "
          f"{seq_cpu:.3f} s CPU per run")

    walls, per_run = {}, {}
    for workers in range(1, args.max_workers + 1):
        with tempfile.TemporaryDirectory() as tmp, engine.Engine(jobs=workers) as eng:
            eng.client           # start the cluster outside the timing; warm every worker:
            eng.run(_jobs(workers, 6.0, offset=0.001 * workers)[2], files, engine.Store(tmp + "/warm"),
                    progress=False)
            wall, client, worker_cpu, results = _engine_run(eng, jobs, files, engine.Store(tmp + "/runs"))
            walls[workers] = wall
            per_run[workers] = (client + worker_cpu) / args.runs
            runs_cpu = sum(r["run_cpu_s"] for r in results) / args.runs
            own = per_run[workers] - runs_cpu
            print(f"  engine, {workers} worker(s): cluster start {eng.start_time:.2f} s; {wall:.2f} s for the runs "
                  f"({sequential / wall:.2f}x sequential, {walls[1] / wall:.2f}x 1 worker: parallel efficiency "
                  f"{100 * walls[1] / wall / workers:.0f} % by wall time)")
            print(f"    CPU per run: {per_run[workers]:.3f} s = {per_run[workers] / seq_cpu:.3f}x the sequential run's "
                  f"({seq_cpu:.3f} s); of it single.run on the worker {runs_cpu:.3f} s "
                  f"({runs_cpu / seq_cpu:.3f}x sequential: the machine's cores shared), the engine's own "
                  f"{own * 1e3:.1f} ms (client {client / args.runs * 1e3:.1f} ms: scheduler, transfer, files; "
                  f"workers beyond single.run {(worker_cpu / args.runs - runs_cpu) * 1e3:.1f} ms)")

    print("wall time against the number of runs (2 workers):")
    with tempfile.TemporaryDirectory() as tmp, engine.Engine(jobs=args.max_workers) as eng:
        eng.client
        for n in (args.runs // 4, args.runs // 2, args.runs, 2 * args.runs):
            more = _jobs(max(n, 1), args.stop, offset=0.01 * n)[2]
            began = time.perf_counter()
            eng.run(more, files, engine.Store(f"{tmp}/{n}"), progress=False)
            wall = time.perf_counter() - began
            print(f"  {len(more):3d} runs: {wall:6.2f} s, {wall / len(more):.3f} s per run")

    workers = args.max_workers
    estimate = 500 * per_run[workers] * 30.0 / args.stop / workers
    print(f"estimate, 500 runs of 30 s on {workers} idle workers: 500 x {per_run[workers] * 30.0 / args.stop:.3f} "
          f"s CPU / {workers} = {estimate:.0f} s ({estimate / 60:.1f} min) plus the cluster's start")

    if args.campaign:
        walls = {}
        for count in (1, workers):     # the same campaign (nothing on disk) on 1 worker, then on all
            with tempfile.TemporaryDirectory() as tmp:
                path = _sky_campaign(args.campaign, tmp)
                load = os.getloadavg()[0]
                began = time.perf_counter()
                _, job_list, _, outcome, _ = campaign.run_campaign(path, tmp, jobs_=count, progress=False)
                walls[count] = time.perf_counter() - began
                print(f"real campaign, {len(job_list)} runs of 30 s on {count} worker(s): {walls[count]:.0f} s "
                      f"({walls[count] / 60:.1f} min, cluster start included), {len(outcome.failed)} failed; load "
                      f"{load:.1f} before, {os.getloadavg()[0]:.1f} after")
        print(f"  parallel efficiency on {workers} workers by wall time: {walls[1] / (workers * walls[workers]):.0%} "
              f"(1 worker {walls[1]:.0f} s / ({workers} x {walls[workers]:.0f} s)); against the sequential runs of "
              f"this process: {len(job_list) * sequential / args.runs / (workers * walls[workers]):.0%}")


if __name__ == "__main__":
    main()
