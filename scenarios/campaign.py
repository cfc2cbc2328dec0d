"""Campaign files: many runs of one base scenario over a grid or a list of cases, run
through scenarios.engine (local worker processes or a Dask cluster), resumable.

    movingbase campaign FILE [--ci] [--jobs N] [--dask tcp://HOST:PORT] [--out DIR]

A campaign is TOML:

    name = "sky_slews"
    scenario = "telescope_slew"        # a shipped name, or a path relative to this file
    set = { stop_time = "30 s", "base.lever_arm" = "25 m" }   # the same for every run
    [[grid]]                           # one axis of a cartesian product; keys in one
    "base.start_elevation" = ["30 deg", "60 deg"]             # axis vary together
    "base.target_elevation" = ["35 deg", "65 deg"]
    [[grid]]
    "controller.feedforward" = ["fixed_base", "moving_base"]
    [[cases]]                          # optional list of cases, crossed with the grid
    label = "east"
    "base.start_azimuth" = "90 deg"
    [ci]                               # replaces name/set/grid/cases for the short CI run

A key is a scenario top-level setting (start_time, stop_time, step, master,
extrapolation) or "instance.parameter" of the base scenario (dotted keys may be written
unquoted). The base scenario's [sweep] is one more axis unless the campaign sets that
parameter. Every key and value is checked before anything runs; errors name the file,
the key and the problem, like scenario files.

Results: <out>/<name>/runs/<key>.json|.npz (scenarios.engine.Store) and summary.csv,
one row per run, read back from the files.
"""
import argparse
import csv
import itertools
import pathlib
import sys
from dataclasses import dataclass

try:
    import tomllib
except ModuleNotFoundError:  # Python 3.10
    import tomli as tomllib

from movingbase.fmu_src.builder import ensure_built
from . import engine, flags, spec
from .fmi import unpack
from .runner import resolve

_TOP = ("name", "description", "scenario", "set", "grid", "cases", "ci", "keep_records")
SCENARIO_KEYS = ("start_time", "stop_time", "step", "master", "extrapolation")


class CampaignError(ValueError):
    """A problem in a campaign file; the message says file, key and problem."""

    def __init__(self, source, key, problem):
        super().__init__(f"{source}: {key}: {problem}")


@dataclass
class Case:
    label: str
    values: dict                    # key -> raw value, as written in the file


@dataclass
class Campaign:
    source: str
    name: str
    description: str
    scenario_path: pathlib.Path
    cases: list                     # every run, in file order
    varying: list                   # keys that differ between cases (summary columns)
    keep_records: bool = False


def _flat(value, prefix=""):
    """{'base': {'x': 1}} -> {'base.x': 1} (unquoted dotted TOML keys make nested tables)."""
    if not isinstance(value, dict):
        return {prefix: value}
    out = {}
    for key, item in value.items():
        out.update(_flat(item, f"{prefix}.{key}" if prefix else key))
    return out


def _table(source, key, value):
    if not isinstance(value, dict):
        raise CampaignError(source, key, f"expected a table, got {type(value).__name__}")
    return value


def _axes(source, grid):
    """[(where, [keys], [value tuples])] of the grid, each axis zipped over its keys."""
    if isinstance(grid, dict):      # [grid]: every key its own axis
        tables = [{k: v} for k, v in _flat(grid).items()]
    elif isinstance(grid, list):    # [[grid]]: each table one axis
        tables = grid
    else:
        raise CampaignError(source, "grid", "expected a table or an array of tables ([[grid]])")
    axes = []
    for i, table in enumerate(tables):
        where = f"grid[{i}]"
        table = _flat(_table(source, where, table))
        if not table:
            raise CampaignError(source, where, "an axis needs at least one key")
        lengths = set()
        for key, values in table.items():
            if not isinstance(values, list) or not values:
                raise CampaignError(source, f"{where}.{key}", "expected a non-empty list of values")
            lengths.add(len(values))
        if len(lengths) > 1:
            raise CampaignError(source, where, f"the keys of one axis vary together and need lists of one "
                                f"length; got lengths {', '.join(str(len(v)) for v in table.values())}")
        axes.append((where, list(table), list(zip(*table.values()))))
    return axes


def _label(value):
    return value if isinstance(value, str) else repr(value)


def parse(text, source="<string>", base_dir=".", ci=False):
    """Campaign from TOML text (``ci``: apply its [ci] replacements); the base scenario
    is loaded and every key and value checked against it and its FMUs."""
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise CampaignError(source, "TOML", str(exc)) from None
    unknown = set(data) - set(_TOP)
    if unknown:
        raise CampaignError(source, sorted(unknown)[0], f"unknown key; allowed: {', '.join(_TOP)}")
    if ci:
        data.update(_table(source, "ci", data.get("ci", {})))
    if "scenario" not in data or not isinstance(data["scenario"], str):
        raise CampaignError(source, "scenario", "missing: name a shipped scenario or a scenario file")
    path = resolve(data["scenario"])
    if not path.exists() and (pathlib.Path(base_dir) / data["scenario"]).exists():
        path = pathlib.Path(base_dir) / data["scenario"]
    if not path.exists():
        raise CampaignError(source, "scenario", f"{data['scenario']!r} is neither a shipped scenario nor a file")
    fixed = _flat(_table(source, "set", data.get("set", {})))
    axes = _axes(source, data.get("grid", []))
    raw_cases = data.get("cases", [{}])
    if not isinstance(raw_cases, list) or not raw_cases:
        raise CampaignError(source, "cases", "expected a non-empty array of tables ([[cases]])")
    cases = []
    for i, case in enumerate(raw_cases):
        case = _flat(_table(source, f"cases[{i}]", case))
        label = case.pop("label", None)
        if label is not None and not isinstance(label, str):
            raise CampaignError(source, f"cases[{i}].label", "expected a string")
        cases.append((f"cases[{i}]", label, case))

    try:
        base = spec.load(path)
    except spec.ScenarioError as exc:
        raise CampaignError(source, "scenario", str(exc)) from None
    sweep_key = base.sweep[0] if base.sweep else None
    named = set(fixed) | {k for _, keys, _ in axes for k in keys} | {k for _, _, c in cases for k in c}
    if sweep_key and sweep_key not in named:
        axes.append(("scenario sweep", [sweep_key], [(v,) for v in base.sweep[1]]))

    descriptions = _descriptions(base)
    checked = {}                    # (key, repr(value)) already checked

    def check(where, key, value):
        if (key, repr(value)) in checked:
            return
        checked[(key, repr(value))] = True
        if key in SCENARIO_KEYS:
            try:
                spec.load(path, overrides={key: value})
            except spec.ScenarioError as exc:
                raise CampaignError(source, where, str(exc).removeprefix(f"{path}: ")) from None
            return
        inst, _, name = key.partition(".")
        if not name or inst not in base.fmus:
            raise CampaignError(source, where, f"unknown key {key!r}: expected one of {', '.join(SCENARIO_KEYS)} "
                                f"or 'instance.parameter' with an instance of {path.name} "
                                f"({', '.join(base.fmus)})")
        variables = {v.name: v for v in descriptions[inst].modelVariables}
        targets = spec.expand(variables, key)
        if not targets or any(variables[t].causality not in ("parameter", "input") for t in targets):
            raise CampaignError(source, where, f"{inst} ({base.fmus[inst]}) has no parameter {name!r}")
        values = value if isinstance(value, list) else [value]
        if len(values) != len(targets):
            raise CampaignError(source, where, f"expected {len(targets)} values, got {len(values)}")
        for target, item in zip(targets, values):
            try:
                spec._value(source, where, variables[target], item)
            except spec.ScenarioError as exc:
                raise CampaignError(source, where, str(exc).removeprefix(f"{source}: {where}: ")) from None

    for key, value in fixed.items():
        check(f"set.{key}", key, value)
    for where, keys, rows in axes:
        for j, row in enumerate(rows):
            for key, value in zip(keys, row):
                check(f"{where}.{key}[{j}]" if where != "scenario sweep" else f"{path.name}: sweep.values[{j}]",
                      key, value)
    for where, _, case in cases:
        for key, value in case.items():
            check(f"{where}.{key}", key, value)

    runs, varying = [], []
    for where, label, case in cases:
        for combo in itertools.product(*[rows for _, _, rows in axes]):
            values = dict(fixed)
            values.update(case)
            parts = [label] if label else []
            for (_, keys, _), row in zip(axes, combo):
                values.update(zip(keys, row))
                parts.append(", ".join(f"{k}={_label(v)}" for k, v in zip(keys, row)))
            runs.append(Case("; ".join(parts) or "run", values))
    for key in dict.fromkeys(k for run in runs for k in run.values):
        if len({repr(run.values.get(key)) for run in runs}) > 1:
            varying.append(key)
    keep = data.get("keep_records", False)
    if not isinstance(keep, bool):
        raise CampaignError(source, "keep_records", "expected true or false")
    name = data.get("name", pathlib.Path(source).stem)
    return Campaign(source, name, data.get("description", ""), path, runs, varying, keep)


def _descriptions(scenario):
    """Model descriptions per instance (FMUs built if missing or stale)."""
    scripts = ensure_built(sorted({spec.FMU_SCRIPTS[f] for f in scenario.fmus.values()}))
    return {inst: unpack(scripts[spec.FMU_SCRIPTS[fmu]])[0] for inst, fmu in scenario.fmus.items()}


SHIPPED = pathlib.Path(__file__).resolve().parent / "campaigns"


def load(path, ci=False):
    """A campaign file, or the name of a shipped one (scenarios/campaigns/<name>.toml)."""
    path = pathlib.Path(path)
    if not path.exists() and path.suffix != ".toml" and (SHIPPED / f"{path}.toml").exists():
        path = SHIPPED / f"{path}.toml"
    if not path.is_file():
        raise CampaignError(str(path), "file", "does not exist" if not path.exists() else "is not a file")
    try:
        text = path.read_text()
    except UnicodeDecodeError:
        raise CampaignError(str(path), "file", "is not UTF-8 text (a TOML campaign file)") from None
    return parse(text, str(path), path.parent, ci)


class CampaignJobs:
    """The campaign's runs as engine Jobs, made as they are iterated (memory does not grow
    with the number of runs); the scenario is loaded and bound once per distinct set of
    top-level settings, the FMUs hashed once."""

    def __init__(self, campaign):
        self.campaign = campaign
        self._bound = {}            # top-level overrides -> (scenario, values, descriptions, digests)
        self.files = {}             # sha256 -> FMU path
        self._scripts = None
        self._bind({})              # the FMUs, built and hashed before anything runs

    def __len__(self):
        return len(self.campaign.cases)

    def _bind(self, top):
        marker = repr(sorted(top.items()))
        if marker not in self._bound:
            c = self.campaign
            scenario = spec.load(c.scenario_path, overrides=top)
            if any(p.get("fidelity") == "auto" for p in scenario.parameters.values()):
                raise CampaignError(c.source, "scenario", 'a plant fidelity "auto" is chosen per scenario '
                                    'run; a campaign names a fidelity level (set "plant.fidelity")')
            self._scripts = self._scripts or ensure_built(sorted({spec.FMU_SCRIPTS[f] for f in scenario.fmus.values()}))
            paths = {inst: self._scripts[spec.FMU_SCRIPTS[fmu]] for inst, fmu in scenario.fmus.items()}
            digests = {inst: engine.file_digest(p) for inst, p in paths.items()}
            self.files.update({digests[inst]: p for inst, p in paths.items()})
            descriptions = {inst: unpack(p)[0] for inst, p in paths.items()}
            self._bound[marker] = (scenario, spec.bind(scenario, descriptions), descriptions, digests)
        return self._bound[marker]

    def __iter__(self):
        for case in self.campaign.cases:
            scenario, values, descriptions, digests = self._bind(
                {k: v for k, v in case.values.items() if k in SCENARIO_KEYS})
            params = {inst: dict(v) for inst, v in values.items()}
            for key, raw in case.values.items():
                if key in SCENARIO_KEYS:
                    continue
                inst = key.split(".", 1)[0]
                variables = {v.name: v for v in descriptions[inst].modelVariables}
                for target, item in zip(spec.expand(variables, key), raw if isinstance(raw, list) else [raw]):
                    params[inst][target] = spec._value(self.campaign.source, key, variables[target], item)
            yield engine.Job(case.label, scenario, params, digests, self.campaign.keep_records)


def jobs(campaign):
    """(jobs, {sha256: FMU path}): a sized iterable of one engine Job per case."""
    made = CampaignJobs(campaign)
    return made, made.files


def results(campaign, store, job_list):
    """(case, record) per run from the store, in campaign order; record is None for a
    run not on disk."""
    for case, job in zip(campaign.cases, job_list):
        yield case, (store.read(job.key) if store.status(job.key) else None)


def write_summary(campaign, store, job_list, path):
    """summary.csv streamed from the result files: case values, status, flags (scenarios.flags:
    '' for a run nothing was seen wrong in), every metric."""
    with open(path, "w", newline="") as file:
        writer = None
        for case, record in results(campaign, store, job_list):
            row = {"label": case.label, **{k: case.values.get(k) for k in campaign.varying}}
            row["status"] = record["status"] if record else "not run"
            row["error"] = record.get("error", "") if record else ""
            row["flags"] = flags.summary(flags.from_dicts((record or {}).get("flags")))
            for name, values in ((record or {}).get("metrics") or {}).items():
                row.update({f"{name} {k}": v for k, v in values.items() if k != "unit"})
            row["run_time_s"] = (record or {}).get("run_time_s", "")
            if writer is None:
                writer = csv.DictWriter(file, list(row), extrasaction="ignore", restval="")
                writer.writeheader()
            writer.writerow(row)
    return path


def run_campaign(path, out="out", ci=False, jobs_=None, address=None, progress=True, retry_failed=False):
    """Check a campaign file, run what is not on disk yet, write the summary.
    Returns (campaign, job list, store, outcome, summary path)."""
    campaign = load(path, ci)
    job_list, files = jobs(campaign)
    outdir = pathlib.Path(out) / campaign.name
    store = engine.Store(outdir / "runs")
    with engine.Engine(jobs_, address) as eng:
        outcome = eng.run(job_list, files, store, progress, retry_failed, name=campaign.name)
    return campaign, job_list, store, outcome, write_summary(campaign, store, job_list, outdir / "summary.csv")


def main(argv=None):
    parser = argparse.ArgumentParser(prog="movingbase campaign", description=__doc__.splitlines()[0])
    parser.add_argument("campaign", help="campaign file (TOML)")
    parser.add_argument("--ci", action="store_true", help="apply the file's [ci] replacements (a small campaign)")
    parser.add_argument("--jobs", type=int, help="local worker processes (default: all cores)")
    parser.add_argument("--dask", metavar="ADDR", help="run on the Dask cluster whose scheduler is at ADDR")
    parser.add_argument("--out", default="out", help="output folder (default: out)")
    parser.add_argument("--retry-failed", action="store_true", help="run again the runs that failed before")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")
    args = parser.parse_args(argv)
    try:
        campaign, job_list, store, outcome, summary = run_campaign(
            args.campaign, args.out, args.ci, args.jobs, args.dask, not args.quiet, args.retry_failed)
    except (CampaignError, spec.ScenarioError) as exc:
        sys.exit(f"campaign error: {exc}")
    print(f"{campaign.name}: {len(outcome.computed)} runs done now, {len(outcome.skipped)} found on disk, "
          f"{len(outcome.failed)} failed, of {outcome.total}, in {outcome.wall_time:.1f} s; summary {summary}")
    labels = {job.key: job.label for job in job_list}
    for key, message in list(outcome.failed.items())[:10]:
        print(f"  failed: {labels[key]}: {message.splitlines()[0]}")
    if outcome.interrupted:
        sys.exit("interrupted: the runs finished so far are on disk; run the same command again to resume")
    if outcome.failed:
        sys.exit(1)


if __name__ == "__main__":
    main()
