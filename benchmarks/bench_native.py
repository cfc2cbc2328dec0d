"""Native (C) FMUs against the pythonfmu ones, measured side by side in one run.

1. HexapodPlant doStep under fmpy (RK4, 1 ms, leg forces holding the platform at rest,
   fixed base): native vs pythonfmu, the ratio (the goal: >= 20x), and the empty
   native doStep (what FMI and ctypes cost without the kernel).
   The same doStep in a host that is not Python (tests/hosts/c_host/fmi2_host.c timing its own
   doStep loop): the native FMU alone in the process, the pythonfmu one with libpython
   preloaded, as a C tool must run it.
2. The paper manoeuvre (telescope, plant, controller; 1 ms; first sweep value; metrics
   as the scenario asks) under our master: wall time per macro step, native vs pythonfmu
   (asks >= 5x), and as a multiple of the floor: three empty native FMUs (the same
   variables, initialization and doStep doing nothing, fmu_src/native_build.py
   empty=True) doing the same exchange through the same master. The master steps in C
   (scenarios/cosim/c/cosim.c); Python records every 10 ms and feeds the metrics. Also shown:
   the same with no recording and no metrics (the stepping alone).
3. The same paper manoeuvre stepped by the master's C loop alone (all steps in one call)
   against the monolithic C loop of the same kernels without FMI (benchmarks/monolithic.c,
   the same leg lengths bit for bit: tests/scenarios/cosim/test_monolithic.py): what FMI costs.
4. The same HexapodPlant doStep as an FMI 3.0 FMU (fmu_src/native/fmi3_layer.c over the
   FMI 2.0 layer) against the FMI 2.0 one, timed in one C process (fmi_step_timer.c:
   through ctypes, fmi3DoStep's eight arguments cost Python more than the FMU's work),
   and the empty FMUs of both (what each layer costs without the kernel).
Repeats interleave the implementations (median), so machine load hits both alike.

    python benchmarks/bench_native.py [--repeats N] [--only cosim]   (the co-simulation pairs: max(N, 15))

Instruction counts, repeatable on a loaded machine (--only steps: each side once, N steps):

    valgrind --tool=callgrind --collect-atstart=no --toggle-collect=cosim_steps \
        python benchmarks/bench_native.py --only steps --steps 2000
    (--toggle-collect='ffi_call*' instead counts the monolithic loop, called through ctypes)
"""
import argparse
import dataclasses
import os
import pathlib
import statistics
import subprocess
import tempfile
import time
import zipfile

import numpy as np
from fmpy import read_model_description

from benchmarks.monolithic import Pair  # noqa: E402
from fmu_src import catalogue, native_build
from fmu_src import python_build as builder
from plant.hexapod.model import HOME_POSE, StewartParams, inverse_dynamics
from scenarios import spec
from scenarios.cosim.fmi import Instance, RealPort
from scenarios.runs import metrics, runner, single
from tests.hosts.c_host import HostFmu  # noqa: E402

STEPS, H = 2000, 1e-3


def rest_forces():
    """Leg forces holding the platform at rest at home (fixed base)."""
    return inverse_dynamics(StewartParams.paper(), HOME_POSE, np.zeros(6), np.zeros(6))


def plant_step_us(path, parameters=None, steps=STEPS):
    """µs per doStep under fmpy of a HexapodPlant (``parameters`` on top of a fixed base)
    holding the platform at rest; the forces are there at initialization too, so an
    actuator with a bandwidth starts without a transient."""
    inst = Instance(path, "plant")
    try:
        forces = rest_forces()
        inst.initialize(0.0, {"moving_base": 0, **(parameters or {}),
                              **{f"leg_force[{i + 1}]": forces[i] for i in range(6)}})
        RealPort(inst, [f"leg_force[{i}]" for i in range(1, 7)]).write(forces)
        start = time.perf_counter()
        for k in range(steps):
            inst.do_step(k * H, H)
        return (time.perf_counter() - start) / steps * 1e6
    finally:
        inst.terminate()


def fmi3_vs_fmi2_us(fmu2, fmu3, folder, steps, repeats):
    """Medians of µs per doStep of the FMI 2.0 and FMI 3.0 builds of one HexapodPlant at
    rest, timed in one C process (benchmarks/fmi_step_timer.c), interleaved."""
    folder = pathlib.Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    timer = folder / "fmi_step_timer"
    compile_run = subprocess.run([os.environ.get("CC", "cc"), "-O2", f"-I{native_build.FMI_HEADERS}",
                                  str(pathlib.Path(__file__).with_name("fmi_step_timer.c")), "-o", str(timer), "-ldl"],
                                 capture_output=True, text=True)
    if compile_run.returncode:
        raise RuntimeError(f"compiling fmi_step_timer.c failed:\n{compile_run.stderr}")
    libraries = []
    for fmu, name in ((fmu2, "fmi2"), (fmu3, "fmi3")):
        with zipfile.ZipFile(fmu) as z:
            z.extractall(folder / name)
        libraries.append(next((folder / name / "binaries").rglob("*.so")))
    md = read_model_description(str(fmu2))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    forces = ",".join(repr(float(f)) for f in rest_forces())
    run = subprocess.run([str(timer), *map(str, libraries), md.guid, str(steps), str(repeats),
                          f"i:{vr['moving_base']}:0", f"r:{vr['leg_force[1]']}:{forces}"], capture_output=True,
                          text=True)
    if run.returncode:
        raise RuntimeError(f"fmi_step_timer failed on {fmu2.name}:\n{run.stderr[-2000:]}")
    times = {"fmi2": [], "fmi3": []}
    for line in run.stdout.split("\n"):
        if line:
            kind, value = line.split()
            times[kind].append(float(value))
    return statistics.median(times["fmi2"]), statistics.median(times["fmi3"]), times


def c_host_step_us(path, folder, steps):
    """µs per doStep of a HexapodPlant holding the platform at rest, timed by the C host."""
    run = HostFmu(path, folder).run(steps=steps, real={f"leg_force[{i + 1}]": f for i, f in enumerate(rest_forces())},
                                    integer={"moving_base": 0}, timed=True)
    if run.returncode != 0:
        raise RuntimeError(f"C host failed on {path}: exit {run.returncode}\n{run.stderr[-2000:]}")
    return float(run.lines("step_us")[0][0])


def bound(py, kernel, floor, host, ratio=20.0):
    """What a doStep ratio of ``ratio`` would take: both plants run the same C kernel step
    (``kernel`` µs), so pythonfmu's doStep is its own cost W plus that step and the native
    one is the host's call ``floor`` plus it; (W + k) / (floor + k) >= ratio needs
    k <= (W - ratio floor) / (ratio - 1)."""
    wrapper = py - kernel
    need = (wrapper - ratio * floor) / (ratio - 1.0)
    verdict = (f"{ratio:g}x would need a kernel step of {need:.2f} us" if need > 0 else
               f"{ratio:g}x is out of reach even with a free kernel ({wrapper / floor:.1f}x at most)")
    return (f"pythonfmu's own cost per doStep in {host}: {wrapper:.2f} us over the {kernel:.2f} us kernel step; "
            + verdict)


def manoeuvre_us(scenario, paths, values, outdir, label):
    """µs of wall time per macro step of one master run."""
    run = single.run(scenario, paths, values, outdir, label, [metrics.make(m) for m in scenario.metrics])
    return run.wall_time / run.steps * 1e6


def cosim_vs_monolithic(scenario, paths, values, repeats):
    """The paper manoeuvre stepped by the master's C loop alone against the monolithic C
    loop, ``repeats`` times each, the two sides alternating (each pair run back to back,
    so the machine's load hits both alike): per step in wall and in CPU time, the median
    and the fastest of each side, and the median of the pairs' ratios (what the ratio is
    taken from: it does not drift with the load between pairs)."""
    steps = round((scenario.stop_time - scenario.start_time) / scenario.step)
    clocks = {"wall": time.perf_counter, "CPU": time.process_time}
    loops = {(side, clock): [] for side in ("cosim", "monolithic") for clock in clocks}
    for r in range(repeats):
        for side in (("cosim", "monolithic") if r % 2 == 0 else ("monolithic", "cosim")):
            pair = Pair(scenario, paths, values)
            try:
                began = {clock: read() for clock, read in clocks.items()}
                done, _ = getattr(pair, side)(steps, lengths=False)
                for clock, read in clocks.items():
                    loops[side, clock].append((read() - began[clock]) / steps * 1e6)
            finally:
                pair.close()
            if done != steps:
                raise RuntimeError(f"the {side} run of the paper manoeuvre stopped at step {done} of {steps}")
    print(f"  co-simulation (native FMUs, the master's C loop alone) against the monolithic C loop of the same "
          f"kernels without FMI, {repeats} pairs of {steps} steps, alternating (load {os.getloadavg()[0]:.1f}):")
    for clock in clocks:
        cosim, mono = loops["cosim", clock], loops["monolithic", clock]
        ratios = [c / m for c, m in zip(cosim, mono)]
        print(f"    {clock:4s}: co-simulation {statistics.median(cosim):.2f} us/step (fastest {min(cosim):.2f}), "
              f"monolithic {statistics.median(mono):.2f} (fastest {min(mono):.2f}) -> co-simulation = "
              f"{statistics.median(ratios):.3f}x monolithic (median of the pairs' ratios; fastest against fastest "
              f"{min(cosim) / min(mono):.3f}x; pairs {min(ratios):.2f}-{max(ratios):.2f}x)")


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--only", choices=["cosim", "steps"],
                        help="only the co-simulation against the monolithic loop (steps: each once, untimed)")
    parser.add_argument("--steps", type=int, default=2000, help="with --only steps: how many macro steps")
    args = parser.parse_args(argv)
    if args.only:
        scenario, paths, descriptions, values = runner.prepare(runner.resolve("paper_manoeuvre"),
                                                               implementation="native")
        if scenario.sweep:
            inst, name, value = spec.sweep_value(scenario, descriptions, scenario.sweep[1][0])
            values[inst][name] = value
        if args.only == "steps":
            for side in ("cosim", "monolithic"):
                pair = Pair(scenario, paths, values)
                try:
                    done, _ = getattr(pair, side)(args.steps, lengths=False)
                finally:
                    pair.close()
                print(f"{side}: {done} steps")
            return
        cosim_vs_monolithic(scenario, paths, values, max(args.repeats, 15))
        return
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
    print("  " + bound(py, nat - floor, floor, "fmpy"))

    host = {"python": [], "native": []}
    for r in range(args.repeats):
        for impl, paths in (("python", python), ("native", native)):
            host[impl].append(c_host_step_us(paths["hexapod_plant_fmu"], out / f"host-{impl}{r}", 5 * STEPS))
    py, nat = (statistics.median(host[k]) for k in ("python", "native"))
    print(f"the same doStep in a C host (tests/hosts/c_host/fmi2_host.c): pythonfmu {py:.1f} us, native {nat:.2f} us "
          f"-> {py / nat:.1f}x")
    print("  " + bound(py, nat, 0.0, "the C host"))

    scenario, _, descriptions, values = runner.prepare(runner.resolve("paper_manoeuvre"))
    if scenario.sweep:
        inst, name, value = spec.sweep_value(scenario, descriptions, scenario.sweep[1][0])
        values[inst][name] = value
    by_impl = {impl: {i: paths[catalogue.BY_KEY[f].script] for i, f in scenario.fmus.items()}
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

    cosim_vs_monolithic(scenario, by_impl["native"], values, max(args.repeats, 15))

    fmi3 = native_build.ensure_native3(["hexapod_plant_fmu"])["hexapod_plant_fmu"]
    empty3 = native_build.build_native3(empty["hexapod_plant_fmu"], out / "empty3", empty=True)
    print("HexapodPlant doStep (RK4, 1 ms, at rest) as FMI 3.0 and FMI 2.0 FMUs of the same build, timed in C "
          "(benchmarks/fmi_step_timer.c, interleaved, median):")
    for what, fmu2, fmu3 in (("model", native["hexapod_plant_fmu"], fmi3),
                             ("empty (the layers alone)", empty["hexapod_plant_fmu"], empty3)):
        f2, f3, runs = fmi3_vs_fmi2_us(fmu2, fmu3, out / f"timer-{len(what)}", 5 * STEPS, max(3, args.repeats))
        print(f"  {what}: FMI 3.0 {f3:.3f} us, FMI 2.0 {f2:.3f} us -> FMI 3 / FMI 2 = {f3 / f2:.3f} "
              f"(runs FMI 3 {min(runs['fmi3']):.3f}-{max(runs['fmi3']):.3f}, FMI 2 "
              f"{min(runs['fmi2']):.3f}-{max(runs['fmi2']):.3f} us)")


if __name__ == "__main__":
    main()
