"""Native (C) FMUs against the pythonfmu ones, measured side by side in one run.

1. HexapodPlant doStep under fmpy (RK4, 1 ms, leg forces holding the platform at rest,
   fixed base): native vs pythonfmu, the ratio (issue 9 asks >= 20x), and the empty
   native doStep (what FMI and ctypes cost without the kernel).
2. The paper manoeuvre (telescope, plant, controller; 1 ms; first sweep value; metrics
   as the scenario asks) under our master: wall time per macro step, native vs pythonfmu
   (asks >= 5x), and as a multiple of the floor: three empty native FMUs (the same
   variables, initialization and doStep doing nothing, fmu_src/native_build.py
   empty=True) doing the same exchange through the same master. The master steps in C
   (scenarios/c/cosim.c); Python records every 10 ms and feeds the metrics. Also shown:
   the same with no recording and no metrics (the stepping alone).
Repeats interleave the implementations (median), so machine load hits both alike.

    python benchmarks/bench_native.py [--repeats N]
"""
import argparse
import dataclasses
import pathlib
import statistics
import tempfile
import time

import numpy as np

from fmu_src import builder, native_build
from plant.stewart import HOME_POSE, StewartParams, inverse_dynamics
from scenarios import master, metrics, runner, spec
from scenarios.fmi import Instance, RealPort

STEPS, H = 2000, 1e-3


def plant_step_us(path, steps=STEPS):
    """µs per doStep of a HexapodPlant holding the platform at rest."""
    inst = Instance(path, "plant")
    try:
        inst.initialize(0.0, {"moving_base": 0})
        forces = inverse_dynamics(StewartParams.paper(), HOME_POSE, np.zeros(6), np.zeros(6))
        RealPort(inst, [f"leg_force[{i}]" for i in range(1, 7)]).write(forces)
        start = time.perf_counter()
        for k in range(steps):
            inst.do_step(k * H, H)
        return (time.perf_counter() - start) / steps * 1e6
    finally:
        inst.terminate()


def manoeuvre_us(scenario, paths, values, outdir, label):
    """µs of wall time per macro step of one master run."""
    run = master.run(scenario, paths, values, outdir, label, [metrics.make(m) for m in scenario.metrics])
    return run.wall_time / run.steps * 1e6


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args(argv)
    out = pathlib.Path(tempfile.mkdtemp())
    scripts = builder.available()
    python = builder.ensure_built(scripts)
    native = native_build.ensure_native(scripts)
    empty = {s: native_build.build_native(python[s], out / "empty", empty=True) for s in scripts}

    times = {"python": [], "native": [], "empty": []}
    for _ in range(args.repeats):
        for impl, paths in (("python", python), ("native", native), ("empty", empty)):
            times[impl].append(plant_step_us(paths["hexapod_plant_fmu"]))
    py, nat, floor = (statistics.median(times[k]) for k in ("python", "native", "empty"))
    print(f"HexapodPlant doStep (RK4, 1 ms): pythonfmu {py:.1f} us, native {nat:.2f} us -> {py / nat:.1f}x "
          f"(an empty native doStep through fmpy's ctypes: {floor:.2f} us, so the native step is "
          f"{nat - floor:.2f} us of kernel)")

    scenario, _, descriptions, values = runner.prepare(runner.resolve("paper_manoeuvre"))
    if scenario.sweep:
        inst, name, value = spec.sweep_value(scenario, descriptions, scenario.sweep[1][0])
        values[inst][name] = value
    by_impl = {impl: {i: paths[spec.FMU_SCRIPTS[f]] for i, f in scenario.fmus.items()}
               for impl, paths in (("python", python), ("native", native), ("empty", empty))}
    bare = dataclasses.replace(scenario, metrics=[], record_interval=scenario.stop_time - scenario.start_time)
    macro = {(k, v): [] for v in ("scenario", "bare") for k in by_impl}
    for r in range(max(1, args.repeats // 2)):
        for variant, scene in (("scenario", scenario), ("bare", bare)):
            for impl, paths in by_impl.items():
                macro[impl, variant].append(manoeuvre_us(scene, paths, values, out, f"{impl}{r}"))
    steps = round((scenario.stop_time - scenario.start_time) / scenario.step)
    print(f"paper manoeuvre ({steps} macro steps of {scenario.step * 1e3:g} ms, {len(scenario.fmus)} FMUs, "
          f"master {scenario.master}, extrapolation {scenario.extrapolation}, stepping in C):")
    for variant, what in (("scenario", "as the scenario runs (record every "
                                       f"{scenario.record_interval * 1e3:g} ms, {len(scenario.metrics)} metrics)"),
                          ("bare", "stepping alone (no recording, no metrics)")):
        py, nat, floor = (statistics.median(macro[k, variant]) for k in ("python", "native", "empty"))
        print(f"  {what}:")
        print(f"    pythonfmu {py:.1f} us/step (RTF {1e6 * scenario.step / py:.1f}), native {nat:.1f} us/step "
              f"(RTF {1e6 * scenario.step / nat:.1f}) -> {py / nat:.1f}x")
        print(f"    floor (three empty native FMUs, same exchange) {floor:.2f} us/step: native = {nat / floor:.1f}x "
              f"floor, pythonfmu = {py / floor:.1f}x floor")

if __name__ == "__main__":
    main()
