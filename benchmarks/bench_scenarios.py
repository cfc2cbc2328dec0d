"""Wall time and real-time factor of every shipped scenario, and the master's own cost
per macro step (its stepping loop is C, scenarios/c/cosim.c) against a Python loop making
the same FMI calls and against fmpy's list-based calls. Prints figures; asserts nothing.

    python -m benchmarks.bench_scenarios [--ci]     (--ci: the short [ci] versions)
"""
import argparse
import dataclasses
import pathlib
import tempfile
import time

from movingbase.scenarios import master, runner


def scenario_table(ci):
    out = pathlib.Path(tempfile.mkdtemp())
    print(f"{'scenario':20s} {'run':12s} {'steps':>8s} {'wall [s]':>9s} {'real-time factor':>17s} {'us/step':>8s}")
    for path in sorted(runner.SHIPPED.glob("*.toml")):
        scenario, runs, _ = runner.run_scenario(path, out, ci=ci, progress=False)
        for run in runs:
            print(f"{scenario.name:20s} {run.label:12s} {run.steps:8d} {run.wall_time:9.2f} "
                  f"{run.real_time_factor:17.1f} {run.wall_time / run.steps * 1e6:8.1f}")


def _instances(scenario, paths, values):
    """Instances initialised as master.run does, with their exchange."""
    instances = {}
    exchange, _ = master.start(scenario, paths, values, instances)
    exchange.read()
    return instances, exchange


def master_overhead(steps=4000):
    """Paper manoeuvre, moving-base feedforward: master.run against the same FMUs driven by
    a Python loop over the same ctypes calls (no extrapolation) and by fmpy's list-based calls."""
    scenario, paths, _, values = runner.prepare(runner.resolve("paper_manoeuvre"), ci=True)
    values["controller"]["feedforward"] = 2
    scenario = dataclasses.replace(scenario, metrics=[], stop_time=steps * scenario.step,
                                   record_interval=steps * scenario.step)
    out = pathlib.Path(tempfile.mkdtemp())
    run = master.run(scenario, paths, values, out, "bench", [])
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
    print(f"  master.run (C stepping loop)    {per_master:7.1f} us/step  (real-time factor {1e3 / per_master:.1f})")
    print(f"  Python loop, same ctypes calls  {bare:7.1f} us/step  -> {bare - per_master:.1f} us/step more than master.run")
    print(f"  Python loop, fmpy list calls    {fmpy_lists:7.1f} us/step  ({fmpy_lists / bare:.2f}x the ctypes path)")


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--ci", action="store_true", help="run the short [ci] versions")
    args = parser.parse_args()
    scenario_table(args.ci)
    master_overhead()


if __name__ == "__main__":
    main()
