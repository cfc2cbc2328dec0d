"""Command line: run scenario files (or shipped scenario names) and write their reports.

    movingbase run [SCENARIO ...] [--out DIR] [--ci] [--quiet] [--jobs N] [--dask tcp://HOST:PORT]
                        [--implementation native|python]
    movingbase run SCENARIO --ssp FILE.ssp      (export for other FMI tools instead)

Without a scenario it runs the main job: the telescope slew (FMUs built first) and the
paper's leg-force charts.
"""
import argparse
import sys

from .paper_forces import main as paper_charts
from .runner import SHIPPED, prepare, resolve, run_scenario
from .spec import IMPLEMENTATIONS, ScenarioError, sweep_value
from .ssp import export_ssp


def shipped_names():
    """Names of the scenario files shipped in scenarios/files/."""
    return sorted(p.stem for p in SHIPPED.glob("*.toml"))


def main(argv=None, prog="movingbase run"):
    shipped = ", ".join(shipped_names())
    parser = argparse.ArgumentParser(prog=prog, description=__doc__.splitlines()[0],
                                     epilog=f"shipped scenarios (scenarios/files/): {shipped}. Wall time and "
                                            "real-time factor count the co-simulation stepping loop only (FMU "
                                            "loading and initialisation excluded).")
    parser.add_argument("scenarios", nargs="*", help=f"scenario files or shipped names: {shipped} "
                                                     "(default: telescope_slew, then the paper's leg-force charts)")
    parser.add_argument("--out", default="out", help="output folder (default: out)")
    parser.add_argument("--ci", action="store_true", help="apply each file's [ci] overrides (short runs)")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")
    parser.add_argument("--jobs", type=int, help="run the sweep values on N local worker processes")
    parser.add_argument("--dask", metavar="ADDR", help="run the sweep values on the Dask cluster at ADDR")
    parser.add_argument("--implementation", choices=IMPLEMENTATIONS,
                        help="run every FMU as this implementation, whatever the file chooses")
    parser.add_argument("--ssp", metavar="FILE", help="export the (one) scenario as an SSP file, first sweep value")
    args = parser.parse_args(argv)
    names = args.scenarios or ["telescope_slew"]
    unknown = [n for n in names if not resolve(n).exists()]
    if unknown:
        sys.exit(f"scenario error: no scenario file or shipped scenario named {', '.join(map(repr, unknown))}; "
                 f"shipped: {shipped}")
    if args.ssp:
        try:
            scenario, paths, descriptions, values = prepare(resolve(names[0]), ci=args.ci,
                                                             implementation=args.implementation)
            if scenario.sweep:
                inst, name, value = sweep_value(scenario, descriptions, scenario.sweep[1][0])
                values[inst][name] = value
            print(f"SSP written to {export_ssp(scenario, paths, values, args.ssp)}")
        except ScenarioError as exc:
            sys.exit(f"scenario error: {exc}")
        return
    errors = []   # one line each; every scenario and every run is still tried
    for name in names:
        try:
            scenario, runs, report = run_scenario(name, args.out, ci=args.ci, progress=not args.quiet,
                                                  jobs=args.jobs, dask=args.dask,
                                                  implementation=args.implementation)
        except ScenarioError as exc:
            errors.append(f"scenario error: {exc}")
            continue
        print(f"{scenario.name}: report {report}")
        for run in runs:
            if run.failure:
                print(f"  {run.label}: FAILED after {run.steps} steps ({run.sim_time:g} s); partial results kept")
                errors.append(f"run error: {run.failure}")
            else:
                print(f"  {run.label}: {run.steps} steps in {run.wall_time:.1f} s of stepping "
                      f"(real-time factor {run.real_time_factor:.1f}; FMU loading and initialisation not counted)")
    if errors:
        sys.exit("\n".join(errors))
    if not args.scenarios:
        paper_charts(f"{args.out}/paper")


if __name__ == "__main__":
    main()
