"""Wall time and real-time factor of every shipped scenario, the master's own cost
per macro step (its stepping loop is C, scenarios/cosim/c/cosim.c) against a Python loop making
the same FMI calls and against fmpy's list-based calls, a recorded run against the bare
stepping (the goal: <= 1.25x, docs/speed.md), the checks before a run (the stability
prediction along the motion, scenarios.runs.flags) against the run, and the whole CLI process
of one scenario against its stepping, phase by phase (the goal: <= 1.5x). Prints
figures; asserts nothing.

    python -m benchmarks.bench_scenarios [--ci] [--only recording|checks|process]   (--ci: the [ci] versions)
    python -m benchmarks.bench_scenarios --against OLD_TREE [--pairs N]   (goal 5 of issue 41, old and new)
"""
import argparse
import dataclasses
import json
import os
import pathlib
import resource
import shutil
import statistics
import subprocess
import sys
import tempfile
import time

from scenarios.cosim import master
from scenarios.runs import metrics, runner, single


def scenario_table(ci):
    out = pathlib.Path(tempfile.mkdtemp())
    print(f"{'scenario':20s} {'run':12s} {'steps':>8s} {'wall [s]':>9s} {'real-time factor':>17s} {'us/step':>8s}")
    for path in sorted(runner.SHIPPED.glob("*.toml")):
        scenario, runs, _ = runner.run_scenario(path, out, ci=ci, progress=False)
        for run in runs:
            print(f"{scenario.name:20s} {run.label:12s} {run.steps:8d} {run.wall_time:9.2f} "
                  f"{run.real_time_factor:17.1f} {run.wall_time / run.steps * 1e6:8.1f}")


def _instances(scenario, paths, values):
    """Instances initialised as single.run does, with their exchange."""
    instances = {}
    exchange, _ = master.start(scenario, paths, values, instances)
    exchange.read()
    return instances, exchange


def master_overhead(steps=4000):
    """Paper manoeuvre, moving-base feedforward: single.run against the same FMUs driven by
    a Python loop over the same ctypes calls (no extrapolation) and by fmpy's list-based calls."""
    scenario, paths, _, values = runner.prepare(runner.resolve("paper_manoeuvre"), ci=True)
    values["controller"]["feedforward"] = 2
    scenario = dataclasses.replace(scenario, metrics=[], stop_time=steps * scenario.step,
                                   record_interval=steps * scenario.step)
    out = pathlib.Path(tempfile.mkdtemp())
    run = single.run(scenario, paths, values, out, "bench", [])
    per_master = run.wall_time / run.steps * 1e6
    h = scenario.step

    instances, exchange = _instances(scenario, paths, values)
    start = time.perf_counter()
    writes = [(port, idx) for port, idx, _ in exchange.write_ports.values()]
    for k in range(steps):
        for port, idx in writes:
            port.write(exchange.y[idx])
        for inst in scenario.fmus:
            instances[inst].do_step(k * h, h)
        exchange.read()
    bare = (time.perf_counter() - start) / steps * 1e6
    for i in instances.values():
        i.terminate()

    instances, exchange = _instances(scenario, paths, values)
    reads = {inst: (port.names, [instances[inst].vr(n) for n in port.names])
             for inst, (port, _) in exchange.read_ports.items()}
    writes = {inst: ([instances[inst].vr(n) for n in port.names], idx)
              for inst, (port, idx, _) in exchange.write_ports.items()}
    y = {}
    start = time.perf_counter()
    for k in range(steps):
        for inst, (vrs, idx) in writes.items():
            instances[inst].fmu.setReal(vrs, list(exchange.y[idx]))
        for inst in scenario.fmus:
            instances[inst].fmu.doStep(k * h, h)
        for inst, (names, vrs) in reads.items():
            y[inst] = instances[inst].fmu.getReal(vrs)
    fmpy_lists = (time.perf_counter() - start) / steps * 1e6
    for i in instances.values():
        i.terminate()
    print(f"\npaper manoeuvre, 3 FMUs at 1 ms ({steps} steps):")
    print(f"  single.run (C stepping loop)    {per_master:7.1f} us/step  (real-time factor {1e3 / per_master:.1f})")
    print(f"  Python loop, same ctypes calls  {bare:7.1f} us/step  -> "
        f"{bare - per_master:.1f} us/step more than single.run")
    print(f"  Python loop, fmpy list calls    {fmpy_lists:7.1f} us/step  ({fmpy_lists / bare:.2f}x the ctypes path)")


def recording_cost(repeats=15):
    """Paper manoeuvre [ci], moving-base feedforward, native FMUs: the run as the scenario
    asks (its 58 recorded columns every 10 ms and its metrics), the same recording every
    step (1 ms), and the bare stepping (nothing recorded between the ends, no metrics),
    interleaved, best of ``repeats`` (runs of ~20 ms: the best of many is what the load
    leaves alone); the stepping wall and CPU time of each (FMU loading excluded) and the
    one-off write of the records as npz."""
    scenario, paths, _, values = runner.prepare(runner.resolve("paper_manoeuvre"), ci=True)
    values["controller"]["feedforward"] = 2
    whole = scenario.stop_time - scenario.start_time
    kinds = {"bare stepping": dataclasses.replace(scenario, metrics=[], record=[], record_interval=whole),
             "recorded as shipped (10 ms)": scenario,
             "recorded every step (1 ms)": dataclasses.replace(scenario, record_interval=scenario.step)}
    best, cpu, save = {k: float("inf") for k in kinds}, {k: float("inf") for k in kinds}, {}
    out = pathlib.Path(tempfile.mkdtemp())
    for _ in range(repeats):
        for kind, variant in kinds.items():
            run = single.run(variant, paths, values, None, "bench", [metrics.make(m) for m in variant.metrics])
            best[kind], cpu[kind] = min(best[kind], run.wall_time), min(cpu[kind], run.cpu_time)
            began = time.perf_counter()
            run.records.save(out / "bench.npz")
            save[kind] = min(save.get(kind, float("inf")), time.perf_counter() - began)
            columns = len(run.records.names)
    bare, bare_cpu = best["bare stepping"], cpu["bare stepping"]
    print(f"\nrecording, paper manoeuvre [ci] ({run.steps} steps, {columns} recorded columns, best of {repeats}, "
          "interleaved):")
    for kind, wall in best.items():
        print(f"  {kind:28s} {wall * 1e3:7.1f} ms stepping  {wall / bare:5.2f}x the bare stepping "
              f"(CPU {cpu[kind] / bare_cpu:5.2f}x)   + {save[kind] * 1e3:5.1f} ms writing the npz once")


def check_cost(ci, names=("telescope_slew", "telescope_slew_realistic", "keyhole_tracking"), repeats=3):
    """The pre-run checks (runner.pre_run_flags: the step-limit prediction along the motion
    and the scene's checks; best of ``repeats``) against the whole run of the scenario
    (run_scenario: checks, runs, report) and against its stepping alone, side by side."""
    out = pathlib.Path(tempfile.mkdtemp())
    print(f"\npre-run checks against the run ({'[ci]' if ci else 'full'} versions):")
    print(f"{'scenario':26s} {'checks [ms]':>11s} {'run [s]':>8s} {'checks/run':>11s} {'stepping [s]':>13s} "
          f"{'checks/stepping':>16s}")
    for name in names:
        began = time.perf_counter()
        _, runs, _ = runner.run_scenario(name, out, ci=ci, progress=False)
        whole = time.perf_counter() - began
        stepping = sum(r.wall_time for r in runs)
        prepared = runner.prepare(runner.resolve(name), ci)
        checks = []
        for _ in range(repeats):
            began = time.perf_counter()
            runner.pre_run_flags(*prepared, ci=ci)
            checks.append(time.perf_counter() - began)
        best = min(checks)
        print(f"{name:26s} {best * 1e3:11.1f} {whole:8.2f} {100 * best / whole:10.2f}% {stepping:13.2f} "
              f"{100 * best / stepping:15.2f}%")


# The CLI in a child process with a clock around each phase of what it does; the phases
# are the real functions (wrapped), not a copy of the command's sequence.
_PHASED = r"""
import atexit, sys, time
began = time.perf_counter()
import movingbase.cli as program
from scenarios.cosim import master, records
from scenarios.output import report
from scenarios.runs import runner
spent = {"imports": time.perf_counter() - began}
def clock(owner, name, phase):
    inner = getattr(owner, name)
    def timed(*args, **kwargs):
        start = time.perf_counter()
        try:
            return inner(*args, **kwargs)
        finally:
            spent[phase] = spent.get(phase, 0.0) + time.perf_counter() - start
    setattr(owner, name, timed)
for owner, name, phase in ((runner, "prepare", "checks"), (runner, "pre_run_flags", "checks"),
                           (runner, "run_prepared", "runs"), (records.Records, "save", "records"),
                           (runner, "write_results", "results"), (report, "_error_chart", "charts"),
                           (report, "_summary_chart", "charts")):
    clock(owner, name, phase)
run = runner.single.run
steps = []
def counted(*args, **kwargs):
    result = run(*args, **kwargs)
    steps.append(result.wall_time)
    return result
runner.single.run = counted
def phases():
    spent["stepping"] = sum(steps)
    spent["inside"] = time.perf_counter() - began
    print("PHASES", repr(spent), flush=True)
atexit.register(phases)
sys.argv = ["movingbase", "run"] + sys.argv[1:]
program.main()   # as the command ends: exit handlers, no teardown
"""


def _cli(args, phased, tree=None):
    """Wall and CPU seconds of one CLI process, its stepping [s] (metrics.json) and, if
    ``phased``, its phases {name: s}; ``tree``: the kit's code from that folder (another
    checkout's copy, its compiled modules beside the sources) instead of this one."""
    out = pathlib.Path(tempfile.mkdtemp())
    command = [sys.executable, "-c", _PHASED] if phased else [sys.executable, "-m", "movingbase", "run"]
    env = {**os.environ, "PYTHONPATH": str(tree)} if tree else None
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    began = time.perf_counter()
    done = subprocess.run(command + args + ["--quiet", "--out", str(out)], capture_output=True, text=True,
                          check=True, env=env, cwd=tree)
    wall = time.perf_counter() - began
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = after.ru_utime + after.ru_stime - before.ru_utime - before.ru_stime
    stem = pathlib.Path(args[0]).stem
    stepping = sum(r["wall_time_s"] for r in json.loads((out / stem / "metrics.json").read_text()).values())
    shutil.rmtree(out)   # ~9 MB of records a process
    phases = eval(done.stdout.split("PHASES ", 1)[1]) if phased else {}
    return wall, cpu, stepping, phases


def process_cost(ci, names=("telescope_slew", "paper_manoeuvre"), repeats=3):
    """One scenario from the CLI (``movingbase run NAME --quiet``, a fresh process, FMUs
    already built): its wall time against its stepping (the runs' wall_time_s), for each
    --charts choice, interleaved, median of ``repeats``; then one process with a clock
    around each phase."""
    charts = ("all", "summary", "none")
    ci_flag = ["--ci"] if ci else []
    print(f"\none scenario from the CLI, whole process against its stepping ({'[ci]' if ci else 'full'} versions, "
          f"median of {repeats}, interleaved; load {os.getloadavg()[0]:.1f}):")
    print(f"{'scenario':18s} {'--charts':>9s} {'process [s]':>12s} {'CPU [s]':>8s} {'stepping [s]':>13s} "
          f"{'process/stepping':>17s}")
    for name in names:
        results = {c: [] for c in charts}
        for _ in range(repeats):
            for c in charts:
                results[c].append(_cli([name, "--charts", c] + ci_flag, False))
        for c in charts:
            wall, cpu, stepping = (sorted(x)[len(x) // 2] for x in list(zip(*results[c]))[:3])
            print(f"{name:18s} {c:>9s} {wall:12.2f} {cpu:8.2f} {stepping:13.2f} {wall / stepping:16.2f}x")
    for name in names:
        wall, cpu, stepping, phases = _cli([name] + ci_flag, True)
        start = wall - phases["inside"]
        fmus = phases["runs"] - phases["stepping"] - phases.get("records", 0.0)
        shown = {"interpreter start and end": start, "imports": phases["imports"], "checks": phases["checks"],
                 "FMU loading, initialisation": fmus, "stepping": phases["stepping"],
                 "records (npz)": phases.get("records", 0.0), "charts": phases.get("charts", 0.0),
                 "report, metrics.json": phases["results"] - phases.get("charts", 0.0)}
        shown["the rest"] = wall - sum(shown.values())
        print(f"\n{name}, --charts all: phases of one process ({wall:.2f} s, {wall / stepping:.2f}x its stepping)")
        for phase, seconds in shown.items():
            print(f"  {phase:30s} {seconds:6.2f} s  {100 * seconds / wall:5.1f} %")


def process_pairs(tree, pairs=10, name="telescope_slew"):
    """Issue 41's goal 5: ``movingbase run NAME --charts none`` against its stepping, this
    tree and the one in ``tree`` (an older commit's files with its compiled extension
    modules, e.g. ``git worktree add``) in interleaved pairs, each pair's ratios and the
    medians (ranges)."""
    print(f"\n{name} --charts none, process / stepping, {pairs} interleaved pairs (load {os.getloadavg()[0]:.1f}):")
    ratios = {"this": [], "other": []}
    for k in range(pairs):
        for which in (("other", "this") if k % 2 == 0 else ("this", "other")):
            wall, _, stepping, _ = _cli([name, "--charts", "none"], False, tree if which == "other" else None)
            ratios[which].append(wall / stepping)
        print(f"  pair {k + 1}: this tree {ratios['this'][-1]:.3f}x, {tree} {ratios['other'][-1]:.3f}x")
    for which, values in ratios.items():
        print(f"  {which:5s}: median {statistics.median(values):.3f}x ({min(values):.3f}-{max(values):.3f}x)")
    print(f"  (load at the end {os.getloadavg()[0]:.1f})")


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--ci", action="store_true", help="run the short [ci] versions")
    parser.add_argument("--only", choices=["recording", "checks", "process"], help="only this part")
    parser.add_argument("--against", metavar="TREE", help="with --only process: issue 41's goal, this tree "
                        "against the kit in TREE, in interleaved pairs")
    parser.add_argument("--pairs", type=int, default=10, help="pairs for --against (default 10)")
    args = parser.parse_args()
    if args.against:
        process_pairs(pathlib.Path(args.against).resolve(), args.pairs)
        return
    if args.only is None:
        scenario_table(args.ci)
        master_overhead()
    if args.only in (None, "recording"):
        recording_cost()
    if args.only in (None, "checks"):
        check_cost(args.ci)
    if args.only in (None, "process"):
        process_cost(args.ci)


if __name__ == "__main__":
    main()
