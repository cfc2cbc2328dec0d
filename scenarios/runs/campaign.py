"""Campaign files: many runs of one base scenario over a grid or a list of cases, run
through scenarios.runs.engine (local worker processes or a Dask cluster), resumable.

    movingbase campaign FILE [--ci] [--jobs N] [--dask tls://HOST:PORT] [--out DIR]

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
    [sample]                           # optional: N sampled runs of every case (Monte Carlo)
    samples = 200
    seed = 2026
    seeds = ["sensor.seed"]            # FMU seed parameters each sample sets (its own noise)
    "plant.payload_mass_error" = { distribution = "normal", sd = "20 kg" }   # a deviation from the run's value
    [ci]                               # replaces name/set/grid/cases for the short CI run
                                       # (its sample = { samples = 4 } replaces only the keys it gives;
                                       # sample = 4 is the same)

A key is a scenario top-level setting (start_time, stop_time, step, master,
extrapolation) or "instance.parameter" of the base scenario (dotted keys may be written
unquoted). The base scenario's [sweep] is one more axis unless the campaign sets that
parameter. Every key and value is checked before anything runs; errors name the file,
the key and the problem, like scenario files.

Results: <out>/<campaign file stem>/runs/<key>.json|.npz (scenarios.runs.engine.Store) and summary.csv,
one row per run, read back from the files.
"""
import csv
import dataclasses
import difflib
import itertools
import json
import pathlib
import re
import sys
import zlib
from dataclasses import dataclass

import numpy as np

from fmu_src import atomic
from scenarios import spec
from scenarios.cosim.fmi import description
from scenarios.runs import engine, flags, status
from scenarios.runs import estimates as resources
from scenarios.runs.runner import OutputError, _named, fmu_paths, output_folder, resolve
from scenarios.spec import distributions, units

_TOP = ("name", "description", "scenario", "set", "grid", "cases", "sample", "ci", "keep_records")
_CI = ("name", "description", "set", "grid", "cases", "sample", "keep_records")     # what [ci] may replace
_SAMPLE = ("samples", "seed", "seeds")      # [sample]'s own keys; the others are uncertain inputs
SCENARIO_KEYS = ("start_time", "stop_time", "step", "master", "extrapolation")


class CampaignError(spec.ScenarioError):
    """Problems in a campaign file; the message says file, key and problem, one line each."""


MAX_RUNS = 200_000              # a campaign of more runs is refused before its cases are made
# A sample whose draws give a body no model may have (plant.hexapod.model.body_problems: a
# payload's moments against the triangle inequalities) is drawn again, up to this many times:
# rejection keeps each input's distribution as written, conditioned on an admissible body.
MAX_REDRAWS = 100


@dataclass
class Case:
    label: str
    values: dict                    # key -> raw value, as written in the file
    sample: int | None = None       # its index in [sample], if sampled


@dataclass(frozen=True)
class Sample:
    """[sample]: ``samples`` draws from ``seed``; ``inputs``: (key, instance, variable, unit,
    Distribution) per scalar (a vector key is one input per element, drawn apart);
    ``seeds``: (key, instance, variable) of the FMU seed parameters each sample sets."""

    samples: int
    seed: int
    inputs: tuple
    seeds: tuple

    def stream(self, k, key, attempt=0):
        """The generator of sample ``k``'s draw for ``key``: SeedSequence(seed, spawn_key=(k,
        crc32(key))), so a draw depends on (seed, k, the input's name) alone: sample k
        re-runs alone, and adding or reordering inputs leaves the others' draws as they were.
        A redraw (``attempt`` > 0, see ``draws``) appends the attempt to the spawn key."""
        return np.random.Generator(np.random.PCG64(np.random.SeedSequence(
            self.seed, spawn_key=(k, zlib.crc32(key.encode())) + ((attempt,) if attempt else ()))))

    def draws(self, k, attempt=0):
        """({key: deviation [SI]}, {key: FMU seed}) of sample ``k``: u in (0, 1) (53-bit,
        never 0 or 1, so a normal's ppf stays finite) through each Distribution's ppf.
        ``attempt``: the redraw of a sample whose draws gave a body no model may have (every
        input drawn anew, so the samples follow the distributions as written, conditioned on
        an admissible body; the seeds stay those of attempt 0)."""
        deviations = {}
        for key, _, _, _, dist in self.inputs:
            u = (float(self.stream(k, key, attempt).integers(1 << 53)) + 0.5) / (1 << 53)
            deviations[key] = float(dist.ppf(u))
        return deviations, {key: int(self.stream(k, key).integers(1, 2 ** 31 - 1)) for key, _, _ in self.seeds}


@dataclass
class Campaign:
    source: str
    name: str
    description: str
    scenario_path: pathlib.Path
    cases: list                     # every run, in file order
    varying: list                   # keys that differ between cases (summary columns)
    keep_records: bool = False
    ci: bool = False                # its [ci] version: runs cut short on purpose (no motion_unfinished)
    sample: Sample | None = None    # [sample], if any


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


def _is_quantity(value):
    try:
        units.to_si(value, "s")
        return True
    except units.UnitError:
        return False


def _near(name, names):
    """"; did you mean 'lever_arm'?" for a mistyped parameter (vectors by their name), or ''."""
    near = difflib.get_close_matches(name, list(dict.fromkeys(n.split("[", 1)[0] for n in names)), 1, 0.6)
    return f"; did you mean {near[0]!r}?" if near else ""


def _label(value):
    return value if isinstance(value, str) else repr(value)


def parse(text, source="<string>", base_dir=".", ci=False):
    """Campaign from TOML text (``ci``: apply its [ci] replacements); the base scenario
    is loaded and every key and value checked against it and its FMUs."""
    data = spec.read_toml(text, source, CampaignError)
    if "fmus" in data and "scenario" not in data:    # not a wall of unknown keys: the other kind of file
        raise CampaignError(source, "file", "this is a scenario file (it has [fmus] and names no scenario), not "
                                            "a campaign: run it with `movingbase run FILE` (movingbase.run)")
    problems = spec.Problems(CampaignError)
    for key, problem in spec.unknown_keys(set(data) - set(_TOP), _TOP):
        problems.errors.append(CampaignError(source, key, problem))
    ci_table = data.get("ci", {})
    if not isinstance(ci_table, dict):
        problems.errors.append(CampaignError(source, "ci", "expected a table of the keys it replaces"))
    else:
        for key, problem in spec.unknown_keys(set(ci_table) - set(_CI), _CI):
            problems.errors.append(CampaignError(source, f"ci.{key}", problem))
        for key, kinds, shape in (("set", dict, "a table"), ("grid", (dict, list), "a table or [[ci.grid]] tables"),
                                  ("cases", list, "an array of tables ([[ci.cases]])")):
            if key in ci_table and not isinstance(ci_table[key], kinds):
                problems.errors.append(CampaignError(source, f"ci.{key}", f"expected {shape}, got "
                                                     f"{ci_table[key]!r:.60}"))
        if "sample" in ci_table:    # a count alone is the samples it replaces: sample = 4
            ci_sample = ci_table["sample"]
            if isinstance(ci_sample, int) and not isinstance(ci_sample, bool):
                ci_table = {**ci_table, "sample": {"samples": ci_sample}}
            elif not isinstance(ci_sample, dict):
                problems.errors.append(CampaignError(source, "ci.sample", "expected a table of the [sample] keys "
                                                     "it replaces, or a count: sample = { samples = 4 } or "
                                                     f"sample = 4; got {ci_sample!r:.60}"))
    if "sample" in data and not isinstance(data["sample"], dict):
        problems.errors.append(CampaignError(source, "sample", f"expected a table ([sample]), got "
                                             f"{data['sample']!r:.60}"))
    for key in ("description", "name"):
        if key in data and not isinstance(data[key], str):
            problems.errors.append(CampaignError(source, key, f"expected text, got {data[key]!r:.60}"))
    problems.raise_any()
    if ci:
        sampled = {**data.get("sample", {}), **ci_table.get("sample", {})} if "sample" in ci_table else None
        data.update(ci_table)
        if sampled is not None:
            data["sample"] = sampled
    if "scenario" not in data or not isinstance(data["scenario"], str):
        raise CampaignError(source, "scenario", "missing: name a shipped scenario or a scenario file")
    name = spec.check_name(source, "name", data["name"], CampaignError) if "name" in data else \
        pathlib.Path(source).stem       # the file's own name needs no check: it is one
    beside = resolve(pathlib.Path(base_dir) / data["scenario"])   # relative to this file first: a file of that
    path = beside if beside.is_file() else resolve(data["scenario"])   # name in the current folder was taken
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

    where_set = {}                  # key -> where the campaign sets it; a key is set in one place
    for where, keys in [("set", list(fixed)), *[(w, k) for w, k, _ in axes]]:
        for key in keys:
            if key in where_set:
                raise CampaignError(source, f"{where}.{key}", f"also set in {where_set[key]}: one value would "
                                    "silently replace the other (the run labels would name values that did not run)")
            where_set[key] = where
    for where, _, case in cases:
        for key in case:
            if key in where_set:
                raise CampaignError(source, f"{where}.{key}", f"also set in {where_set[key]}, which would replace "
                                    "this case's value in every run")
    count = len(cases) * (data["sample"].get("samples", 1) if isinstance(data.get("sample"), dict) and
                          isinstance(data["sample"].get("samples"), int) else 1)
    for _, _, rows in axes:
        count *= len(rows)
    if count > MAX_RUNS:
        raise CampaignError(source, "grid", f"{count:,} runs (cases x the axes' lengths); a campaign holds at most "
                            f"{MAX_RUNS:,}: split it or coarsen the grid")

    try:
        base = spec.load(path)
    except spec.ScenarioError as exc:
        raise CampaignError(source, "scenario", str(exc)) from None
    sweep_key = base.sweep[0] if base.sweep else None
    named = set(fixed) | {k for _, keys, _ in axes for k in keys} | {k for _, _, c in cases for k in c}
    written = [*fixed.items(), *[(k, v) for _, keys, rows in axes for row in rows for k, v in zip(keys, row)],
               *[(k, v) for _, _, c in cases for k, v in c.items()]]
    steps = [base.step] + [units.to_si(v, "s") for k, v in written if k == "step" and _is_quantity(v)]
    connected = {(t.split(".", 1)[0], t.split(".", 1)[1]) for _, targets in base.connections for t in targets}
    if sweep_key and sweep_key not in named:
        axes.append(("scenario sweep", [sweep_key], [(v,) for v in base.sweep[1]]))

    descriptions = _descriptions(base)
    fixed_top = {k: v for k, v in fixed.items() if k in SCENARIO_KEYS}
    checked = {}                    # (key, repr(value)) -> the value converted, once checked

    def check(where, key, value):
        if (key, repr(value)) not in checked:
            checked[(key, repr(value))] = converted(where, key, value)

    def converted(where, key, value):
        if key in SCENARIO_KEYS:
            try:
                spec.load(path, overrides={**fixed_top, key: value})   # with set's start_time, stop_time, ...
            except spec.ScenarioError as exc:
                raise CampaignError(source, where, str(exc).removeprefix(f"{path}: ")) from None
            return units.to_si(value, "s") if _is_quantity(value) else value
        if isinstance(value, str) and value.startswith("@"):
            raise CampaignError(source, where, f"{value!r}: a link to another FMU's output at the start time is "
                                f"written in the scenario file ({path.name}); a campaign sets values")
        inst, _, name = key.partition(".")
        if not name or inst not in base.fmus:
            raise CampaignError(source, where, f"unknown key {key!r}: expected one of {', '.join(SCENARIO_KEYS)} "
                                f"or 'instance.parameter' with an instance of {path.name} "
                                f"({', '.join(base.fmus)})")
        variables = {v.name: v for v in descriptions[inst].modelVariables}
        targets = spec.expand(variables, key)
        if not targets or any(variables[t].causality not in ("parameter", "input") for t in targets):
            raise CampaignError(source, where, f"{inst} ({base.fmus[inst]}) has no parameter {name!r}"
                                + _near(name, [v for v, var in variables.items() if var.causality == "parameter"]))
        if (inst, name) in connected or any((inst, t) in connected for t in targets):
            raise CampaignError(source, where, f"{key} is an input that {path.name} connects: the connection "
                                "feeds it in every run, a value set here would be ignored")
        values = spec.plain(value) if isinstance(value, list) else [value]
        if len(values) != len(targets):
            raise CampaignError(source, where, f"expected {len(targets)} values, got {len(values)}")
        out = []
        for target, item in zip(targets, values):
            try:
                out.append(spec._value(source, where, variables[target], item))
            except spec.ScenarioError as exc:
                raise CampaignError(source, where, str(exc).removeprefix(f"{source}: {where}: ")) from None
            try:            # the largest step of the campaign: a cut-off must lie below each run's Nyquist
                spec.check_rates(source, where, dataclasses.replace(base, step=max(steps)),
                                 {inst: {target: variables[target]}}, {inst: {target: out[-1]}})
            except spec.ScenarioError as exc:
                raise CampaignError(source, where, str(exc).removeprefix(f"{source}: {where}: ")) from None
        return tuple(out)

    every = [(f"set.{key}", key, value) for key, value in fixed.items()]
    every += [(f"{where}.{key}[{j}]" if where != "scenario sweep" else f"{path.name}: sweep.values[{j}]", key, value)
              for where, keys, rows in axes for j, row in enumerate(rows) for key, value in zip(keys, row)]
    every += [(f"{where}.{key}", key, value) for where, _, case in cases for key, value in case.items()]
    problems = spec.Problems(CampaignError)      # every bad value of the file, told at once
    for where, key, value in every:
        with problems.part():
            check(where, key, value)
    problems.raise_any()
    for where, keys, rows in axes:   # one run per value: "1 m" and "1000 mm" are one value
        if where == "scenario sweep":
            continue                 # the scenario checks its own
        seen = {}
        for j, row in enumerate(rows):
            same = seen.setdefault(tuple(checked[(k, repr(v))] for k, v in zip(keys, row)), j)
            if same != j:
                shown = ", ".join(f"{k} = {v!r}" for k, v in zip(keys, rows[same]))
                problems.errors.append(CampaignError(
                    source, f"{where}.{keys[0]}[{j}]" if len(keys) == 1 else f"{where}[{j}]",
                    f"{', '.join(f'{v!r}' for v in row)} is already value [{same}] of this axis ({shown}): "
                    "each runs once"))
    problems.raise_any()

    sample = _sample(source, data["sample"], base, descriptions) if "sample" in data else None
    if sample:
        _check_seeds(source, sample, every, descriptions)
    runs, varying = [], []
    for where, label, case in cases:
        for combo in itertools.product(*[rows for _, _, rows in axes]):
            values = dict(fixed)
            values.update(case)
            parts = [label] if label else []
            for (_, keys, _), row in zip(axes, combo):
                values.update(zip(keys, row))
                parts.append(", ".join(f"{k}={_label(v)}" for k, v in zip(keys, row)))
            if sample is None:
                runs.append(Case("; ".join(parts) or "run", values))
            for k in range(sample.samples if sample else 0):    # every case with the same draws
                runs.append(Case("; ".join([*parts, f"sample {k}"]), values, k))
    labels = {}
    for i, run in enumerate(runs):   # a label names one run (the table's rows, CampaignResult.series)
        j = labels.setdefault(run.label, i)
        if j != i:
            first, this = cases[j // (len(runs) // len(cases))], cases[i // (len(runs) // len(cases))]
            raise CampaignError(source, f"{this[0]}.label" if this[1] else this[0],
                                f"its runs would have the labels of {first[0]}'s ({run.label!r}): "
                                "give each case its own label")
    for key in dict.fromkeys(k for run in runs for k in run.values):
        if len({repr(run.values.get(key)) for run in runs}) > 1:
            varying.append(key)
    keep = data.get("keep_records", False)
    if not isinstance(keep, bool):
        raise CampaignError(source, "keep_records", "expected true or false")
    return Campaign(source, name, data.get("description", ""), path, runs, varying, keep, ci, sample)


def _inputs(table, prefix=""):
    """[sample]'s uncertain inputs flattened to 'inst.name' keys, stopping at a table that
    names a distribution (unquoted dotted keys make nested tables)."""
    out = {}
    for key, value in table.items():
        name = f"{prefix}.{key}" if prefix else key
        if isinstance(value, dict) and "distribution" not in value and (prefix or key not in _SAMPLE):
            out.update(_inputs(value, name))
        else:
            out[name] = value
    return out


def _sample(source, table, base, descriptions):
    """The checked [sample] table: every problem of it told at once."""
    table = _inputs(_table(source, "sample", table))
    problems = spec.Problems(CampaignError)
    samples, seed = table.pop("samples", None), table.pop("seed", None)
    for key, value, low in (("samples", samples, 1), ("seed", seed, 0)):
        if isinstance(value, bool) or not isinstance(value, int) or value < low:
            problems.errors.append(CampaignError(source, f"sample.{key}", f"expected an integer >= {low}, got "
                                                 f"{value!r}"))
    seed_keys = table.pop("seeds", [])
    if not isinstance(seed_keys, list) or not all(isinstance(k, str) for k in seed_keys):
        problems.errors.append(CampaignError(source, "sample.seeds", "expected a list of 'instance.seed' keys"))
        seed_keys = []
    if not table:
        problems.errors.append(CampaignError(source, "sample", 'names no uncertain input: add e.g. '
                                             '"plant.payload_mass_error" = { distribution = "normal", sd = "20 kg" }'))

    def variables(where, key):
        inst, _, name = key.partition(".")
        if not name or inst not in base.fmus:
            raise CampaignError(source, where, f"unknown key {key!r}: expected 'instance.parameter' with an "
                                f"instance of {base.source} ({', '.join(base.fmus)})")
        found = {v.name: v for v in descriptions[inst].modelVariables}
        targets = spec.expand(found, key)
        if not targets:
            raise CampaignError(source, where, f"{inst} ({base.fmus[inst]}) has no parameter {name!r}"
                                + _near(name, [v for v, var in found.items() if var.causality == "parameter"]))
        if any(found[t].causality != "parameter" for t in targets):
            raise CampaignError(source, where, f"{key} is an {found[targets[0]].causality}, not a parameter: a sample "
                                "draws the deviations of parameters")
        return inst, [found[t] for t in targets]

    inputs, seeds = [], []
    for key, value in table.items():
        with problems.part():
            inst, found = variables(f"sample.{key}", key)
            if any(v.type != "Real" for v in found):
                raise CampaignError(source, f"sample.{key}", "a deviation is drawn for a real parameter; "
                                    f"{key} is {found[0].type.lower()}: set it in the grid or cases")
            dist = distributions.parse(source, f"sample.{key}", value, found[0].unit or "1", CampaignError)
            twice = [v.name for v in found if any((i, n) == (inst, v.name) for _, i, n, _, _ in inputs)]
            if twice:       # "imu.imu_alignment" and "imu.imu_alignment[1]": two draws added to one value
                raise CampaignError(source, f"sample.{key}", f"{inst}.{twice[0]} is drawn by an earlier key of "
                                    "[sample] too: each parameter gets one distribution")
            inputs += [(f"{inst}.{v.name}" if len(found) > 1 else key, inst, v.name,
                        "" if v.unit in (None, "1") else v.unit, dist)
                       for v in found]
    for j, key in enumerate(seed_keys):
        with problems.part():
            inst, found = variables(f"sample.seeds[{j}]", key)
            if len(found) != 1 or found[0].type != "Integer":
                raise CampaignError(source, f"sample.seeds[{j}]", f"{key} is not an integer seed parameter")
            if any((i, n) == (inst, found[0].name) for _, i, n in seeds):
                raise CampaignError(source, f"sample.seeds[{j}]", f"{key} is listed twice")
            seeds.append((key, inst, found[0].name))
    problems.raise_any()
    return Sample(samples, seed, tuple(inputs), tuple(seeds))


def _check_seeds(source, sample, every, descriptions):
    """A seed a sample sets must be set nowhere else: each sample's own seed would replace
    the value of the set, grid, cases or sweep in every run (six labelled runs that are three)."""
    written = {}                    # (instance, scalar) -> where the campaign (or its scenario's sweep) sets it
    for where, key, _ in every:
        inst, _, name = key.partition(".")
        if name and inst in descriptions:
            variables = {v.name: v for v in descriptions[inst].modelVariables}
            for target in spec.expand(variables, key):
                written.setdefault((inst, target), re.sub(r"\[\d+\]$", "", where) if where.startswith("grid")
                                  or "sweep" in where else where)   # an axis, not one of its values
    problems = spec.Problems(CampaignError)
    for j, (key, inst, name) in enumerate(sample.seeds):
        if (inst, name) in written:
            problems.errors.append(CampaignError(source, f"sample.seeds[{j}]", f"{key} is also set in "
                                   f"{written[inst, name]}: each sample sets its own seed, which would replace "
                                   "that value in every run (runs labelled apart would run alike); sample it "
                                   "or set it, not both"))
    problems.raise_any()


def _descriptions(scenario):
    """Model descriptions per instance, of the implementation and FMI version the scenario
    chose (FMUs built if missing or stale; an FMI 3 FMU's arrays as elements, fmi.description)."""
    return {inst: description(p) for inst, p in fmu_paths(scenario).items()}


SHIPPED = pathlib.Path(__file__).resolve().parents[1] / "campaigns"


def load(path, ci=False):
    """A campaign file, or the name of a shipped one (scenarios/campaigns/<name>.toml)."""
    path = spec.text.shipped_file(path, SHIPPED, CampaignError, "campaign")
    return parse(spec.read_text(path, CampaignError, "campaign"), str(path), path.parent, ci)


class CampaignJobs:
    """The campaign's runs as engine Jobs, made as they are iterated (memory does not grow
    with the number of runs); the scenario is loaded and bound once per distinct set of
    top-level settings, the FMUs hashed once."""

    def __init__(self, campaign):
        self.campaign = campaign
        self._bound = {}            # top-level overrides -> (scenario, values, descriptions, digests)
        self.files = {}             # sha256 -> FMU path
        self.flags = {}             # run label -> the flags of its motion (check), each run gets its own
        self.redrawn = {}           # run label -> its draws' attempt (0: as first drawn; > 0: drawn again)
        self.base = self._bind({})[0]   # the FMUs, built and hashed before anything runs

    def __len__(self):
        return len(self.campaign.cases)

    def _bind(self, top):
        marker = repr(sorted(top.items()))
        if marker not in self._bound:
            c = self.campaign
            try:
                scenario = spec.load(c.scenario_path, overrides=top)
                if any(p.get("fidelity") == "auto" for p in scenario.parameters.values()):
                    raise CampaignError(c.source, "scenario", 'a plant fidelity "auto" is chosen per scenario '
                                        'run; a campaign names a fidelity level (set "plant.fidelity")')
                paths = fmu_paths(scenario)     # each instance's implementation, as the scenario says
                digests = {inst: engine.file_digest(p) for inst, p in paths.items()}
                self.files.update({digests[inst]: p for inst, p in paths.items()})
                descriptions = {inst: description(p) for inst, p in paths.items()}
                self._bound[marker] = (scenario, spec.bind(scenario, descriptions), descriptions, digests)
            except CampaignError:
                raise
            except spec.ScenarioError as exc:    # the settings of some runs together, told as the campaign's
                where = ", ".join(f"{k} = {v!r}" for k, v in sorted(top.items()))
                raise CampaignError(c.source, f"runs of {where}" if top else "scenario", str(exc)) from None
        return self._bound[marker]

    def _case(self, case):
        """(scenario, bound parameters, descriptions, digests) of one case."""
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
        if case.sample is not None:
            sample = self.campaign.sample
            nominal = {inst: dict(p) for inst, p in params.items()}
            for attempt in range(MAX_REDRAWS + 1):
                params = self._drawn(case.sample, attempt, nominal, descriptions, scenario)
                inadmissible = {inst: found for inst, fmu in scenario.fmus.items() if fmu == "hexapod_plant"
                                for found in [spec.payload_problems({v.name: v for v in
                                                                     descriptions[inst].modelVariables},
                                                                    params[inst])] if found}
                if not inadmissible:
                    self.redrawn[case.label] = attempt   # per run: a grid's cases differ in value
                    break
            else:
                told = "; ".join(p for found in inadmissible.values() for p in found)
                raise CampaignError(self.campaign.source, "sample", f"sample {case.sample}: {MAX_REDRAWS + 1} draws "
                                    f"in a row gave a body no model may have ({told}): the distributions allow "
                                    "mostly impossible bodies; narrow them")
            _, seeds = sample.draws(case.sample)
            for key, inst, name in sample.seeds:
                params[inst][name] = seeds[key]
        return scenario, params, descriptions, digests

    def draws(self, case):
        """(deviations, seeds) of a sampled case as it runs: its admissible attempt's draws."""
        if case.label not in self.redrawn:
            self._case(case)
        deviations, _ = self.campaign.sample.draws(case.sample, self.redrawn[case.label])
        return deviations, self.campaign.sample.draws(case.sample)[1]

    def _drawn(self, k, attempt, nominal, descriptions, scenario):
        """The parameters of sample ``k`` (its ``attempt``-th draw): each input's value in the
        run (``nominal``, the scene's or the campaign's; unset: the FMU's start) plus the draw,
        checked against the FMU's range."""
        sample = self.campaign.sample
        params = {inst: dict(p) for inst, p in nominal.items()}
        deviations, _ = sample.draws(k, attempt)
        for key, inst, name, _, _ in sample.inputs:
            variable = next(v for v in descriptions[inst].modelVariables if v.name == name)
            if isinstance(nominal[inst].get(name), spec.Link):   # known only as the run starts
                link = nominal[inst][name]
                raise CampaignError(self.campaign.source, f"sample.{key}", f"{inst}.{name} is linked in "
                                    f"{pathlib.Path(scenario.source).name} to '@{link.instance}."
                                    f"{link.variable}' (that output at the start time): a deviation is "
                                    "drawn around a value, so set one for it in the campaign's set (or "
                                    "grid) to sample around it")
            value = float(nominal[inst].get(name, variable.start)) + deviations[key]
            try:
                params[inst][name] = spec._value(self.campaign.source, key, variable, value)
            except spec.ScenarioError as exc:
                raise CampaignError(self.campaign.source, f"sample {k}: {key}", f"the draw "
                                    f"{deviations[key]:.6g} {variable.unit or ''} gives {exc.problems[0][2]}"
                                    ) from None
        return params

    def cost(self):
        """What the runs will cost (resources.estimate), each at its own top-level settings
        (a campaign's set.stop_time, a grid of steps), with the recorded vectors' sizes."""
        counts = {}                 # top-level overrides -> (them, runs)
        for case in self.campaign.cases:
            top = {k: v for k, v in case.values.items() if k in SCENARIO_KEYS}
            marker = repr(sorted(top.items()))
            counts[marker] = (top, counts.get(marker, (None, 0))[1] + 1)
        estimates = []
        for top, runs in counts.values():
            scenario, _, descriptions, _ = self._bind(top)
            estimates.append(resources.estimate(scenario, descriptions, runs, self.campaign.keep_records))
        return resources.combined(estimates)

    def __iter__(self):
        for case in self.campaign.cases:
            scenario, params, _, digests = self._case(case)
            yield engine.Job(case.label, scenario, params, digests, self.campaign.keep_records,
                             self.flags.get(case.label, ()))

    def check(self):
        """Each run's settings together, as a scenario file's are checked before it runs:
        what the models refuse (the telescope's profile over the run; once per distinct
        run; the flags of its motion are kept for its Job: a slew unfinished at the stop
        time) and a step beyond the predicted stability limit (a campaign runs no step
        beyond it; predicted for every run at its own values, each distinct loop once:
        its gains, plant, sensor, motion, time grid, master and extrapolation). Every
        refused run is told, with its limit."""
        source, refused, seen, predicted, motion = self.campaign.source, {}, {}, {}, {}   # refused: problem -> labels
        for case in self.campaign.cases:
            scenario, params, descriptions, digests = self._case(case)
            paths = {inst: self.files[digest] for inst, digest in digests.items()}
            grid = repr((scenario.start_time, scenario.stop_time, scenario.step, scenario.master,
                         scenario.extrapolation))
            marker = repr((grid, sorted((i, sorted(p.items())) for i, p in params.items())))
            if marker not in seen:
                variables = {inst: {v.name: v for v in d.modelVariables} for inst, d in descriptions.items()}
                written = {tuple(k.split(".", 1)): v for k, v in case.values.items() if k not in SCENARIO_KEYS}
                try:
                    spec.check_models(source, "run", scenario, variables, params, written)
                    seen[marker] = ""
                    motion[marker] = () if self.campaign.ci else tuple(
                        flags.motion_flags(scenario, paths, descriptions, params, predicted))
                except spec.ScenarioError as exc:
                    seen[marker] = "; ".join(p for _, _, p in exc.problems)
            if seen[marker]:            # the model refuses it: no motion to predict along
                refused.setdefault(seen[marker], []).append(case.label)
                continue
            self.flags[case.label] = motion[marker]
            try:
                flags.check(scenario, flags.predict(scenario, paths, descriptions, params, cache=predicted))
            except spec.ScenarioError as exc:    # said of the scenario's step
                problem = "; ".join(f"{k}: {p.split('; or run it anyway')[0]}" for _, k, p in exc.problems)
                refused.setdefault(problem, []).append(case.label)
        if refused:
            raise CampaignError.joined([CampaignError(source, f"run {labels[0]!r}" + (
                f" (and {len(labels) - 1} more: "
                f"{', '.join(map(repr, labels[1:4]))}{', ...' if len(labels) > 4 else ''})"
                if len(labels) > 1 else ""), problem) for problem, labels in refused.items()])


def jobs(campaign):
    """(jobs, {sha256: FMU path}): a sized iterable of one engine Job per case, every run's
    settings checked (CampaignJobs.check)."""
    made = CampaignJobs(campaign)
    made.check()
    return made, made.files


def results(campaign, store, job_list):
    """(case, record) per run from the store, in campaign order; record is None for a
    run not on disk."""
    for case, job in zip(campaign.cases, job_list):
        yield case, (store.read(job.key) if store.status(job.key) else None)


def write_summary(campaign, store, job_list, path):
    """summary.csv streamed from the result files: case values, status, flags (scenarios.runs.flags:
    '' for a run nothing was seen wrong in), every metric."""
    with atomic.replacing(path, text=True, newline="") as file:
        writer = None
        for case, record in results(campaign, store, job_list):
            row = {"label": case.label, **{k: case.values.get(k) for k in campaign.varying}}
            if campaign.sample:         # its draws (redrawn if need be): each input's deviation [SI], its seeds
                deviations, seeds = job_list.draws(case)
                row["sample"] = case.sample
                row.update({f"{key} [{unit}]" if unit else key: repr(deviations[key])
                            for key, _, _, unit, _ in campaign.sample.inputs})
                row.update(seeds)
            row["status"] = status.of_record(record)    # the vocabulary's: flagged, not the store's "ok"
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


def summary_statuses(path):
    """{run label: status} from a summary.csv (write_summary)."""
    with open(path, newline="", encoding="utf-8") as file:
        return {row["label"]: row["status"] for row in csv.DictReader(file)}


def rerun_sample(path, k, out="out", ci=False):
    """Sample ``k`` of a campaign file alone, in this process (scenarios.runs.engine.execute,
    the workers' own call): [(job, result, stored)] per case, ``stored`` the campaign's
    result of that run if on disk under ``out`` (else None), and ``same`` in the result:
    its metrics and metric series equal the stored ones bit for bit, or ``damaged``: what is
    wrong with the stored files (engine.Store.status). Writes nothing; OutputError if ``out``
    is no folder (before anything runs)."""
    campaign = load(path, ci)
    out = pathlib.Path(_named(out))
    if out.exists() and not out.is_dir():
        raise OutputError(f"output folder {spec.shown(out)}: a file, not a folder; --sample compares with the "
                          "results the campaign wrote under its --out folder")
    if campaign.sample is None:
        raise CampaignError(campaign.source, "sample", "this campaign has no [sample] table: --sample needs one")
    if not isinstance(k, int) or not 0 <= k < campaign.sample.samples:
        raise CampaignError(campaign.source, "sample", f"--sample {k}: the campaign has samples 0.."
                            f"{campaign.sample.samples - 1}")
    campaign = dataclasses.replace(campaign, cases=[c for c in campaign.cases if c.sample == k])
    job_list, files = jobs(campaign)
    blobs = {digest: pathlib.Path(p).read_bytes() for digest, p in files.items()}
    folder = out / pathlib.Path(campaign.source).stem / "runs"
    store = engine.Store(folder) if folder.is_dir() else None
    done = []
    for job in job_list:
        result = engine.execute(job, blobs)
        stored = store.read(job.key) if store and store.status(job.key) else None
        if store and job.key in store.damaged:
            result["damaged"] = store.damaged[job.key]
        if stored is not None:
            series = store.series(job.key)
            result["same"] = stored["metrics"] == json.loads(json.dumps(result["metrics"], default=float)) and all(
                np.array_equal(series[n][0], t) and np.array_equal(series[n][1], v)
                for n, (t, v) in result["series"].items())
        done.append((job, result, stored))
    return done


def run_campaign(path, out="out", ci=False, jobs_=None, address=None, progress=True, retry_failed=False):
    """Check a campaign file, run what is not on disk yet, write the summary.
    Returns (campaign, job list, store, outcome, summary path)."""
    campaign = load(path, ci)
    job_list, files = jobs(campaign)
    cost = job_list.cost()
    warning = resources.check(cost, out, campaign.source)
    if warning:
        print(warning, file=sys.stderr)
    outdir = output_folder(out, campaign.source)
    if (outdir / "summary.csv").exists():
        print(f"{outdir / 'summary.csv'} from an earlier run is replaced; the results in {outdir / 'runs'} are "
              "reused where a run's key matches", file=sys.stderr)
    store = engine.Store(outdir / "runs")
    with engine.Engine(jobs_, address) as eng:
        outcome = eng.run(job_list, files, store, progress, retry_failed, name=campaign.name)
    return campaign, job_list, store, outcome, write_summary(campaign, store, job_list, outdir / "summary.csv")
