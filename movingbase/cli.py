"""Command line of the kit: ``movingbase COMMAND ...`` (or ``python -m movingbase``).

    movingbase                      the main job: the telescope slew and the paper's leg-force charts
    movingbase run SCENARIO ...     run scenario files or shipped names (movingbase run --help)
    movingbase campaign FILE        run a campaign of many scenario runs
    movingbase budget FILE          a geometric tolerance budget (pose error, Sobol indices, allocation)
    movingbase regress SCENARIO... --baseline DIR   compare runs with their stored baselines (--update stores)
    movingbase build                build every FMU (as build.py)
    movingbase headline             regenerate the README's headline from docs/headline.json
    movingbase --version
"""
import argparse
import atexit
import json
import math
import os
import pathlib
import shutil
import signal
import sys

from movingbase import __version__

COMMANDS = ("run", "campaign", "budget", "build", "headline", "regress")
# Each command imports what it runs when it runs: `movingbase --version` and `--help` pay for
# no master, fmpy or Dask (0.04 s, against 0.3 s with every command's imports at the top).


def main(argv=None):
    """The command. As the program (``argv`` None: the console command or ``python -m
    movingbase``) the process ends right after its exit handlers, without the
    interpreter's teardown: freeing numpy's, matplotlib's, fmpy's and the FMUs' modules one
    by one took 0.2-0.3 s of a 2.6 s run (docs/speed.md); every file is closed by then."""
    if argv is not None:
        return _command(list(argv))
    signal.signal(signal.SIGTERM, _terminated)
    for stream in (sys.stdout, sys.stderr):   # a file name or message the locale cannot encode (ASCII,
        stream.reconfigure(errors="backslashreplace")   # Latin-1): shown escaped, never a UnicodeEncodeError
    try:
        status = _command(sys.argv[1:])
    except SystemExit as exc:
        status = exc.code
    if status is not None and not isinstance(status, int):   # sys.exit("message"): printed, status 1
        print(status, file=sys.stderr)
        status = 1
    exit_now(status or 0)


def _terminated(signum, frame):
    """SIGTERM (kill, a batch system's time limit) ends the command as Ctrl-C does: through
    its cleanup (the workers stopped, the unpacked FMUs removed), status 143."""
    raise SystemExit(128 + signum)


def exit_now(status):
    """End the process with ``status`` after its exit handlers (temporary folders) and with
    stdout and stderr flushed, without the interpreter's teardown (the command's and the
    test session's end: see main and tests/conftest.py)."""
    atexit._run_exitfuncs()
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(status)


def _command(argv):
    if argv[:1] in (["--version"], ["-V"]):
        print(f"movingbase {__version__}")
        return
    if argv[:1] in (["-h"], ["--help"]):
        print(__doc__)
        return
    command, rest = (argv[0], argv[1:]) if argv and argv[0] in COMMANDS else ("run", argv)
    if argv and argv[0] not in COMMANDS and not argv[0].startswith("-"):
        unknown = _unknown_command(argv[0])
        if unknown:
            sys.exit(unknown)
    if command == "run":
        return run_command(rest, prog="movingbase run")
    if command == "campaign":
        return campaign_command(rest)
    if command == "budget":
        return budget_command(rest)
    if command == "regress":
        return regress_command(rest)
    if command == "build":
        try:
            build_command(rest)    # it returns the output folder: not an exit status
        except OSError as exc:      # --out onto a file, a folder it may not write, a full disk
            return f"build error: {_os_problem(exc)}"
        return None
    try:
        return headline_command(rest)
    except OSError as exc:          # --from a folder without the full runs' results
        return f"headline error: {_os_problem(exc)} (--from names the --out of the full runs: movingbase run)"
    except (ValueError, KeyError) as exc:     # a metrics.json that is not the kit's
        return f"headline error: --from {rest[-1] if rest else ''}: results that are not the full runs' ({exc!r:.200})"


def _unknown_command(word):
    """The error for a first word that is neither a command nor a scenario (a file or a
    shipped name), or None: `movingbase campain x` was read as scenarios 'campain', 'x'."""
    import difflib

    from scenarios.runs.runner import not_found, resolve
    if resolve(word).exists():
        return None
    near = difflib.get_close_matches(word.lower(), COMMANDS, 1, 0.6)
    return (f"movingbase: unknown command {word!r}" + (f"; did you mean {near[0]!r}?" if near else "")
            + f"\n  commands: {', '.join(COMMANDS)} (movingbase --help)\n  or a scenario: {not_found([word])}")


def _os_problem(exc):
    """'<path>: <what>' of an OSError, a file where a folder belongs said so."""
    target = exc.filename or ""
    return f"{target}: {'is a file, not a folder' if os.path.isfile(target) else exc.strerror or exc}"


def run_command(argv=None, prog="movingbase run"):
    from scenarios.output.report import CHARTS
    from scenarios.runs.runner import shipped_names
    from scenarios.spec import IMPLEMENTATIONS
    shipped = ", ".join(shipped_names())
    parser = argparse.ArgumentParser(prog=prog,
                                     description='Command line: run scenario files (or shipped scenario names) and '
                                                 'write their reports.',
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
    parser.add_argument("--require", action="store_true",
                        help="exit with status 1 if a run does not meet a requirement of its file ([requirements])")
    args = parser.parse_args(argv)
    try:
        return _run(args, shipped)
    except KeyboardInterrupt as exc:     # runner.Interrupted says what it kept
        sys.exit(f"interrupted: {exc}" if str(exc) else
                 f"interrupted: the runs that finished are in {args.out}; a sweep run with --jobs or --dask "
                 "resumes where it stopped when the same command runs again")


def _run(args, shipped):
    """The checks of the command line (all before anything runs), then each scenario."""
    from scenarios.cosim.fmi import FmuFileError
    from scenarios.cosim.records import run_records
    from scenarios.runs import status
    from scenarios.runs.estimates import ResourceError, check_jobs
    from scenarios.runs.runner import OutputError, not_found, resolve, run_scenario
    from scenarios.spec import ScenarioError, judge, unmet
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
    repeated = [
        n for n in dict.fromkeys(names) if [resolve(m).resolve() for m in names].count(resolve(n).resolve()) > 1
    ]
    if clashes or repeated:
        what = [f"{', '.join(sorted(map(str, p)))} would all write to {args.out}/{min(p).stem}"
                for p in clashes.values()]
        what += [f"{n!r} is named more than once" for n in repeated]
        sys.exit(f"scenario error: {'; '.join(what)}: run them in separate commands with their own --out")
    try:
        for warning in (check_jobs(args.jobs),):
            if warning:
                print(warning, file=sys.stderr)
    except ResourceError as exc:
        sys.exit(f"command error: {exc}")
    if args.dask is not None:   # "" too: it once ran locally, silently
        from scenarios.runs.engine import EngineError, check_address  # only here: a local run need not import it
        try:
            check_address(args.dask)
        except EngineError as exc:
            sys.exit(f"command error: {exc}")
    if args.ssp:
        if len(names) > 1:   # one file holds one scenario: the others were dropped without a word
            sys.exit(f"command error: --ssp {args.ssp}: exports one scenario, {len(names)} given "
                     f"({', '.join(names)}); run one --ssp per scenario")
        _export(args, names[0])
        return
    errors, statuses = [], []   # one line each; every scenario and every run is still tried
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
        statuses += [status.of_run(run.failure, run.flags) for run in runs]
        print(f"{scenario.name}: report {report} ({status.told(statuses[-len(runs):])})")
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
        for run in runs:
            for judged in judge(scenario.requirements, run.label, run.metrics):
                value = "not counted" if judged["value"] is None else f"{judged['value']:.3g} {judged['unit']}"
                said = "met" if judged["met"] else "NOT MET"
                print(f"  {run.label}: requirement {judged['requirement']}: {said} ({value})")
            missed = unmet(judge(scenario.requirements, run.label, run.metrics))
            if missed and args.require:
                errors.append(f"requirement error: {scenario.name}, run {run.label}: {missed}")
        flagged = [run.label for run in runs if run.flags and not run.failure]
        if flagged:
            print(f"  {len(flagged)} of {len(runs)} runs FLAGGED ({', '.join(flagged)}): their numbers are not "
                  f"results; see {report}")
    if errors:
        sys.exit("\n".join(errors))
    if not args.scenarios:
        from studies.paper_forces import main as paper_charts  # pyplot: imported by what draws
        paper_charts(f"{args.out}/paper")
    return status.exit_status(statuses) or None     # 3: a run flagged (docs/flagged-runs.md)


def _export(args, name):
    """--ssp: the scenario (its first sweep value) as an SSP file; the target must be a
    file path whose folder exists."""
    from movingbase.api import export_ssp
    from scenarios.cosim.fmi import FmuFileError
    from scenarios.runs.estimates import ResourceError
    from scenarios.spec import ScenarioError
    target = pathlib.Path(args.ssp)
    if target.is_dir() or not target.parent.is_dir():
        blocker = next((p for p in target.parents if p.exists() and not p.is_dir()), None)
        why = "is a folder" if target.is_dir() else f"{blocker} is a file, not a folder" if blocker else \
            f"its folder {target.parent} does not exist"
        sys.exit(f"command error: --ssp {target}: {why}; give the path of the .ssp file to write")
    try:
        print(f"SSP written to {export_ssp(name, target, ci=args.ci, implementation=args.implementation)}")
    except ScenarioError as exc:
        sys.exit(f"scenario error: {exc}")
    except (ResourceError, FmuFileError) as exc:
        sys.exit(f"{name}: {exc}")
    except OSError as exc:
        sys.exit(f"output error: --ssp {target}: {exc.strerror or exc}")


def campaign_command(argv=None):
    from scenarios import spec
    from scenarios.cosim.fmi import FmuFileError
    from scenarios.runs import engine, status
    from scenarios.runs import estimates as resources
    from scenarios.runs.campaign import run_campaign, summary_statuses
    from scenarios.runs.runner import OutputError, unlock_folder
    parser = argparse.ArgumentParser(prog="movingbase campaign",
                                     description='Run a campaign file: many scenario runs, on worker processes or a '
                                                 'Dask cluster, results in a store.')
    parser.add_argument("campaign", help="campaign file (TOML)")
    parser.add_argument("--ci", action="store_true", help="apply the file's [ci] replacements (a small campaign)")
    parser.add_argument("--jobs", type=int, help="local worker processes (default: all cores)")
    parser.add_argument("--dask", metavar="ADDR", help="run on the Dask cluster whose scheduler is at ADDR")
    parser.add_argument("--out", default="out", help="output folder (default: out)")
    parser.add_argument("--retry-failed", action="store_true", help="run again the runs that failed before")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")
    parser.add_argument("--sample", type=int, metavar="K", help="run sample K of the file's [sample] alone, in this "
                        "process, and compare it with the campaign's result on disk (writes nothing)")
    args = parser.parse_args(argv)
    if args.sample is not None:
        return _rerun_sample(args)
    try:
        warning = resources.check_jobs(args.jobs)
        if warning:
            print(warning, file=sys.stderr)
        if args.dask is not None:   # "" too: it once ran locally, silently
            engine.check_address(args.dask)
        campaign, job_list, store, outcome, summary = run_campaign(
            args.campaign, args.out, args.ci, args.jobs, args.dask, not args.quiet, args.retry_failed)
    except spec.ScenarioError as exc:       # a CampaignError too
        sys.exit(f"campaign error: {exc}")
    except (resources.ResourceError, engine.EngineError, OutputError, FmuFileError) as exc:
        sys.exit(f"campaign error: {exc}")
    except OSError as exc:
        sys.exit(f"campaign error: output: {exc.filename or args.out}: {exc.strerror or exc}")
    except KeyboardInterrupt:
        sys.exit("interrupted: the runs finished so far are on disk; run the same command again to resume")
    unlock_folder(summary.parent)
    statuses = summary_statuses(summary)
    print(f"{campaign.name}: {status.told(statuses.values())}; {len(outcome.computed)} done now, "
          f"{len(outcome.skipped)} found on disk, in {outcome.wall_time:.1f} s; summary {summary}")
    if outcome.damaged:
        print(f"  {len(outcome.damaged)} damaged results were found and run again (named above)")
    if outcome.orphans:
        print(f"  {outcome.orphans} results in {store.folder} belong to no run of this campaign (other settings, "
              "or FMUs of other sources); they are kept: delete them to reclaim the space")
    labels = {job.key: job.label for job in job_list}
    for key, message in list(outcome.failed.items())[:10]:
        print(f"  failed: {labels[key]}: {message.splitlines()[0]}")
    flagged = [label for label, s in statuses.items() if s == status.FLAGGED]
    if flagged:
        print(f"  flagged: {', '.join(flagged[:10])}{' ...' if len(flagged) > 10 else ''}: their numbers are not "
              "results; the flags column of the summary says why")
    if outcome.interrupted:
        sys.exit("interrupted: the runs finished so far are on disk; run the same command again to resume")
    return status.exit_status(statuses.values()) or None


def budget_command(argv=None):
    from scenarios.runs.budget import BudgetError, run_budget
    from scenarios.runs.estimates import ResourceError
    parser = argparse.ArgumentParser(prog="movingbase budget",
                                     description="Run a geometric tolerance budget file: the pose error over the "
                                                 "workspace at the file's probability, Sobol indices by input group, "
                                                 "and the tolerances that meet the targets.")
    parser.add_argument("budget", help="budget file (TOML) or a shipped name (default, nanshan)")
    parser.add_argument("--samples", type=_count, help="Monte Carlo samples (default: the file's; 1e6 is 1000000)")
    parser.add_argument("--out", help="write the results to DIR/<name>.json")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")
    args = parser.parse_args(argv)
    try:
        result = run_budget(args.budget, args.samples, args.out, not args.quiet)
    except (BudgetError, ResourceError) as exc:
        sys.exit(f"budget error: {exc}")
    except OSError as exc:
        sys.exit(f"budget error: output: {exc.filename or args.out}: {exc.strerror or exc}")
    print(summary(result))


def _count(text):
    """A whole number as written on a command line: "2000", "2e3", "1_000_000"."""
    try:
        number = float(text.replace("_", ""))
    except ValueError:
        number = math.nan
    if not (math.isfinite(number) and number == int(number)):
        raise argparse.ArgumentTypeError(f"expected a whole number, got {text!r}")
    return int(number)


def summary(result):
    """The lines ``movingbase budget`` prints of a budget's result."""
    si = {"m": (1e6, "um"), "rad": (1e6, "urad"), "1": (1e6, "ppm")}
    from scenarios.output import budget_report
    from scenarios.output.budget_report import percent
    lines = [f"{result['name']}: {result['samples']:,d} samples, pose error at {percent(result['probability'])}:"]
    confidence = result.get("confidence", 0.95)
    for metric, q in result["quantiles"].items():
        verdict = "met" if q["met"] else "NOT met (its interval reaches it)" if q["value"] < q["target"] else "NOT met"
        lines.append(f"  {metric:9s} {q['value'] * 1e6:9.2f} um  ({percent(confidence)} interval {q['low'] * 1e6:.2f}.."
                     f"{q['high'] * 1e6:.2f})  target {q['target'] * 1e6:g} um: {verdict}")
    if "sobol" in result:
        s = result["sobol"]
        for i, component in enumerate(s["components"]):
            ranked = sorted(zip(s["groups"], s["total"][i], s["total_conf"][i]), key=lambda r: -r[1])[:3]
            lines.append(f"  Sobol total, {component}: " + ", ".join(f"{g} {v:.3f}+-{c:.3f}" for g, v, c in ranked))
    if "allocation" in result:
        a = result["allocation"]
        lines.append(f"  allocation (cost {a['cost']:.3g} against {a['cost_as_given']:.3g} as given; "
                     f"checked: {'met' if a['verified'] else 'NOT met'}):")
        for group, g in a["groups"].items():
            factor, unit = si[g["tolerance"][1]]
            lines.append(f"    {group:18s} x{g['scale']:.3f} -> {g['tolerance'][0] * factor:9.3f} {unit}"
                         f"  (cost {g['cost']:.3g})")
    state, flags = budget_report.status(result)
    lines.append(f"status: {state}" + (f" ({len(flags)} flag{'s' * (len(flags) != 1)}: the targets not met are "
                                       "above, as NOT met)" if flags else ": every target met"))
    return "\n".join(lines)


def regress_command(argv=None):
    """movingbase regress: exit status 0 every scenario passed, 1 a regression, 2 a
    scenario (or the command) that could not run."""
    from scenarios.output.regress_report import write_junit, write_report
    from scenarios.runs import regress
    from scenarios.runs.estimates import ResourceError, check_jobs
    from scenarios.spec import units
    parser = argparse.ArgumentParser(prog="movingbase regress",
                                     description="Hold scenarios in CI: re-run each and compare its signals (within "
                                                 "a tube), metrics (within tolerances), status and flags with the "
                                                 "baseline stored in --baseline DIR; --update stores the baseline. "
                                                 "Exit status 0 pass, 1 regression, 2 could not run.")
    parser.add_argument("scenarios", nargs="+", help="scenario files or shipped names")
    parser.add_argument("--baseline", required=True, metavar="DIR", help="folder of the baselines (one per file)")
    parser.add_argument("--update", action="store_true", help="run and store the baselines (saying first what "
                        "changed against those they replace); tolerances from the run at half the plant's step")
    parser.add_argument("--ci", action="store_true", help="apply each file's [ci] overrides (short runs)")
    parser.add_argument("--tolerance", action="append", default=[], metavar="'NAME = QUANTITY'",
                        help="override one tolerance, with units: 'pose error peak = 0.5 um', 'plant.pose = 1 um' "
                             "(repeatable; with --update it is stored)")
    parser.add_argument("--signal", action="append", default=[], metavar="INST.VAR",
                        help="with --update: a recorded variable to store and compare (repeatable; default: the "
                             "variables the metrics read)")
    parser.add_argument("--time-tolerance", default="0 s", metavar="DURATION",
                        help="width of the signals' tubes in time (default 0 s: the record grid is fixed)")
    parser.add_argument("--junit", metavar="FILE", help="write a JUnit XML file for CI servers")
    parser.add_argument("--report", metavar="DIR", help="write DIR/regress.md with a chart per failure")
    parser.add_argument("--jobs", type=int, help="run each file's sweep values on N worker processes")
    parser.add_argument("--fmi-version", type=int, choices=(2, 3), help="run every native FMU as FMI 2.0 or 3.0")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")
    args = parser.parse_args(argv)
    try:
        warning = check_jobs(args.jobs)
        if warning:
            print(warning, file=sys.stderr)
        overrides = dict(regress.parse_override(text) for text in args.tolerance)
        time_tol = units.to_si(args.time_tolerance, "s")
        outcome = regress.regress(args.scenarios, args.baseline, args.update, args.ci, overrides, time_tol, args.jobs,
                                  None, args.fmi_version, not args.quiet, args.signal)
    except (regress.BaselineError, units.UnitError, ResourceError) as exc:
        print(f"regress error: {exc}", file=sys.stderr)
        return 2
    print(outcome.summary())
    try:
        if args.junit:
            print(f"JUnit: {write_junit(outcome, args.junit)}")
        if args.report:
            print(f"report: {write_report(outcome, args.report)}")
    except OSError as exc:
        print(f"regress error: output: {exc.filename}: {exc.strerror or exc}", file=sys.stderr)
        return 2
    return outcome.exit_code


def _rerun_sample(args):
    from scenarios import spec
    from scenarios.cosim.fmi import FmuFileError
    from scenarios.runs.campaign import rerun_sample
    from scenarios.runs.runner import OutputError
    try:
        done = rerun_sample(args.campaign, args.sample, args.out, args.ci)
    except (spec.ScenarioError, OutputError, FmuFileError) as exc:
        sys.exit(f"campaign error: {exc}")
    for job, result, stored in done:
        print(f"{job.label}: {result['status']} {result.get('error', '')}".rstrip())
        for name, values in result.get("metrics", {}).items():
            print(f"  {name}: " + ", ".join(f"{k} {v!r}" for k, v in values.items() if k != "unit")
                  + f" {values.get('unit', '')}")
        print("  " + (f"DAMAGED on disk, not compared: {result['damaged']} (the campaign's run of it "
                      "runs it again)" if "damaged" in result else
                      "not on disk: no campaign result to compare" if stored is None else
                      "equal to the campaign's result bit for bit" if result["same"] else
                      "DIFFERS from the campaign's result"))
    if any("damaged" in result or stored is not None and not result["same"] for _, result, stored in done):
        sys.exit(1)


def build_command(argv=None, prog="movingbase build"):
    from fmu_src import native_build
    from fmu_src.python_build import OUT, available, build, write_stamp
    parser = argparse.ArgumentParser(prog=prog,
                                     description='Build every FMU of the kit: pythonfmu (FMI 2.0), native (FMI 2.0) '
                                                 'and native (FMI 3.0).')
    parser.add_argument("--out", default=str(OUT), help="output folder")
    parser.add_argument("names", nargs="*", default=available(),
                        help="FMU scripts to build (default: all)")
    args = parser.parse_args(argv)
    out = pathlib.Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    for name in args.names:
        fmu = build(name, out)
        write_stamp(out / f"{name}.built", fmu)
        print(f"built {fmu}")
        native = native_build.build_native(fmu, out / "native")
        print(f"built {native}")
        print(f"built {native_build.build_native3(native, out / 'native3')}")
    print(f"FMUs are in {out}: pythonfmu (FMI 2.0), native/ (FMI 2.0), native3/ (FMI 3.0)")
    return out


def headline_command(argv=None):
    from scenarios.output.headline import CHART, README, ROOT, STORE, Flagged, collect, rewrite_readme
    parser = argparse.ArgumentParser(prog="movingbase headline",
                                     description="Regenerate the README's headline from docs/headline.json.")
    parser.add_argument("--from", dest="out", metavar="DIR", help="take the metrics of the full runs in DIR first")
    args = parser.parse_args(argv)
    if args.out:
        out = pathlib.Path(args.out)
        try:
            store = collect(out)
        except Flagged as exc:
            raise SystemExit(f"headline error: {exc}") from None
        STORE.write_text(json.dumps(store, indent=1, ensure_ascii=False) + "\n")
        shutil.copyfile(out / CHART[0] / CHART[1], CHART[2])
    rewrite_readme(json.loads(STORE.read_text()))
    print(f"{README.name}: headline rewritten from {STORE.relative_to(ROOT)}")


