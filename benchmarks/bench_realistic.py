"""What the realistic loop's pieces cost, measured side by side in one run.

1. HexapodPlant doStep (fmpy host, RK4, 1 ms communication step, fixed base, leg forces
   holding the platform): the actuator off (today's plant) against each actuator effect
   alone and all of them, native and pythonfmu. max_step is 1 ms except where the friction
   is on: its tanh slope (coulomb / friction_velocity) takes either 0.1 ms fixed substeps
   (the realistic scenes before issue 41) or error-controlled ones (tolerance 0.1 nm,
   at most 1 ms, the lag exact: the scenes now).
2. CPU time of the master's stepping per macro step (1 ms) of the CI versions of the
   shipped scenes, one run each (the last sweep value: the design the scene ships), native:
   the ideal loop (telescope_slew, moving-base feedforward) against every realistic one
   (telescope_slew_realistic: actuators + LegSensor; telescope_slew_observer,
   keyhole_tracking_observer, telescope_slew_gust_front, telescope_slew_observer_switch_on:
   + Wind, LoadCell and the disturbance observer; telescope_slew_wind_feedforward: + Wind and
   the anemometer's feedforward; telescope_slew_support: the ideal plant on a flexible
   support in wind), each with its plant as shipped (error-controlled substeps) and some
   with the 0.1 ms fixed substeps they had; the ratio to the ideal loop is the issue's
   figure (the observer slew also runs at the 0.03 nm it shipped before issue 41's fourth
   pass: what that tolerance cost). The plant's own share is printed beside it: the same run with the
   actuator's friction and lag off and 1 ms substeps. The Wind FMUs turn their gust's
   phasors per step (plant/c/wind.h, Stepping) since issue 41's second pass: 256 sin/cos a
   step before.
Repeats interleave the cases (median), so machine load hits all alike. CPU time of the
stepping thread (master.Run.cpu_time), not wall time: the machine is shared.

    python benchmarks/bench_realistic.py [--repeats N] [--only plant|loop]
"""
import argparse
import pathlib
import statistics
import tempfile

from bench_native import plant_step_us  # this folder: the scripts run from it

from fmu_src import native_build
from fmu_src import python_build as builder
from scenarios.runs import metrics, runner, single

STEPS = 3000
FIXED = {"max_step": 1e-4, "tolerance": 0.0}       # the realistic scenes' plant before issue 41
CONTROLLED = {"max_step": 1e-3, "tolerance": 1e-10}   # ... and now
SCREW = {"coulomb_friction": 200.0, "viscous_friction": 2000.0}
ALL_ON = {"actuator_bandwidth": 50.0, "reflected_mass": 758.0, **SCREW, "actuator_force_limit": 25e3}
CASES = {   # label: plant parameters
    "actuator off (ideal)": {},
    "force loop 50 Hz": {"actuator_bandwidth": 50.0},
    "reflected mass 758 kg": {"reflected_mass": 758.0},
    "force limit 25 kN": {"actuator_force_limit": 25e3},
    "friction, fixed 0.1 ms": {**SCREW, **FIXED},
    "friction, controlled": {**SCREW, **CONTROLLED},
    "all on, fixed 0.1 ms": {**ALL_ON, **FIXED},
    "all on, controlled": {**ALL_ON, **CONTROLLED},
    "ideal at max_step 0.1 ms": {"max_step": 1e-4},
}
# (label, scene, plant parameters on top of the scene's)
LOOPS = [("ideal loop", "telescope_slew", {}),
         ("realistic, controlled", "telescope_slew_realistic", {}),
         ("realistic, fixed 0.1 ms", "telescope_slew_realistic", FIXED),
         ("realistic, plant ideal 1 ms", "telescope_slew_realistic",
          {"actuator_bandwidth": 0.0, "coulomb_friction": 0.0, "viscous_friction": 0.0, **CONTROLLED}),
         ("slew observer, controlled", "telescope_slew_observer", {}),
         ("slew observer, controlled 0.03 nm", "telescope_slew_observer", {**CONTROLLED, "tolerance": 3e-11}),
         ("slew observer, fixed 0.1 ms", "telescope_slew_observer", FIXED),
         ("slew observer, plant ideal 1 ms", "telescope_slew_observer",
          {"actuator_bandwidth": 0.0, "coulomb_friction": 0.0, "viscous_friction": 0.0, **CONTROLLED}),
         ("keyhole observer, controlled", "keyhole_tracking_observer", {}),
         ("keyhole observer, fixed 0.1 ms", "keyhole_tracking_observer", FIXED),
         ("gust front, controlled", "telescope_slew_gust_front", {}),
         ("observer switch-on, controlled", "telescope_slew_observer_switch_on", {}),
         ("wind feedforward, controlled", "telescope_slew_wind_feedforward", {}),
         ("support in wind (ideal plant)", "telescope_slew_support", {})]


def prepared(name):
    """The CI version of a shipped scene, its last sweep value's parameters and its plant instance."""
    scenario, paths, descriptions, values = runner.prepare(runner.resolve(name), ci=True)
    label, params = list(runner.sweep_runs(scenario, descriptions, values))[-1]
    plant = next(inst for inst, fmu in scenario.fmus.items() if fmu == "hexapod_plant")
    return scenario, paths, label, params, plant


def macro_step_cpu_us(scene, plant_values, out):
    """µs of the stepping thread's CPU time per macro step of one run of ``scene`` (prepared)."""
    scenario, paths, label, params, plant = scene
    params = {inst: dict(v) for inst, v in params.items()}
    params[plant].update(plant_values)
    out.mkdir(parents=True, exist_ok=True)
    run = single.run(scenario, paths, params, out, label, [metrics.make(m) for m in scenario.metrics])
    return run.cpu_time / run.steps * 1e6


def plant_table(repeats):
    python = builder.ensure_built(["hexapod_plant_fmu"])["hexapod_plant_fmu"]
    native = native_build.ensure_native(["hexapod_plant_fmu"])["hexapod_plant_fmu"]
    times = {(label, impl): [] for label in CASES for impl in ("native", "python")}
    for _ in range(repeats):
        for label, parameters in CASES.items():
            for impl, path in (("native", native), ("python", python)):
                times[label, impl].append(plant_step_us(path, parameters, STEPS))
    med = {key: statistics.median(v) for key, v in times.items()}
    base = {impl: med["actuator off (ideal)", impl] for impl in ("native", "python")}
    print(f"HexapodPlant doStep, RK4, h = 1 ms, fixed base, wall time, median of {repeats}")
    print(f"{'case':30s} {'native [us]':>12s} {'x off':>7s} {'python [us]':>12s} {'x off':>7s}")
    for label in CASES:
        print(f"{label:30s} {med[label, 'native']:12.1f} {med[label, 'native'] / base['native']:7.2f} "
              f"{med[label, 'python']:12.1f} {med[label, 'python'] / base['python']:7.2f}")


def loop_table(repeats):
    scenes = {name: prepared(name) for name in dict.fromkeys(scene for _, scene, _ in LOOPS)}
    times = {label: [] for label, _, _ in LOOPS}
    with tempfile.TemporaryDirectory() as tmp:
        for k in range(repeats):
            for n, (label, scene, plant_values) in enumerate(LOOPS):
                times[label].append(macro_step_cpu_us(scenes[scene], plant_values, pathlib.Path(tmp) / f"{k}_{n}"))
    med = {label: statistics.median(v) for label, v in times.items()}
    ideal = med["ideal loop"]
    print(f"\nCI scenes, native, stepping CPU time per macro step (1 ms), median of {repeats} interleaved")
    print(f"{'loop':36s} {'us/step':>8s} {'x ideal':>8s} {'range x ideal':>15s}")
    for label, _, _ in LOOPS:
        ratios = [t / i for t, i in zip(times[label], times["ideal loop"])]
        print(f"{label:36s} {med[label]:8.2f} {med[label] / ideal:8.2f} {min(ratios):7.2f}-{max(ratios):.2f}")


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--only", choices=("plant", "loop"))
    args = parser.parse_args(argv)
    if args.only != "loop":
        plant_table(args.repeats)
    if args.only != "plant":
        loop_table(args.repeats)


if __name__ == "__main__":
    main()
