"""Command line: run scenario files (or shipped scenario names) and write their reports.

    movingbase run [SCENARIO ...] [--out DIR] [--ci] [--quiet] [--jobs N] [--dask tcp://HOST:PORT]
                        [--implementation native|python] [--csv] [--allow-unstable] [--charts all|summary|none]
    movingbase run SCENARIO --ssp FILE.ssp      (export for other FMI tools instead)

Without a scenario it runs the main job: the telescope slew (FMUs built first) and the
paper's leg-force charts.
"""
import argparse
import pathlib
import sys

from scenarios.cosim.fmi import FmuFileError
from scenarios.cosim.records import run_records
from scenarios.output.report import CHARTS
from scenarios.runs.engine import EngineError, check_address
from scenarios.runs.estimates import ResourceError, check_jobs
from scenarios.runs.runner import OutputError, not_found, prepare, resolve, run_scenario, shipped_names
from scenarios.spec import IMPLEMENTATIONS, ScenarioError, sweep_value
from scenarios.ssp import export_ssp


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
    parser.add_argument("--csv", action="store_true",
                        help="also export each run's records as CSV (<label>.csv beside its <label>.npz)")
    parser.add_argument("--allow-unstable", action="store_true",
                        help="run a communication step beyond the predicted stability limit anyway (flagged)")
    parser.add_argument("--charts", choices=CHARTS, default="all",
                        help="all: error against time per metric and the summary bars (default); summary: the "
                             "summary bars of a sweep only; none: no charts (the report's tables and the records)")
    parser.add_argument("--ssp", metavar="FILE", help="export the (one) scenario as an SSP file, first sweep value")
    args = parser.parse_args(argv)
    try:
        _run(args, shipped)
    except KeyboardInterrupt:
        sys.exit(f"interrupted: the runs that finished are in {args.out}; a sweep run with --jobs or --dask "
                 "resumes where it stopped when the same command runs again")


def _run(args, shipped):
    """The checks of the command line (all before anything runs), then each scenario."""
    names = args.scenarios or ["telescope_slew"]
    if not all(n.strip() for n in names):
        sys.exit("scenario error: an empty scenario name; give a scenario file or a shipped name: " + shipped)
    unknown = [n for n in names if not resolve(n).exists()]
    if unknown:
        sys.exit(f"scenario error: {not_found(unknown)}")
    folders = {}
    for name in names:   # the output folder follows the file: two files of one stem would share it
        path = resolve(name).resolve()   # (a stem differing in case only too: one folder on macOS and Windows)
        folders.setdefault(path.stem.casefold(), set()).add(path)
    clashes = {stem: paths for stem, paths in folders.items() if len(paths) > 1}
    repeated = [n for n in dict.fromkeys(names) if [resolve(m).resolve() for m in names].count(resolve(n).resolve()) > 1]
    if clashes or repeated:
        what = [f"{', '.join(sorted(map(str, p)))} would all write to {args.out}/{min(p).stem}"
                for p in clashes.values()]
        what += [f"{n!r} is named more than once" for n in repeated]
        sys.exit(f"scenario error: {'; '.join(what)}: run them in separate commands with their own --out")
    try:
        for warning in (check_jobs(args.jobs),):
            if warning:
                print(warning, file=sys.stderr)
        if args.dask is not None:   # "" too: it once ran locally, silently
            check_address(args.dask)
    except (ResourceError, EngineError) as exc:
        sys.exit(f"command error: {exc}")
    if args.ssp:
        if len(names) > 1:   # one file holds one scenario: the others were dropped without a word
            sys.exit(f"command error: --ssp {args.ssp}: exports one scenario, {len(names)} given "
                     f"({', '.join(names)}); run one --ssp per scenario")
        _export(args, names[0])
        return
    errors = []   # one line each; every scenario and every run is still tried
    for name in names:
        try:
            scenario, runs, report = run_scenario(name, args.out, ci=args.ci, progress=not args.quiet,
                                                  jobs=args.jobs, dask=args.dask,
                                                  implementation=args.implementation,
                                                  allow_unstable=args.allow_unstable, charts=args.charts)
        except ScenarioError as exc:
            errors.append(f"scenario error: {exc}")
            continue
        except (OutputError, ResourceError, FmuFileError) as exc:
            errors.append(f"{name}: {exc}")
            continue
        except OSError as exc:     # the disk filled or the folder went away while writing
            errors.append(f"{name}: output error: {exc.filename or args.out}: {exc.strerror or exc}")
            continue
        print(f"{scenario.name}: report {report}")
        if args.csv:
            for run in runs:
                if run.record_path:
                    run_records(run).to_csv(run.record_path.with_suffix(".csv"))
        for run in runs:
            if run.failure:
                print(f"  {run.label}: FAILED after {run.steps} steps ({run.sim_time:g} s); partial results kept")
                errors.append(f"run error: {run.failure}")
            else:
                print(f"  {run.label}: {run.steps} steps in {run.wall_time:.1f} s of stepping "
                      f"(real-time factor {run.real_time_factor:.1f}; FMU loading and initialisation not counted)")
            for flag in run.flags:
                if flag.kind != "cut_short":   # a failed run says so above
                    print(f"    FLAGGED {flag.kind}: {flag.message}")
        flagged = [run.label for run in runs if run.flags]
        if flagged:
            print(f"  {len(flagged)} of {len(runs)} runs FLAGGED ({', '.join(flagged)}): their numbers are not "
                  f"results; see {report}")
    if errors:
        sys.exit("\n".join(errors))
    if not args.scenarios:
        from studies.paper_forces import main as paper_charts  # pyplot: imported by what draws
        paper_charts(f"{args.out}/paper")


def _export(args, name):
    """--ssp: the scenario (its first sweep value) as an SSP file; the target must be a
    file path whose folder exists."""
    target = pathlib.Path(args.ssp)
    if target.is_dir() or not target.parent.is_dir():
        blocker = next((p for p in target.parents if p.exists() and not p.is_dir()), None)
        why = "is a folder" if target.is_dir() else f"{blocker} is a file, not a folder" if blocker else \
            f"its folder {target.parent} does not exist"
        sys.exit(f"command error: --ssp {target}: {why}; give the path of the .ssp file to write")
    try:
        scenario, paths, descriptions, values = prepare(resolve(name), ci=args.ci, implementation=args.implementation)
        if scenario.sweep:
            inst, var, value = sweep_value(scenario, descriptions, scenario.sweep[1][0])
            values[inst][var] = value
        print(f"SSP written to {export_ssp(scenario, paths, values, target)}")
    except ScenarioError as exc:
        sys.exit(f"scenario error: {exc}")
    except (ResourceError, FmuFileError) as exc:
        sys.exit(f"{name}: {exc}")
    except OSError as exc:
        sys.exit(f"output error: --ssp {target}: {exc.strerror or exc}")


if __name__ == "__main__":
    main()
