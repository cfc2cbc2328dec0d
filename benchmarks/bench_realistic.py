"""What the realistic loop's pieces cost, measured side by side in one run.

1. HexapodPlant doStep (fmpy host, RK4, 1 ms communication step, fixed base, leg forces
   holding the platform): the actuator off (today's plant) against each actuator effect
   alone and all of them, native and pythonfmu. max_step is 1 ms except where the friction
   is on: its tanh slope (coulomb / friction_velocity) needs 0.1 ms substeps, and that
   cost is printed as it is (it is what the realistic scenario pays).
2. Wall time per macro step of the CI telescope slew (moving-base feedforward, native):
   the ideal loop (telescope_slew) against the realistic one (telescope_slew_realistic:
   actuators + LegSensor).
Repeats interleave the cases (median), so machine load hits all alike.

    python benchmarks/bench_realistic.py [--repeats N]
"""
import argparse
import statistics
import tempfile

from bench_native import plant_step_us  # this folder: the scripts run from it

from fmu_src import native_build
from fmu_src import python_build as builder
from scenarios.runs import runner

STEPS = 3000
CASES = {   # label: plant parameters
    "actuator off (ideal)": {},
    "force loop 50 Hz": {"actuator_bandwidth": 50.0},
    "reflected mass 758 kg": {"reflected_mass": 758.0},
    "force limit 25 kN": {"actuator_force_limit": 25e3},
    "friction (max_step 0.1 ms)": {"coulomb_friction": 200.0, "viscous_friction": 2000.0, "max_step": 1e-4},
    "all on (max_step 0.1 ms)": {"actuator_bandwidth": 50.0, "reflected_mass": 758.0, "coulomb_friction": 200.0,
                                 "viscous_friction": 2000.0, "actuator_force_limit": 25e3, "max_step": 1e-4},
    "ideal at max_step 0.1 ms": {"max_step": 1e-4},
}


def macro_step_us(name, out):
    """µs of stepping wall time per macro step of the moving-base run of a shipped scenario's CI version."""
    _, runs, _ = runner.run_scenario(name, out, ci=True, progress=False)
    run = next(r for r in runs if r.label == "moving_base")
    return run.wall_time / run.steps * 1e6


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args(argv)
    python = builder.ensure_built(["hexapod_plant_fmu"])["hexapod_plant_fmu"]
    native = native_build.ensure_native(["hexapod_plant_fmu"])["hexapod_plant_fmu"]
    times = {(label, impl): [] for label in CASES for impl in ("native", "python")}
    for _ in range(args.repeats):
        for label, parameters in CASES.items():
            for impl, path in (("native", native), ("python", python)):
                times[label, impl].append(plant_step_us(path, parameters, STEPS))
    med = {key: statistics.median(v) for key, v in times.items()}
    base = {impl: med["actuator off (ideal)", impl] for impl in ("native", "python")}
    print(f"HexapodPlant doStep, RK4, h = 1 ms, fixed base, median of {args.repeats}")
    print(f"{'case':30s} {'native [us]':>12s} {'x off':>7s} {'python [us]':>12s} {'x off':>7s}")
    for label in CASES:
        print(f"{label:30s} {med[label, 'native']:12.1f} {med[label, 'native'] / base['native']:7.2f} "
              f"{med[label, 'python']:12.1f} {med[label, 'python'] / base['python']:7.2f}")
    with tempfile.TemporaryDirectory() as tmp:
        loop = {"telescope_slew": [], "telescope_slew_realistic": []}
        for _ in range(args.repeats):
            for name in loop:
                loop[name].append(macro_step_us(name, f"{tmp}/{name}"))
    ideal, real = (statistics.median(loop[n]) for n in loop)
    print(f"\nCI telescope slew, moving-base feedforward, native, per macro step (1 ms), median of {args.repeats}")
    print(f"{'ideal loop (telescope_slew)':45s} {ideal:8.1f} us")
    print(f"{'realistic loop (telescope_slew_realistic)':45s} {real:8.1f} us  ({real / ideal:.2f}x)")


if __name__ == "__main__":
    main()
