"""Run a scenario file end to end: check it, build the FMUs it needs, co-simulate each
sweep value with a progress bar, and write results, charts and the report. A run an FMU
stops is kept with its partial results and marked; the other sweep values still run."""
import contextlib
import difflib
import errno
import fcntl
import json
import logging
import os
import pathlib
import sys
import time

from fmu_src import atomic, catalogue
from fmu_src.native_build import ensure_native, ensure_native3
from fmu_src.python_build import ensure_built
from plant.hexapod.model import FIDELITIES
from scenarios import spec
from scenarios.cosim import master
from scenarios.cosim.fmi import description
from scenarios.output import report
from scenarios.runs import auto_fidelity, flags, metrics, single
from scenarios.runs import estimates as resources

SHIPPED = pathlib.Path(__file__).resolve().parents[1] / "files"


def resolve(name):
    """A scenario file path (".toml" may be left out), or the bare name of a shipped
    scenario (scenarios/files/<name>.toml); anything else as given, for load to refuse."""
    path = pathlib.Path(name).expanduser()
    if path.name in ("", ".", ".."):    # "", ".", "/", "..": a folder, which load refuses as such
        return path
    candidates = [path, path.with_name(path.name + ".toml")] if path.suffix != ".toml" else [path]
    if path.parent == pathlib.Path(".") and path.suffix != ".toml":
        candidates.append(SHIPPED / f"{path.name}.toml")
    return next((c for c in candidates if c.is_file()), path)


def shipped_names():
    """Names of the scenario files shipped in scenarios/files/."""
    return sorted(p.stem for p in SHIPPED.glob("*.toml"))


def not_found(names):
    """What to say of names that are neither a scenario file nor a shipped scenario: the
    shipped names, and the nearest one where a name is close ("telescope_slew "). A name
    with a folder in it can only be a file (resolve looks for shipped ones by bare name), so
    the list is left out there: with 14 shipped scenes it made a message with a long path
    (shortened, shown twice) 725 characters long."""
    shipped = shipped_names()
    near = [difflib.get_close_matches(str(n).strip().lower(), shipped, 1, 0.6) for n in names]
    hints = "".join(f"; did you mean {m[0]!r} for {spec.shown(n)!r}?" for n, m in zip(names, near) if m)
    bare = any(pathlib.Path(n).parent == pathlib.Path(".") for n in names)
    return (f"no scenario file or shipped scenario named {', '.join(repr(spec.shown(n)) for n in names)}{hints}"
            + (f"; shipped: {', '.join(shipped)}" if bare else ""))


class OutputError(ValueError):
    """An output folder that cannot take the results; the message names it and why."""


def output_folder(out, path):
    """``out``/<the scenario file's stem>: the results follow the file the user ran (a
    copy of a shipped scenario does not write into the shipped one's folder). Created
    here; OutputError if ``out`` is empty or a file, cannot be created or is not writable."""
    out = pathlib.Path(_named(out))
    stem = pathlib.Path(path).stem
    if stem in ("", ".", ".."):       # "..toml", "...toml": out itself or its parent, not a folder under it
        raise OutputError(f"file name {spec.shown(repr(pathlib.Path(path).name))}: without .toml, {stem!r} cannot "
                          "name its output "
                          f"folder under {out} (it would write into {out / stem}); rename the file")
    return lock_folder(make_folder(out / stem))


LOCK = ".movingbase.lock"
_LOCKS: dict = {}                     # folder -> the open lock file this process holds (until it exits)


def lock_folder(folder):
    """``folder``, locked for this process (fcntl.flock on ``folder``/.movingbase.lock, held
    until the process exits): a second process writing the same results (two runs into one
    --out) is refused naming the first, instead of mixing its files with the other's."""
    key = os.path.realpath(folder)
    if key in _LOCKS:
        return folder
    fd = os.open(os.path.join(key, LOCK), os.O_RDWR | os.O_CREAT, 0o666)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        holder = os.read(fd, 200).decode("utf-8", "replace").strip() or "another process"
        os.close(fd)
        raise OutputError(f"output folder {spec.shown(folder)} is in use by {holder}, which writes its results there; "
                          "wait for it to end or choose another output folder") from None
    os.ftruncate(fd, 0)
    os.write(fd, f"process {os.getpid()} ({' '.join(sys.argv)[:120]})".encode("utf-8", "surrogateescape"))
    _LOCKS[key] = fd
    return folder


def unlock_folder(folder):
    """Release ``folder``'s lock (lock_folder) and remove its lock file: a notebook's
    process lives on after its runs, and the file was left beside the results."""
    key = os.path.realpath(folder)
    fd = _LOCKS.pop(key, None)
    if fd is None:
        return
    with contextlib.suppress(OSError):
        os.unlink(os.path.join(key, LOCK))    # while still locked: no other process holds it meanwhile
    os.close(fd)


class Interrupted(KeyboardInterrupt):
    """Ctrl-C during a sweep: ``runs`` those that finished (master.Run), ``stopped`` the
    label of the run it stopped, ``left`` the labels not run to their end (it among them);
    ``result`` what movingbase.run makes of the finished runs (set there)."""

    def __init__(self, runs, stopped, left):
        super().__init__(f"interrupted during run {stopped!r}")
        self.runs, self.stopped, self.left, self.result = runs, stopped, left, None


def interrupted_message(scenario, interrupted, outdir, command=False):
    """What an interrupted sweep kept and how to run the rest (the exception's message), in
    Python's words or, with ``command``, the command line's."""
    kept = ", ".join(repr(r.label) for r in interrupted.runs) or "none"
    where = f": records, metrics.json and a report marked interrupted in {outdir}" if outdir and interrupted.runs \
        else " (in memory: the exception's .result holds them; out= would have written them)" if interrupted.runs \
        else ""
    values = [v for v in (scenario.sweep[1] if scenario.sweep else [])
              if spec.run_label(v) in interrupted.left]
    if command:
        rest = (f"a copy of {pathlib.Path(scenario.source).name} with [sweep] values = {values!r}, run into another "
                "--out" if scenario.sweep else "the same command")
    else:
        rest = (f"set={{'sweep': {{'parameter': {scenario.sweep[0]!r}, 'values': {values!r}}}}}"
                if scenario.sweep else "the same call")
    return (f"{scenario.name} interrupted during run {interrupted.stopped!r}: runs finished: {kept}{where}; "
            f"not run to their end: {', '.join(map(repr, interrupted.left))}; to run the rest: {rest}")


def _named(folder):
    """``folder`` unless it is empty ("" is the current folder to pathlib: never meant)."""
    if not isinstance(folder, (str, os.PathLike)):
        raise OutputError(f"the output folder must be a path, got {type(folder).__name__} {folder!r:.60}")
    if not str(folder).strip():
        raise OutputError("the output folder (--out, out=, report()) is empty; name the folder the results go to")
    return folder


def make_folder(folder):
    """The folder ``folder``, created; OutputError, naming it, if it is empty or a file (or
    under one), cannot be created or is not writable."""
    folder = pathlib.Path(_named(folder))
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        said = _blocker(folder) or f"cannot be created ({exc.strerror})"
        raise OutputError(f"output folder {spec.shown(folder)}: {said}; choose another folder") from None
    if not os.access(folder, os.W_OK | os.X_OK):
        raise OutputError(f"output folder {spec.shown(folder)}: not writable; choose another folder")
    return folder


def _blocker(folder):
    """What stands where ``folder`` (or a folder above it) should be: a file, a link to
    nothing, a link loop; None if nothing does."""
    for path in (folder, *folder.parents):
        if path.is_symlink() and not path.exists():
            try:
                path.resolve(strict=True)
            except (RuntimeError, OSError) as exc:    # a loop: RuntimeError, or ELOOP from Python 3.13
                if isinstance(exc, RuntimeError) or exc.errno == errno.ELOOP:
                    return f"{spec.shown(path)} is a symbolic link in a loop, not a folder"
                return f"{spec.shown(path)} is a symbolic link to {spec.shown(os.readlink(path))}, which does not exist"
        if path.exists() and not path.is_dir():
            return f"{spec.shown(path)} is a file, not a folder"
    return None


def replaced(folder):
    """What an earlier run left in ``folder`` that this run replaces, as one line, or ""."""
    earlier = sorted(p.name for p in pathlib.Path(folder).iterdir() if p.is_file() and p.name != LOCK)
    if not earlier:
        return ""
    when = max(pathlib.Path(folder, n).stat().st_mtime for n in earlier)
    shown = ", ".join(earlier[:4]) + (f" and {len(earlier) - 4} more" if len(earlier) > 4 else "")
    return (f"{folder} holds the results of an earlier run (last written "
            f"{time.strftime('%Y-%m-%d %H:%M', time.localtime(when))}): {shown}; this run replaces them")


def left_over(folder, since):
    """The files in ``folder`` this run did not rewrite (older than ``since``, its start),
    as one line, or "": an earlier run's charts beside this run's report (--charts none,
    another sweep) are not its results."""
    kept = sorted(p.name for p in pathlib.Path(folder).iterdir()
                  if p.is_file() and p.name != LOCK and p.stat().st_mtime < since)
    if not kept:
        return ""
    shown = ", ".join(kept[:6]) + (f" and {len(kept) - 6} more" if len(kept) > 6 else "")
    return f"{folder}: {shown} from the earlier run are not this run's (it wrote no such file); delete them"


@contextlib.contextmanager
def announcing_builds(on=True):
    """While it lasts, every FMU build (the builders' "movingbase.build" log) is said on
    stderr as it starts: a first build takes seconds, and nothing is said when none is due."""
    if not on:
        yield
        return
    said = logging.StreamHandler(sys.stderr)
    said.setFormatter(logging.Formatter("%(message)s"))
    log = logging.getLogger("movingbase.build")
    level = log.level
    log.setLevel(logging.INFO)     # setLevel, not .level: it clears the logger's cache of what is enabled
    log.addHandler(said)
    try:
        yield
    finally:
        log.removeHandler(said)
        log.setLevel(level)


def prepare(path, ci=False, implementation=None, out=None, fmi_version=None):
    """Scenario, FMU paths per instance and checked parameter values: all checks done
    before anything runs. ``ci`` applies the file's [ci] overrides (a shorter run);
    ``implementation`` ("native" or "python") and ``fmi_version`` (2 or 3; 3 with the
    native FMUs) override every instance's choice; ``out`` (a folder) is checked to hold
    the records (scenarios.runs.estimates), warnings printed."""
    scenario = spec.load(path)
    told = spec.sources_of(scenario.ci, "the value of [ci], for --ci") if ci else {}
    if told:
        scenario = spec.load(path, overrides=scenario.ci, told_as=told)
    scenario.short = bool(ci)
    try:
        return prepare_loaded(scenario, implementation, out, fmi_version)
    except spec.ScenarioError as exc:
        raise spec.with_sources(exc, told) from None


def prepare_loaded(scenario, implementation=None, out=None, fmi_version=None):
    """prepare for a Scenario already loaded (and changed in Python, movingbase.api)."""
    if implementation is not None:
        if implementation not in spec.IMPLEMENTATIONS:
            raise ValueError(f"implementation must be one of {spec.IMPLEMENTATIONS}, got {implementation!r}")
        scenario.implementations = dict.fromkeys(scenario.fmus, implementation)
        if implementation == "python":   # the pythonfmu FMUs are FMI 2.0
            scenario.fmi_versions = dict.fromkeys(scenario.fmus, 2)
    if fmi_version is not None:
        if fmi_version not in spec.FMI_VERSIONS:
            raise ValueError(f"fmi_version must be one of {spec.FMI_VERSIONS}, got {fmi_version!r}")
        if fmi_version == 3 and "python" in scenario.implementations.values():
            raise ValueError("fmi_version 3 needs the native FMUs: the pythonfmu FMUs are FMI 2.0")
        scenario.fmi_versions = dict.fromkeys(scenario.fmus, fmi_version)
    paths = fmu_paths(scenario)
    descriptions = {inst: description(p) for inst, p in paths.items()}
    runs = len(scenario.sweep[1]) if scenario.sweep else 1
    warning = resources.check(resources.estimate(scenario, descriptions, runs), out or ".", scenario.source)
    if warning:
        print(warning, file=sys.stderr)
    auto = [inst for inst, params in scenario.parameters.items() if params.get("fidelity") == "auto"]
    for inst in auto:
        scenario.parameters[inst]["fidelity"] = "full"    # bound as full, then chosen below
    values = spec.bind(scenario, descriptions)
    for inst in auto:
        _choose_fidelity(scenario, paths, values, inst)
    return scenario, paths, descriptions, values


def fmu_paths(scenario):
    """instance -> FMU file of the implementation the scenario chose for it (built if stale)."""
    chosen = {inst: (catalogue.BY_KEY[fmu].script, _kind(scenario.implementations.get(inst, spec.IMPLEMENTATIONS[0]),
                                                  scenario.fmi_versions.get(inst, 2)))
              for inst, fmu in scenario.fmus.items()}
    built = {kind: build(sorted({s for s, impl in chosen.values() if impl == kind})) for kind, build in BUILDS.items()}
    return {inst: built[impl][script] for inst, (script, impl) in chosen.items()}


# how each kind of FMU file is built (if missing or stale) from its fmu_src script: pythonfmu,
# native C FMI 2.0, native C FMI 3.0
BUILDS = {"python": ensure_built, "native": ensure_native, "native3": ensure_native3}


def _kind(implementation, fmi_version):
    """The BUILDS key of an implementation at an FMI version."""
    return implementation + ("3" if fmi_version == 3 else "")


def fmu_files(fmus, implementation="native", fmi_version=2):
    """{fmu: FMU file} of the scenario files' FMU names (catalogue.KEYS), built if missing
    or stale; ValueError naming an unknown name or a kind the kit does not build."""
    unknown = [f for f in fmus if f not in catalogue.KEYS]
    if unknown:
        near = difflib.get_close_matches(unknown[0], list(catalogue.KEYS), 1, 0.6)
        raise ValueError(f"no FMU {unknown[0]!r}" + (f"; did you mean {near[0]!r}?" if near else "")
                         + f" The kit's FMUs: {', '.join(catalogue.KEYS)}")
    if implementation not in spec.IMPLEMENTATIONS or fmi_version not in spec.FMI_VERSIONS or isinstance(fmi_version,
                                                                                                        bool):
        raise ValueError(f"implementation is one of {', '.join(spec.IMPLEMENTATIONS)} and fmi_version 2 or 3, "
                         f"got {implementation!r} and {fmi_version!r}")
    if implementation == "python" and fmi_version == 3:
        raise ValueError("the pythonfmu FMUs are FMI 2.0 only; FMI 3.0: implementation='native'")
    built = BUILDS[_kind(implementation, fmi_version)]([catalogue.BY_KEY[f].script for f in fmus])
    return {f: built[catalogue.BY_KEY[f].script] for f in fmus}


def _choose_fidelity(scenario, paths, values, plant):
    """Replace the plant's fidelity by the cheapest within the scenario's tolerance."""
    sources = {src.split(".", 1)[0] for src, targets in scenario.connections if f"{plant}.base_pose" in targets}
    telescope = next((s for s in sources if scenario.fmus[s] == "telescope"), None)
    if telescope is None:
        raise spec.ScenarioError(scenario.source, f"fmus.{plant}.parameters.fidelity",
                                 '"auto" needs the plant\'s base_pose fed by a telescope FMU')
    errors = auto_fidelity.fidelity_errors(auto_fidelity.scene_motion(scenario, paths, values, telescope))
    choice = auto_fidelity.choose(errors, scenario.fidelity_tolerance)
    values[plant]["fidelity"] = FIDELITIES.index(choice)
    scenario.parameters[plant]["fidelity"] = choice
    listed = ", ".join(f"{f} {e:.3g} N" for f, e in errors.items())
    scenario.notes.append(f"fidelity auto for {plant}: chose {choice!r} (tolerance {scenario.fidelity_tolerance:g} N; "
                          f"largest leg-force error of each level along this scene: {listed})")


def run_scenario(path, out="out", ci=False, progress=True, jobs=None, dask=None, implementation=None,
                 allow_unstable=False, fmi_version=None, charts="all"):
    """Run every sweep value of a scenario; returns (scenario, runs, report path).
    ``jobs`` worker processes or the Dask cluster at ``dask`` run the values in parallel;
    ``implementation`` and ``fmi_version`` as in prepare; ``charts`` as report.write. A step beyond the
    predicted stability limit (each run's own, pre_run_flags) is refused (ScenarioError) unless
    ``allow_unstable``; then the runs beyond their limit are flagged."""
    with announcing_builds(progress):
        scenario, paths, descriptions, values = prepare(resolve(path), ci, implementation, out, fmi_version)
    before = pre_run_flags(scenario, paths, descriptions, values, ci, allow_unstable)
    for line in foretold(scenario, before):
        print(line, file=sys.stderr, flush=True)
    outdir = output_folder(out, scenario.source)
    earlier, started = replaced(outdir), time.time()
    if earlier:
        print(earlier, file=sys.stderr)
    try:
        runs = run_prepared(scenario, paths, descriptions, values, outdir, progress, jobs, dask, before)
    except Interrupted as stopped:
        keep_interrupted(scenario, stopped, outdir, charts, command=True)
        raise
    written = write_results(scenario, runs, outdir, charts)
    if earlier and left_over(outdir, started):
        print(left_over(outdir, started), file=sys.stderr)
    unlock_folder(outdir)
    return scenario, runs, written


def keep_interrupted(scenario, interrupted, outdir, charts="all", command=False):
    """Write what an interrupted sweep finished (its records are on disk already) with a
    report marked interrupted, release the folder, and say it all in the exception."""
    if outdir is not None:
        if interrupted.runs:
            write_results(scenario, interrupted.runs, outdir, charts, interrupted.left)
        unlock_folder(outdir)
    interrupted.args = (interrupted_message(scenario, interrupted, outdir, command),)


def run_prepared(scenario, paths, descriptions, values, outdir=None, progress=True, jobs=None, dask=None,
                 before=()):
    """Run every sweep value of a prepared scenario; returns the master.Run objects. Each
    run's records go to outdir/<label>.npz; with no ``outdir`` nothing is written (runs in
    this process only: the engine stores its results on disk). ``before``: each run's
    flags known before it runs, by label (pre_run_flags)."""
    if outdir is not None:
        outdir.mkdir(parents=True, exist_ok=True)
    before = before or {}
    runs, todo = [], list(sweep_runs(scenario, descriptions, values))
    if jobs or dask:   # the values on worker processes or a Dask cluster (scenarios.runs.engine)
        from scenarios.runs import engine  # here: a run in this process need not import it (17 ms)
        items = scenario.sweep[1] if scenario.sweep else [None]
        runs, todo = engine.run_sweep(scenario, paths, descriptions, values, items, outdir, jobs, dask, progress), []
        for run in runs:
            run.flags[:0] = before.get(run.label, ())
    try:   # the records are written on a thread while the next run loads and steps (~15 ms a run)
        for label, params in todo:
            desc = f"{scenario.name} [{label}]"
            bar = single.progress_bar(total=100, desc=f"{desc} loading and initialising the FMUs", unit="%",
                                      disable=not progress,
                                      bar_format="{desc}: {percentage:3.0f}%|{bar}| {elapsed}<{remaining}")

            def update(fraction, bar=bar, desc=desc, begun=[]):
                if not begun:   # stepping has begun: the FMUs are loaded
                    begun.append(True)
                    bar.set_description_str(desc, refresh=False)
                bar.update(round(100 * fraction) - bar.n)
            try:
                runs.append(single.run(scenario, paths, params, outdir, label,
                                       [metrics.make(m) for m in scenario.metrics], update, before.get(label, ()),
                                       save_later=True))
                if runs[-1].flags:
                    bar.set_description_str(f"{desc} flagged", refresh=False)
            except master.RunFailed as failed:   # keep what it did; the other runs still run
                failed.run.failure = f"{scenario.source}: scene {scenario.name}, run {label}: {failed.run.failure}"
                runs.append(failed.run)
                bar.set_description_str(f"{desc} FAILED at t = {failed.run.sim_time:g} s", refresh=False)
                bar.close()                      # where it stopped, not 100 %
                continue
            except KeyboardInterrupt:            # Ctrl-C: the finished runs are kept (Interrupted)
                bar.close()
                done = {r.label for r in runs}
                raise Interrupted(runs, label, [lb for lb, _ in sweep_runs(scenario, descriptions, values)
                                                if lb not in done]) from None
            except BaseException:                # an error that ends the command
                bar.close()                      # where it stopped, not 100 %
                raise
            bar.update(100 - bar.n)
            bar.close()
    finally:
        atomic.settle()   # every finished run's file in place before anything says it is (or an error)
    return runs


def write_results(scenario, runs, outdir, charts="all", interrupted=()):
    """metrics.json, the ``charts`` (report.CHARTS) and report.md of the runs into outdir;
    the report's path. ``interrupted``: the labels Ctrl-C left unrun (the report says so)."""
    summary = {r.label: {"metrics": r.metrics, "wall_time_s": r.wall_time, "steps": r.steps,
                         "real_time_factor": r.real_time_factor, **({"failed": r.failure} if r.failure else {}),
                         **({"ci": True} if scenario.short else {}),     # a short run: no full run's numbers
                         "flags": flags.as_dicts(r.flags),
                         **({"requirements": spec.judge(scenario.requirements, r.label, r.metrics)}
                            if scenario.requirements else {})}
               for r in runs}
    outdir.mkdir(parents=True, exist_ok=True)
    atomic.write_text(outdir / "metrics.json", json.dumps(_no_nan(summary), indent=2, default=float))
    return report.write(scenario, runs, outdir, charts, interrupted)


def sweep_runs(scenario, descriptions, values):
    """(label, parameters) of every run of the scenario: one per sweep value, its value applied."""
    for item in scenario.sweep[1] if scenario.sweep else [None]:
        params = {inst: dict(v) for inst, v in values.items()}
        if item is None:
            yield "run", params
            continue
        inst, name, value = spec.sweep_value(scenario, descriptions, item)
        params[inst][name] = value
        yield spec.run_label(item), params


def pre_run_flags(scenario, paths, descriptions, values, ci=False, allow_unstable=False):
    """The stability prediction and the scene's own checks (scenarios.runs.flags) of every run
    at its own values (a sweep value can move the limit; each distinct loop is predicted
    once): {label: the flags the run gets}. Raises ScenarioError before anything runs if
    any run's step is beyond its own limit, naming each such run and its limit, unless
    ``allow_unstable``: then exactly those runs are flagged."""
    found, refused, cache = {}, [], {}
    for label, params in sweep_runs(scenario, descriptions, values):
        try:
            found[label] = flags.check(scenario, flags.predict(scenario, paths, descriptions, params, ci, cache),
                                       allow_unstable)
        except spec.ScenarioError as exc:
            refused.append((label, exc))
    if refused and not scenario.sweep:
        raise refused[0][1]
    if refused:   # runs refused for the same reason (a sweep that leaves the loop as it is) told once
        by_problem = {}
        for label, refusal in refused:
            for _, _, problem in refusal.problems:
                by_problem.setdefault(problem, []).append(label)
        raise spec.ScenarioError.joined([spec.ScenarioError(
            scenario.source, "step", f"run{'s' * (len(labels) > 1)} {', '.join(map(repr, labels))} "
                                     f"(sweep of {scenario.sweep[0]}): {problem}")
            for problem, labels in by_problem.items()])
    return found


def foretold(scenario, before):
    """What the flags known before the runs (pre_run_flags) say of the motion, as lines to
    say BEFORE running: a slew cut by the stop time is known from its analytic profile, and
    a user who waited for a 60 s run to learn it needs 107 s tried twice more."""
    by_message = {}
    for label, found in before.items():
        for flag in found:
            if flag.kind == "motion_unfinished":
                by_message.setdefault(flag.message, []).append(label)
    return [f"{scenario.name}: run{'s' * (len(labels) > 1)} {', '.join(map(repr, labels))} will be flagged "
            f"motion_unfinished: {message}" for message, labels in by_message.items()]


def _no_nan(value):
    """JSON has no NaN: what was not measured (a failed run's metrics) is written null."""
    if isinstance(value, dict):
        return {k: _no_nan(v) for k, v in value.items()}
    if isinstance(value, float) and value != value:
        return None
    return value
