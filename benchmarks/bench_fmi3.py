"""FMI 3.0 FMUs against the FMI 2.0 builds of the same models under our master, side by
side in one run (repeats interleave the two, median; machine load hits both alike; the ratio
is taken as the median of the pairs' ratios, each pair run back to back).

A scene's runs ([ci] overrides, every sweep value) as the master steps them: CPU time of
the stepping thread per macro step of single.run (stepping in C, recording, metrics;
Run.cpu_time: wall time on the shared machine measures its load), every instance FMI 3
against every instance FMI 2. The FMI 3 instances are stepped by the C loop's direct
fmi3DoStep/fmi3GetFloat64/fmi3SetFloat64 calls (scenarios/cosim/c/cosim.c).

    python benchmarks/bench_fmi3.py [scenario] [--repeats N]
"""
import argparse
import os
import statistics
import tempfile

from scenarios import spec
from scenarios.runs import metrics, runner, single


def scene_us(scenario, paths, descriptions, values, outdir):
    """µs of the stepping thread's CPU time per macro step over every sweep value of ``scenario``."""
    cpu, steps = 0.0, 0
    for item in scenario.sweep[1] if scenario.sweep else [None]:
        bound = {inst: dict(v) for inst, v in values.items()}
        if item is not None:
            inst, name, value = spec.sweep_value(scenario, descriptions, item)
            bound[inst][name] = value
        run = single.run(scenario, paths, bound, outdir, "bench", [metrics.make(m) for m in scenario.metrics])
        cpu, steps = cpu + run.cpu_time, steps + run.steps
    return cpu / steps * 1e6


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scenario", nargs="?", default="keyhole_tracking")
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args(argv)
    out = tempfile.mkdtemp()
    prepared = {}
    for version in (2, 3):
        prepared[version] = runner.prepare(runner.resolve(args.scenario), ci=True, fmi_version=version)
    times = {2: [], 3: []}
    for _ in range(args.repeats):
        for version, setup in prepared.items():
            times[version].append(scene_us(*setup, out))
    two, three = statistics.median(times[2]), statistics.median(times[3])
    scenario = prepared[2][0]
    print(f"{args.scenario} [ci] ({len(scenario.fmus)} FMUs, {scenario.step * 1e3:g} ms steps, master "
          f"{scenario.master}, every sweep value), stepping CPU time per macro step, median of {args.repeats}:")
    ratios = [t3 / t2 for t2, t3 in zip(times[2], times[3])]   # each pair back to back: the load hits both alike
    print(f"  FMI 2.0 FMUs {two:.2f} us, FMI 3.0 FMUs {three:.2f} us -> FMI 3 / FMI 2 = {three / two:.3f}; median of "
          f"the pairs' ratios {statistics.median(ratios):.3f} (pairs {min(ratios):.3f}..{max(ratios):.3f}; spread FMI "
          "2 "
          f"{min(times[2]):.2f}..{max(times[2]):.2f}, FMI 3 {min(times[3]):.2f}..{max(times[3]):.2f}; load "
          f"{os.getloadavg()[0]:.1f})")


if __name__ == "__main__":
    main()
