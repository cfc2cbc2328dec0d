"""The kit's Python API, for notebooks and scripts: ``movingbase.run`` and
``movingbase.campaign`` return result objects holding the recorded time series (numpy
arrays with units, or pandas DataFrames), the metrics, the flags of runs that went wrong,
the report's charts as matplotlib figures and the report itself. Modelled on FMPy's
``simulate_fmu`` (a scenario in, arrays out, nothing on disk unless asked) and on
python-control's response objects (``.to_pandas()``, ``.plot()``; pandas optional).

    >>> import movingbase
    >>> result = movingbase.run("telescope_slew", ci=True, set={"base.start_elevation": "60 deg"})
    >>> result.metrics["moving_base"]["leg error"]["rms"]      # µm
    >>> result["moving_base"]["plant.pose"]                    # (rows, 6) array, SI units
    >>> result.to_pandas()                                     # every run's series, by run and time

The runs are those of the command line (``movingbase run``): the same checks, the same
FMUs and master, the same numbers bit for bit; ``out=`` writes the same files.
"""
from __future__ import annotations

import base64
import copy
import dataclasses
import difflib
import functools
import html
import io
import os
import pathlib
import re
import sys
import textwrap
import time
import types
import warnings
from collections.abc import Iterator, Mapping, Sequence
from typing import TYPE_CHECKING, Any, Union

import numpy as np

from fmu_src import catalogue
from scenarios import spec
from scenarios.cosim import master
from scenarios.cosim.records import Records, read_records, run_records
from scenarios.output import budget_report, report
from scenarios.runs import campaign as campaigns
from scenarios.runs import engine, runner
from scenarios.runs import estimates as resources
from scenarios.runs import flags as run_flags
from scenarios.runs import status as run_status
from scenarios.runs.flags import Flag
from scenarios.runs.metrics import key_unit
from scenarios.spec import units
from scenarios.spec.units import UnitError, split

if TYPE_CHECKING:   # pandas and matplotlib are imported where they are used
    import pandas
    from matplotlib.figure import Figure

ScenarioLike = Union[str, "os.PathLike[str]", spec.Scenario]


def _public(function: Any) -> Any:
    """A refusal (ScenarioError) raised from the public call itself: a notebook shows the
    call and the message (file, key, problem), not 30-60 lines of the checks it passed
    through. Any other error keeps its whole traceback: that one is the kit's to fix."""
    @functools.wraps(function)
    def public(*args: Any, **kwargs: Any) -> Any:
        try:
            return function(*args, **kwargs)
        except spec.ScenarioError as exc:
            raise exc.with_traceback(None) from None
    return public


def _pandas() -> Any:
    try:
        import pandas
    except ModuleNotFoundError:
        raise ModuleNotFoundError("tables (metrics_table, to_pandas, CampaignResult.table) need pandas, a "
                                  "dependency of movingbase that is missing here: pip install pandas (or the "
                                  "arrays: .time, .values, .names, .units)") from None
    return pandas


# ------------------------------------------------------------------------ loading
def _flags_given(**given: Any) -> None:
    """Each of ``given`` is True or False (numpy's too), as a command-line switch is: a
    string such as "false" or "no" would be taken as true and run what was not asked for."""
    for name, value in given.items():
        if not isinstance(value, (bool, np.bool_)):
            raise TypeError(f"{name} must be True or False, got {type(value).__name__} {value!r:.60}")


@_public
def load_scenario(scenario: ScenarioLike, *, set: Mapping[str, Any] | None = None,
                  ci: bool = False) -> spec.Scenario:
    """A checked Scenario from a shipped name, a file path or a Scenario (copied, the
    argument is left as it is). ``set`` overrides values as the file would give them:
    ``{"base.start_elevation": "60 deg"}`` sets an FMU instance's parameter,
    ``{"stop_time": "10 s"}`` a top-level key (names and files only); a bare number is SI
    (``1.0`` for an angle is 1 rad, 57.3 deg: write ``"60 deg"``); every value goes
    through the checks of a value written in the file (units, ranges, the model's own
    refusals) when the scenario is bound (``run``). ``ci`` applies the file's [ci] section.
    A Scenario's fields (changed in Python) are checked as the same values in a file."""
    _flags_given(ci=ci)
    source = scenario.source if isinstance(scenario, spec.Scenario) else str(scenario)
    set = _overrides(source, set)
    top = {k: v for k, v in set.items() if "." not in k}
    if isinstance(scenario, spec.Scenario):
        if top or ci:
            raise spec.ScenarioError(scenario.source, "set" if top else "ci",
                                     f"{'top-level keys ' + ', '.join(top) if top else 'ci'} can be applied to a "
                                     "scenario file only (load_scenario(path, set=..., ci=...)), not to a Scenario "
                                     "object; change its fields with dataclasses.replace")
        loaded = spec.parse_data(copy.deepcopy(spec.as_data(scenario)), scenario.source)
        loaded.short = scenario.short
    elif not isinstance(scenario, (str, os.PathLike)):
        raise TypeError(f"scenario must be a shipped name, a file path or a Scenario, got "
                        f"{type(scenario).__name__} {scenario!r:.60}")
    else:
        path = runner.resolve(os.fspath(scenario))
        if not path.exists():
            raise spec.ScenarioError(str(path), "file", runner.not_found([os.fspath(scenario)]))
        loaded = spec.load(path)
        overrides = {**(loaded.ci if ci else {}), **top}
        if overrides:
            try:
                loaded = spec.load(path, overrides=overrides)
            except spec.ScenarioError as exc:
                raise _as_set(exc, top) from None
        loaded.short = bool(ci)
    problems = []   # every mistake of set= at once, not the first alone
    for key, value in set.items():
        if "." not in key:
            continue
        inst, name = key.split(".", 1)
        if inst not in loaded.fmus:
            near = difflib.get_close_matches(inst, list(loaded.fmus), 1, 0.6)
            problems.append(spec.ScenarioError(_set_source(loaded.source), f"set[{key!r}]",
                                               f"unknown FMU instance {inst!r}; "
                                               + (f"did you mean {near[0]!r}? " if near else "")
                                               + f"declared: {', '.join(loaded.fmus)} (top-level keys: no dot)"))
        elif loaded.sweep and loaded.sweep[0] == key:
            problems.append(spec.ScenarioError(_set_source(loaded.source), f"set[{key!r}]",
                                               "is the swept parameter; every run sets it from sweep.values; to run "
                                               f"one value: set={{'sweep': {{'parameter': {key!r}, "
                                               f"'values': [{value!r}]}}}}"))
        else:
            loaded.parameters[inst][name] = value
    if problems:
        raise spec.ScenarioError.joined(problems)
    return loaded


def _set_source(source: str) -> str:
    """Where a problem of ``set`` is told as coming from: the caller's set= on the scenario,
    not the scenario's file (a shipped file named first read as broken)."""
    return f"set= for {pathlib.Path(source).name}"


def _as_set(error: spec.ScenarioError, given: Mapping[str, Any] | None) -> spec.ScenarioError:
    """``error`` told as the caller's where ``given`` (``set``) is to blame, as set's own
    refusals are (a shipped file named first reads as broken): a problem in a parameter or
    top-level key it set as ``set['inst.name']`` / ``set['stop_time']``, one whose text
    names a value it set ("declination = ...", "stop_time (0.5 s)") from ``set=``. A
    problem told for several keys in the same words (a source below the horizon: once per
    sweep value) is told once."""
    paths = {f"fmus.{k.split('.', 1)[0]}.parameters.{k.split('.', 1)[1]}": k for k in given or {} if "." in k}
    paths.update({k: k for k in given or {} if "." not in k})
    named = [k.split(".", 1)[-1] for k in given or {}]
    told = []
    for source, key, problem in error.problems:
        path = next((p for p in paths if key == p or key.startswith((p + "[", p + "."))), None)
        if path is not None:
            told.append(spec.ScenarioError(_set_source(source), f"set[{paths[path]!r}]{key[len(path):]}", problem))
        elif any(re.search(rf"\b{re.escape(name)}\b( = |\s*\()", problem) for name in named):
            told.append(spec.ScenarioError(_set_source(source), key, problem))
        else:
            told.append(spec.ScenarioError(source, key, problem))
    return spec.ScenarioError.joined(told)     # each problem once


def _overrides(source: str, values: Any) -> dict[str, Any]:
    """``set`` as a dict of text keys to values as a file gives them (numpy scalars and
    arrays as numbers and lists); anything else is refused, naming it."""
    if values is None:
        return {}
    if not isinstance(values, Mapping):
        raise spec.ScenarioError(_set_source(source), "set",
                                 f"expected a mapping of 'instance.parameter' or top-level keys "
                                 f"to values, got {type(values).__name__} {values!r:.60}")
    bad = [k for k in values if not isinstance(k, str) or not k]
    if bad:
        raise spec.ScenarioError(_set_source(source), "set",
                                 f"keys are text, 'instance.parameter' or a top-level key; got "
                                 f"{', '.join(repr(k) for k in bad)}")
    return {k: spec.plain(v) for k, v in values.items()}


# ------------------------------------------------------------------------ results
class Charts(list["Figure"]):
    """Figures that show themselves: a notebook cell ending in ``result.plot()`` draws
    them (as python-control's ControlPlot does), a script saves them (``save``). A list of
    matplotlib Figures (not pyplot's: drawing them leaves the caller's figures alone);
    ``names`` the file name of each (the report's: "leg_error_vs_time")."""

    def __init__(self, figures: Any = (), names: Sequence[str] = ()):
        super().__init__(figures)
        self.names = list(names)

    def _repr_html_(self) -> str:
        images = []
        for figure in self:
            buffer = io.BytesIO()
            figure.savefig(buffer, format="png", dpi=90)
            images.append(f'<img src="data:image/png;base64,{base64.b64encode(buffer.getvalue()).decode()}"/>')
        return "<br/>".join(images)

    def save(self, folder: str | os.PathLike[str], stem: str = "chart") -> list[pathlib.Path]:
        """Write each figure as ``folder/<its name>.png`` (the names report.md gives them;
        ``<stem>_<k>.png`` for a figure without one); their paths."""
        made: pathlib.Path = runner.make_folder(folder)
        names = self.names + [f"{stem}_{k}" for k in range(len(self.names) + 1, len(self) + 1)]
        paths = [made / f"{spec.file_label(name)}.png" for name in names[:len(self)]]
        for figure, path in zip(self, paths):
            figure.savefig(path, dpi=120)
        return paths

    def __repr__(self) -> str:
        titles = "; ".join(t.split("\n")[0] for t in (f.get_suptitle() for f in self) if t)
        return f"<Charts: {len(self)} figure{'s' * (len(self) != 1)}{': ' + titles if titles else ''}>"


_SMALL = {"m": ("nm", "µm", "mm", "m"), "rad": ("nrad", "µrad", "mrad", "rad")}   # their units by 1e-9 .. 1
_POSE = ("x", "y", "z", "roll", "pitch", "yaw")      # a 6-vector of m, m, m, rad, rad, rad


def _from_start(name: str, unit: str, values: np.ndarray, labels: list[str]) -> tuple[str, str, np.ndarray, list[str]]:
    """Positions or angles (rows x n, one unit) as their change from their first row, in
    the unit the largest change reads best in (µm, µrad, ...): a platform 2.68 m below the
    base moving by microns is drawn as those microns, not as a flat line at -2.68 m."""
    change = values - values[:1]
    largest = float(np.nanmax(np.abs(change))) if change.size and np.isfinite(change).any() else 0.0
    power = min(3, max(0, int(np.floor(np.log10(largest) / 3)) + 3)) if largest > 0 else 1
    shown = _SMALL[unit][power]
    start = f"from {values[0, 0]:.6g} {unit}" if values.shape[1] == 1 and len(values) else "from the start"
    return name, f"{shown}, {start}", change / 10.0 ** (3 * power - 9), labels


def _html_table(head: Sequence[str], rows: Sequence[Sequence[Any]]) -> str:
    cells = "".join(f"<th>{html.escape(str(h))}</th>" for h in head)
    body = "".join("<tr>" + "".join(f"<td>{html.escape(str(c))}</td>" for c in row) + "</tr>" for row in rows)
    return f"<table><tr>{cells}</tr>{body}</table>"


_STATUS_STYLE = {run_status.OK: "", run_status.FLAGGED: "color:#b00020",
                 run_status.FAILED: "color:#b00020;font-weight:bold", run_status.REFUSED: "color:#b00020",
                 run_status.NOT_RUN: "color:#777777"}


class RunResult:
    """One run: its recorded time series (SI units), metrics and flags.

    ``time``, ``values`` (rows x columns), ``names`` ("inst.var[k]") and ``units`` are
    numpy arrays and lists; ``result["plant.pose"]`` is one variable (a vector: rows x n),
    ``to_pandas()`` the table, ``to_numpy()`` a structured array as FMPy's simulate_fmu
    returns. A run that failed holds what it recorded up to then (``flags`` says why)."""

    def __init__(self, run: master.Run, plotted: Sequence[str] = ()):
        self.run = run
        self._plotted = list(plotted)    # what ``plot()`` draws by default: what the metrics read
        self.label: str = run.label
        self.metrics: dict = run.metrics
        self.flags: list[Flag] = run_flags.by_severity(run.flags)
        self.failure: str | None = run.failure or None   # why an FMU stopped the run before its stop time
        self.steps: int = run.steps
        self.wall_time: float = run.wall_time
        self.sim_time: float = run.sim_time
        records = run_records(run)
        self.records: Records = records if records is not None else Records([], [], 0)
        # the file's [requirements] judged on this run (Result fills them in): [{"requirement", "value", "unit", "met"}]
        self.requirements: list[dict] = []

    @property
    def requirements_met(self) -> bool:
        """True if the run meets every requirement of its file that holds for it."""
        return all(j["met"] for j in self.requirements)

    @property
    def ok(self) -> bool:
        """True if nothing flagged the run (as ``solve_ivp``'s ``success``)."""
        return not self.flags

    @property
    def status(self) -> str:
        """"failed" (cut short: an FMU stopped it), "flagged" (ran to its stop time, but its
        numbers are not results) or "ok": the vocabulary of scenarios/runs/status.py."""
        return run_status.of_run(self.failure, self.flags)

    @property
    def message(self) -> str:
        """What went wrong, worst first ('' for a clean run)."""
        return run_flags.summary(self.flags)

    @property
    def time(self) -> np.ndarray:
        return self.records.time

    @property
    def values(self) -> np.ndarray:
        return self.records.values

    @property
    def names(self) -> list[str]:
        return self.records.names

    @property
    def units(self) -> dict[str, str]:
        """{"inst.var[k]": unit} of every recorded column."""
        return dict(zip(self.records.names, self.records.units))

    def __getitem__(self, name: str) -> np.ndarray:
        """A recorded variable: a scalar's column, or a vector's (rows x n) array."""
        if name == "time" or name in self.records.names:
            return self.records[name]
        parts = [n for n in self.records.names if n.startswith(name + "[")]
        if not parts and not self.records.names and self.run.failure:
            raise KeyError(f"run {self.label}: nothing was recorded, the run failed before its first row: "
                           f"{self.run.failure}")
        if not parts:
            groups = self._variables()
            near = [g for g in groups if g.split(".", 1)[-1] == name] or difflib.get_close_matches(name, groups, 1, 0.6)
            raise KeyError(f"run {self.label}: no recorded variable {name!r}"
                           + (f"; did you mean {near[0]!r}?" if near else "") + "; recorded: "
                           f"{', '.join(groups) or 'nothing (the scenario records no variable)'}")
        return np.column_stack([self.records[n] for n in parts])

    def _variables(self) -> list[str]:
        """The recorded variables, a vector once by its name ("plant.pose")."""
        return list(dict.fromkeys(n.split("[", 1)[0] for n in self.records.names))

    def _ipython_key_completions_(self) -> list[str]:
        """Completion inside ``run["...``: every recorded variable, vectors by their name."""
        return list(dict.fromkeys(self._variables() + self.records.names))

    def to_pandas(self) -> pandas.DataFrame:
        """The recorded series as a DataFrame indexed by time [s], one column per
        variable; the units in ``frame.attrs["units"]``."""
        pd = _pandas()
        frame = pd.DataFrame(self.values, columns=self.names, index=pd.Index(self.time, name="time"))
        frame.attrs["units"] = self.units
        return frame

    def to_numpy(self) -> np.ndarray:
        """A structured array with a "time" field and one field per variable (FMPy's shape)."""
        table = np.empty(len(self.time), dtype=[(name, float) for name in ["time"] + self.names])
        for name, column in zip(table.dtype.names or (), [self.time] + list(self.values.T)):
            table[name] = column
        return table

    def to_csv(self, path: str | os.PathLike[str]) -> pathlib.Path:
        """Export the records as CSV (header with units, each float exactly)."""
        return self.records.to_csv(path)

    def plot(self, *names: str) -> Charts:
        """Recorded variables against time, one panel each (a vector's components as
        lines), the unit on each axis: ``run.plot("plant.pose", "controller.leg_force")``;
        without names, the variables the scenario's metrics read. A failed or flagged run
        says so in the title."""
        chosen = list(names) or [n for n in self._plotted if n in self._ipython_key_completions_()]
        if not chosen:
            raise ValueError(f"run {self.label}: name the variables to plot; recorded: "
                             f"{', '.join(self._variables()) or 'nothing'}")
        columns = []     # (label, unit, rows x n, the lines' labels)
        for name in chosen:
            values = self[name].reshape(len(self.time), -1)
            parts = [name] if name in self.records.names else [n for n in self.names if n.startswith(name + "[")]
            if [self.units[p] for p in parts] == ["m"] * 3 + ["rad"] * 3:   # a pose: each component apart, named
                columns += [_from_start(f"{part} {_POSE[k]}", self.units[part], values[:, [k]], [""])
                            for k, part in enumerate(parts)]
                continue
            for unit in dict.fromkeys(self.units[p] for p in parts):
                mine = [k for k, p in enumerate(parts) if self.units[p] == unit]
                shown = name if len(mine) == len(parts) else f"{name}[{mine[0] + 1}:{mine[-1] + 1}]"
                labels = [parts[k][len(name):] for k in mine]
                columns.append(_from_start(shown, unit, values[:, mine], labels) if unit in _SMALL else
                               (shown, unit, values[:, mine], labels))
        status = "" if self.ok else self.message if self.status == "failed" else f"FLAGGED: {self.message}"
        return Charts([report.variables_chart(self.label, self.time, columns, status)],
                      [f"{self.label}_{'_'.join(chosen)}"])

    def _repr_html_(self) -> str:
        state = html.escape(self.status)
        said = f": {html.escape(self.message)}" if self.message else ""
        rows = [(m, k, f"{v:.4g}" if isinstance(v, float) else v, key_unit(values, k))
                for m, values in self.metrics.items() for k, v in values.items() if k != "unit"]
        return (f'<p><b>run {html.escape(self.label)}</b>: <span style="{_STATUS_STYLE[self.status]}">{state}'
                f'{said}</span>; {len(self.time)} rows x {len(self.names)} variables, {self.sim_time:g} s '
                f'simulated</p>' + _html_table(("metric", "", "value", "unit"), rows)
                + (_html_table(("requirement", "value", ""), [
                    (j["requirement"], "not counted" if j["value"] is None else f"{j['value']:.4g} {j['unit']}",
                     "met" if j["met"] else "NOT MET") for j in self.requirements]) if self.requirements else ""))

    def __repr__(self) -> str:
        kinds = "; ".join(f.kind for f in self.flags)
        state = {"ok": "ok", "flagged": f"flagged: {kinds}",
                 "failed": f"FAILED at t = {self.sim_time:g} s: {kinds}"}[self.status]
        missed = spec.unmet(self.requirements)
        said = f"; requirements NOT MET: {missed}" if missed else "; requirements met" if self.requirements else ""
        return (f"<RunResult {self.label!r}: {state}; {len(self.time)} rows x {len(self.names)} variables, "
                f"{self.sim_time:g} s simulated{said}>")


class Result:
    """What ``movingbase.run`` returns: one RunResult per run (per sweep value), in sweep
    order, by label (``result["moving_base"]``) or by iteration; the metrics of every run;
    the report's charts (``plot``) and the report itself (``report``)."""

    def __init__(self, scenario: spec.Scenario, runs: Sequence[master.Run], report_path: pathlib.Path | None = None):
        self.scenario = scenario
        self._runs = list(runs)
        read = [v for m in scenario.metrics for v in m.args.values() if isinstance(v, str) and "." in v]
        self.runs: dict[str, RunResult] = {r.label: RunResult(r, list(dict.fromkeys(read))) for r in self._runs}
        for result in self.runs.values():
            result.requirements = spec.judge(scenario.requirements, result.label, result.metrics)
        self.report_path = report_path     # where ``out`` wrote the report, if it was given

    def __getitem__(self, label: str | int) -> RunResult:
        """A run by its label, or by its position in sweep order (as iteration gives them)."""
        if isinstance(label, int) and not isinstance(label, bool):
            if not -len(self.runs) <= label < len(self.runs):
                raise IndexError(f"run {label} of {len(self.runs)} ({', '.join(self.runs)})")
            return list(self.runs.values())[label]
        if label not in self.runs:
            raise KeyError(f"no run {label!r}; runs: {', '.join(self.runs)}")
        return self.runs[label]

    def _ipython_key_completions_(self) -> list[str]:
        return list(self.runs)

    def __iter__(self) -> Iterator[RunResult]:
        return iter(self.runs.values())

    def __len__(self) -> int:
        return len(self.runs)

    @property
    def metrics(self) -> dict[str, dict]:
        """{run label: {metric: {key: value, "unit": ...}}}, as metrics.json holds them."""
        return {label: r.metrics for label, r in self.runs.items()}

    @property
    def flags(self) -> dict[str, list]:
        """{run label: its flags} of the runs that were flagged."""
        return {label: r.flags for label, r in self.runs.items() if r.flags}

    def metrics_table(self) -> pandas.DataFrame:
        """One row per run, one column per (metric, key) number (floats; NaN where nothing
        was counted), their units in ``table.attrs["units"]`` ({("leg error", "rms"): "µm"}),
        and the columns ("status", "") and ("flags", "") saying what went wrong with a run
        ('' if nothing): a flagged run's numbers are not results, and the table says so
        where they stand."""
        pd = _pandas()
        rows = {label: {("status", ""): r.status,
                        **{(m, k): (float("nan") if v is None else v)
                           for m, values in r.metrics.items() for k, v in values.items() if k != "unit"},
                        ("flags", ""): run_flags.summary(r.flags),
                        **({("requirements", ""): spec.unmet(r.requirements) or "met"} if r.requirements else {})}
                for label, r in self.runs.items()}
        table = pd.DataFrame.from_dict(rows, orient="index")
        table.attrs["units"] = {(m, k): key_unit(values, k) for r in self.runs.values()
                                for m, values in r.metrics.items() for k in values if k != "unit"}
        return table

    def to_pandas(self) -> pandas.DataFrame:
        """Every run's recorded series in one DataFrame indexed by (run, time)."""
        pd = _pandas()
        return pd.concat({label: r.to_pandas() for label, r in self.runs.items()}, names=["run"])

    def plot(self) -> Charts:
        """The report's charts (a notebook shows them; ``.save(folder)`` writes them): error
        against time per tracking metric, and the summary bars when there are several
        runs. One run's recorded variables: ``result[label].plot(...)``."""
        tracked = [m for m in self.scenario.metrics if m.kind in report.TRACKING]
        panels = [report._error_chart(self.scenario, self._runs, m, io.BytesIO()) for m in tracked]
        if tracked and len(self._runs) > 1:
            panels.append(report._summary_chart(self.scenario, self._runs, tracked, io.BytesIO()))
        names = [f"{m.name.replace(' ', '_')}_vs_time" for m in tracked] + ["summary"] * (len(panels) > len(tracked))
        return Charts((next(iter(p.values())).figure for p in panels), names)

    def report(self, out: str | os.PathLike[str]) -> pathlib.Path:
        """Write what ``run(..., out=out)`` and ``movingbase run --out OUT`` write, where they
        write it: into ``out/<file stem>/`` (records as npz, metrics.json, charts,
        report.md); the report's path."""
        folder = runner.output_folder(out, self.scenario.source)     # made and locked there
        earlier, started = runner.replaced(folder), time.time()
        if earlier:       # said, as the command says it
            print(earlier, file=sys.stderr, flush=True)
        runs = []
        for run in self._runs:
            kept = self.runs[run.label].records
            target = folder / f"{spec.file_label(run.label)}.npz"
            if run.record_path is None or pathlib.Path(str(run.record_path)).resolve() != target.resolve():
                run = dataclasses.replace(run, record_path=kept.save(target))
            runs.append(run)
        written = runner.write_results(self.scenario, runs, folder)
        if earlier and runner.left_over(folder, started):
            print(runner.left_over(folder, started), file=sys.stderr, flush=True)
        runner.unlock_folder(folder)
        return written

    @property
    def ok(self) -> bool:
        """True if no run was flagged or failed."""
        return all(r.ok for r in self)

    def to_ssp(self, path: str | os.PathLike[str], run: str | None = None) -> pathlib.Path:
        """Write the scenario as an SSP file with the sweep value of run ``run`` (a label;
        default the first): ``export_ssp``, the values as this result ran them."""
        value = None
        if self.scenario.sweep:
            label = run if run is not None else self[0].label
            self[label]     # a KeyError naming the runs
            value = next(item for item in self.scenario.sweep[1] if spec.run_label(item) == label)
        elif run is not None and run not in self.runs:
            raise KeyError(f"no run {run!r}; runs: {', '.join(self.runs)}")
        return export_ssp(self.scenario, path, value=value)

    @property
    def requirements_met(self) -> bool:
        """True if every run meets every requirement of the file that holds for it."""
        return all(r.requirements_met for r in self)

    def __repr__(self) -> str:
        bad = "".join(f"; {s}: {', '.join(label for label, r in self.runs.items() if r.status == s)}"
                      for s in run_status.counts(r.status for r in self) if s != run_status.OK)
        missed = [label for label, r in self.runs.items() if not r.requirements_met]
        said = f"; requirements NOT MET: {', '.join(missed)}" if missed else \
            "; requirements met" if any(r.requirements for r in self) else ""
        return f"<Result {self.scenario.name!r}: {run_status.told(r.status for r in self)}{bad}{said}>"

    def _repr_html_(self) -> str:
        """Each run's status first (FAILED and flagged in red, with why), then its metrics."""
        tracked = [(m, k) for m, values in next(iter(self.runs.values())).metrics.items()
                   for k in ("rms", "peak") if k in values] if self.runs else []
        head = ["run", "status"] + [f"{m} {k} [{key_unit(self[0].metrics[m], k)}]" for m, k in tracked] + ["flags"]
        rows = [[label, r.status]
                + [f"{r.metrics[m][k]:.4g}" if isinstance(r.metrics.get(m, {}).get(k), float) else ""
                   for m, k in tracked] + [r.message] for label, r in self.runs.items()]
        if any(r.requirements for r in self):
            head.append("requirements")
            for row, r in zip(rows, self):
                row.append(spec.unmet(r.requirements) or ("met" if r.requirements else ""))
        state = run_status.told(r.status for r in self) + ("" if self.ok else ": a flagged or failed run's "
                                                              "numbers are not results")
        return (f"<p><b>Result {html.escape(self.scenario.name)}</b>: "
                f'<span style="{_STATUS_STYLE[run_status.worst(r.status for r in self)]}">{state}</span></p>'
                + _html_table(head, rows))


@_public
def run(scenario: ScenarioLike, *, set: Mapping[str, Any] | None = None, ci: bool = False,
        implementation: str | None = None, out: str | os.PathLike[str] | None = None,
        progress: bool = True, allow_unstable: bool = False) -> Result:
    """Run a scenario (a shipped name, a file path or a Scenario) as ``movingbase run``
    does, every sweep value; ``set`` and ``ci`` as in ``load_scenario`` (a bare number in
    ``set`` is SI: ``1.0`` for an angle is 1 rad; write ``"60 deg"``);
    ``implementation`` ("native" or "python") for every FMU. A communication step beyond
    the predicted stability limit is refused (ScenarioError) unless ``allow_unstable``;
    then every run is flagged. Nothing is written to disk unless ``out`` is given: then
    the files of ``movingbase run --out OUT`` (OUT/<file stem>/). A RunWarning names each
    run that failed or was flagged, and before the runs start a slew its stop time cuts
    (with the stop time that finishes it). Ctrl-C keeps the runs that finished: written
    with ``out`` (a report marked interrupted), and the KeyboardInterrupt's ``.result``;
    its message says how to run the rest. Statuses: scenarios/runs/status.py."""
    _flags_given(ci=ci, progress=progress, allow_unstable=allow_unstable)
    loaded = load_scenario(scenario, set=set, ci=ci)
    try:
        with runner.announcing_builds():    # always: a first build takes seconds (progress= is the bars)
            prepared, paths, descriptions, values = runner.prepare_loaded(loaded, implementation, out)
    except spec.ScenarioError as exc:
        raise _as_set(exc, set) from None
    try:
        before = runner.pre_run_flags(prepared, paths, descriptions, values, loaded.short, allow_unstable)
    except spec.ScenarioError as exc:
        raise _as_set(exc, set) from None
    values_set = f" (set={textwrap.shorten(repr(dict(set)), 200, placeholder=' ...}')})" if set else ""
    for line in runner.foretold(prepared, before):    # before running: the user may stop and fix it
        warnings.warn(line.replace(": ", f"{values_set}: ", 1), RunWarning, stacklevel=3)
    outdir = None if out is None else runner.output_folder(out, prepared.source)
    earlier, started = outdir is not None and runner.replaced(outdir), time.time()
    if earlier:
        print(earlier, file=sys.stderr, flush=True)
    try:
        runs = runner.run_prepared(prepared, paths, descriptions, values, outdir, progress, before=before)
    except runner.Interrupted as stopped:   # Ctrl-C: what finished is kept (on disk with out=), as campaign's
        runner.keep_interrupted(prepared, stopped, outdir)
        stopped.result = Result(prepared, stopped.runs, outdir / "report.md" if outdir and stopped.runs else None)
        raise stopped.with_traceback(None) from None
    result = Result(prepared, runs, runner.write_results(prepared, runs, outdir) if outdir else None)
    if earlier and runner.left_over(outdir, started):
        print(runner.left_over(outdir, started), file=sys.stderr, flush=True)
    if outdir is not None:
        runner.unlock_folder(outdir)
    for r in result:     # shown in a notebook as a warning: a failed run is no result
        if not r.ok:
            said = r.message if r.status == "failed" else f"flagged: {r.message}"
            warnings.warn(f"{prepared.name}{values_set}, run {r.label!r} {said}", RunWarning,
                          stacklevel=3)   # the caller's line
    return result


def fmus(*names: str, implementation: str = "native", fmi_version: int = 2) -> dict[str, pathlib.Path]:
    """The kit's FMU files, by the names scenario files give them (``fmu = "hexapod_plant"``;
    every FMU without names), built if missing or stale: what to give
    ``fmpy.simulate_fmu`` or any FMI tool. ``implementation`` "native" (C, no Python in
    the host; FMI 2.0 or 3.0) or "python" (pythonfmu, FMI 2.0). Each build is said on
    stderr as it starts."""
    with runner.announcing_builds():    # 25 s of first builds once passed without a word
        return runner.fmu_files(names or catalogue.KEYS, implementation, fmi_version)


@_public
def export_ssp(scenario: ScenarioLike, path: str | os.PathLike[str], *, set: Mapping[str, Any] | None = None,
               ci: bool = False, implementation: str | None = None, fmi_version: int | None = None,
               value: Any = None) -> pathlib.Path:
    """Write a scenario as an SSP file (``movingbase run NAME --ssp FILE``): SystemStructure.ssd
    (its FMU instances, connections and parameter values as SSD bindings) with the FMUs it
    chose; SSP 1.0, or 2.0 where an FMU is FMI 3.0 (``fmi_version=3``). A sweep's run is
    one system: ``value`` picks the sweep value (default: the first). ``set``, ``ci`` and
    ``implementation`` as in ``run``. Run it in fmpy with ``simulate_ssp``, in libcosim or
    ecos as docs/hosts.md shows. Returns the file's path."""
    from scenarios.ssp import export_ssp as export
    _flags_given(ci=ci)
    target = pathlib.Path(path)
    if target.is_dir() or not target.parent.is_dir():
        raise runner.OutputError(f"SSP file {spec.shown(target)}: " + (
            "is a folder" if target.is_dir() else f"its folder {spec.shown(target.parent)} does not exist")
            + "; give the path of the .ssp file to write")
    prepared, paths, _, values = _one_run(scenario, set, ci, value, implementation, fmi_version)
    return export(prepared, paths, values, target)


def _one_run(scenario: ScenarioLike, set: Mapping[str, Any] | None, ci: bool, value: Any,
             implementation: str | None = None, fmi_version: int | None = None) -> tuple:
    """(scenario, FMU paths, descriptions, values) of one run: the sweep value ``value``
    applied (default the first), every check done as before a run."""
    loaded = load_scenario(scenario, set=set, ci=ci)
    try:
        with runner.announcing_builds():
            prepared, paths, descriptions, values = runner.prepare_loaded(loaded, implementation, None, fmi_version)
        if prepared.sweep:
            items = prepared.sweep[1]
            if value is not None and value not in items:
                raise spec.ScenarioError(prepared.source, "value", f"{value!r} is not one of the sweep's values "
                                         f"({prepared.sweep[0]}: {', '.join(map(repr, items))})")
            inst, var, converted = spec.sweep_value(prepared, descriptions, items[0] if value is None else value)
            values[inst][var] = converted
        elif value is not None:
            raise spec.ScenarioError(prepared.source, "value", "the scenario has no sweep: give no value")
    except spec.ScenarioError as exc:
        raise _as_set(exc, set) from None
    return prepared, paths, descriptions, values


class LoopAnalysis:
    """A scenario's control loop as python-control objects, as the guard predicts it before
    a run (scenarios/runs/flags.py, controller/design.py): the loop of the controller with
    the lowest predicted step limit, each leg-space mode along the motion a SISO loop.

    ``step`` the scenario's communication step [s]; ``step_limit`` the step [s] beyond
    which a mode goes unstable (the guard refuses a run beyond it); ``observer_limit`` the
    disturbance observer's bandwidth limit [Hz] at this step (None without an observer);
    ``masses`` the distinct modes' masses [kg], lightest first (the plant's payload as built),
    ``observer_masses`` the mass [kg] the observer assumes for each (its matrix's Rayleigh
    quotient in the mode's shape; None without an observer); ``gains``
    (controller.pid.PIDGains) and ``model`` (controller.design.LoopModel: master,
    extrapolation, reflected mass, actuator, sensors, observer) as the scenario sets them.
    ``open_loop(k)`` / ``closed_loop(k)`` mode k's discrete loop (python-control LTI, dt =
    step; default the heaviest), ``margins()`` the heaviest and worst modes' margins
    (controller.design.Design), ``table()`` every mode's. The model is linear: it leaves
    out gravity stiffness, Coulomb friction and saturation."""

    def __init__(self, name: str, prediction: run_flags.Prediction):
        from controller import design
        self._design = design
        self.name, self.controller = name, prediction.controller
        self.step, self.step_limit = prediction.step, prediction.limit
        self.gains, self.model = prediction.gains, prediction.loop
        self._modes = design.distinct_modes(prediction.masses)   # masses, or (mass, observer's mass) pairs
        paired = self._modes.ndim == 2
        self.masses = self._modes[:, 0] if paired else self._modes
        self.observer_masses = self._modes[:, 1] if paired else None

    @functools.cached_property
    def observer_limit(self) -> float | None:
        """The disturbance observer's bandwidth [Hz] beyond which a mode goes unstable at this
        step (None without an observer; bisected: seconds)."""
        if self.model.observer_bandwidth <= 0:
            return None
        return float(self._design.observer_limit(self._modes, self.gains, self.step, self.model))

    @property
    def stable(self) -> bool:
        """True if the step is within the predicted limit (the guard runs it)."""
        return self.step <= self.step_limit * (1 + 1e-9)

    def open_loop(self, mode: int = -1) -> Any:
        """Mode ``mode``'s loop transfer L(z) (python-control StateSpace, dt = step): for
        ``control.stability_margins``, ``bode_plot``, ``nyquist_plot``."""
        assumed = None if self.observer_masses is None else self.observer_masses[mode]
        return self._design.mode_loop(self.masses[mode], self.gains, self.step, self.model, assumed)

    def closed_loop(self, mode: int = -1) -> Any:
        """Mode ``mode``'s closed loop L / (1 + L) (its poles: ``.poles()``)."""
        import control
        return control.feedback(self.open_loop(mode))

    def margins(self) -> Any:
        """controller.design.Design: the heaviest mode's crossover [Hz] and margins, the worst
        phase and gain margin over every mode (ValueError if a mode is unstable)."""
        return self._design.modal_margins(self.gains, self.step, self._modes, self.model)

    def table(self) -> pandas.DataFrame:
        """One row per mode: its mass, crossover, phase and gain margins (python-control's,
        on the frequency response up to Nyquist) and the closed loop's largest pole radius
        (< 1: stable), with an observer the mass it assumes (a payload error: a row per end
        of it); units in ``attrs``."""
        pd = _pandas()
        rows = []
        for k, mass in enumerate(self.masses):
            loop = self.open_loop(k)
            w_gc, pm, gm, lower = self._design.loop_margins(loop)
            with np.errstate(divide="ignore"):     # no lower gain margin: -inf dB
                decibels = 20 * np.log10([gm, lower])
            rows.append({"mass": float(mass), "crossover": float(w_gc / (2 * np.pi)), "phase margin": float(pm),
                         "gain margin": float(decibels[0]), "lower gain margin": float(decibels[1]),
                         "pole radius": float(np.abs(self.closed_loop(k).poles()).max())})
            if self.observer_masses is not None:   # a payload error: a mode once per end of its observer mass
                rows[-1]["observer mass"] = float(self.observer_masses[k])
        table = pd.DataFrame(rows)
        table.attrs["units"] = {"mass": "kg", "crossover": "Hz", "phase margin": "deg", "gain margin": "dB",
                                "lower gain margin": "dB", "pole radius": "1"} | (
            {} if self.observer_masses is None else {"observer mass": "kg"})
        return table

    def __repr__(self) -> str:
        observer = "" if self.observer_limit is None else (
            f"; observer {self.model.observer_bandwidth:g} Hz, limit {self.observer_limit:.3g} Hz")
        return (f"<LoopAnalysis {self.name!r} {self.controller!r}: step {self.step * 1e3:g} ms, predicted limit "
                f"{self.step_limit * 1e3:.4g} ms ({'stable' if self.stable else 'UNSTABLE'}); {len(self.masses)} "
                f"modes {self.masses[0]:.0f}..{self.masses[-1]:.0f} kg{observer}>")


@_public
def loop_analysis(scenario: ScenarioLike, *, set: Mapping[str, Any] | None = None, ci: bool = False,
                  value: Any = None) -> LoopAnalysis:
    """The scenario's control loop as the guard predicts it (LoopAnalysis): the predicted
    step limit, the observer's limit, each leg-space mode's loop as python-control objects
    and their margins; no run. ``value`` picks a sweep value (default the first); ``set``
    and ``ci`` as in ``run``. ScenarioError if the scenario closes no loop the kit models."""
    prepared, paths, descriptions, values = _one_run(scenario, set, ci, value)
    prediction = run_flags.predict(prepared, paths, descriptions, values, ci=True)
    if prediction is None:
        raise spec.ScenarioError(prepared.source, "fmus", "no control loop the kit models (a controller FMU "
                                 "closing a loop of fmu_src/catalogue.py's CONTROL_LOOPS)")
    return LoopAnalysis(prepared.name, prediction)


def simulate_ssp(path: str | os.PathLike[str], *, initial_exchange: bool = True) -> np.ndarray:
    """Run an SSP of ``export_ssp`` in fmpy (``fmpy.ssp.simulate_ssp``, fmpy's own master,
    plain Jacobi) with what fmpy needs given: the SSD's parameter values as its
    ``parameter_set`` (fmpy reads the bindings but applies none) and the file's start,
    step and stop; with ``initial_exchange`` (default) each FMU gets the connected inputs
    at the start time before its first step, as this kit's master and libcosim do (fmpy as
    it is steps first with every connected input 0.0: the controller's reference is then
    the singular zero pose and the run stops at t = 0 with SingularConfigurationError).
    fmpy's structured array: one row per step, "time" the end of the step, columns
    "instance.connector"."""
    from scenarios.ssp import experiment, simulate_exported
    _flags_given(initial_exchange=initial_exchange)
    start, step, stop = experiment(path)
    timing = types.SimpleNamespace(start_time=start, step=step, stop_time=stop)
    return simulate_exported(path, timing, initial_exchange)


class RunWarning(UserWarning):
    """A run of ``movingbase.run`` failed or was flagged: its numbers are not results."""


# ------------------------------------------------------------------------ campaigns
def _si_column(values: list) -> tuple[list[float], str] | None:
    """A campaign column of quantities ("0 m", "5 m") as SI floats and their SI unit; None
    if it is not one (words such as "moving_base", mixed dimensions)."""
    numbers, dimensions = [], set()
    for value in values:
        if not isinstance(value, str):
            return None
        try:
            unit = split(value)[1]
            numbers.append(units.to_si(value))
        except UnitError:
            return None
        known = units.lookup(units.spelled(unit)) if unit else None
        dimensions.add(known[1] if known else None)
    dimension = dimensions.pop() if len(dimensions) == 1 else None
    return (numbers, dimension) if dimension else None


class CampaignResult:
    """What ``movingbase.campaign`` returns: the table of its runs (``table()``: one row
    per run with its case values, status, error and metrics, the campaign's summary.csv
    as a DataFrame), each run's metric series and, if the campaign keeps them, records."""

    def __init__(self, campaign: campaigns.Campaign, jobs: list, store: Any, summary: pathlib.Path):
        self.campaign = campaign
        self.store = store            # scenarios.runs.engine.Store: the runs' result files
        self.summary_path = summary
        self._keys = {job.label: job.key for job in jobs}

    def table(self) -> pandas.DataFrame:
        """One row per run: label, the case values, status, error, every metric number.
        Numbers are numbers: a case value written with a unit ("5 m", "2 ms") in SI
        (plot a metric against it), a sampled input's draw in SI, each column named by its
        key alone and its unit in ``table.attrs["units"]`` ({"base.lever_arm": "m",
        "plant.payload_mass_error": "kg", "leg error rms": "µm"}); summary.csv keeps the
        values as written and a draw's unit in its column's name."""
        table = _pandas().read_csv(self.summary_path)   # floats exact: written as repr, read round-trip
        for column in ("error", "flags"):               # '' (nothing went wrong) is text, not a missing number
            table[column] = table[column].astype(object).where(table[column].notna(), "")
        units = {}
        for column in self.campaign.varying:
            if column in table:
                converted = _si_column(table[column].tolist())
                if converted is not None:
                    table[column], units[column] = converted
        sampled = {key for key, *_ in self.campaign.sample.inputs} if self.campaign.sample else set()
        for column in list(table.columns):   # summary.csv's "plant.payload_mass_error [kg]": named as a grid
            named = re.fullmatch(r"(.+) \[([^\]]+)\]", column)   # column is, the unit in attrs
            if named and (named[1] in sampled or named[1].split("[", 1)[0] in sampled):
                table = table.rename(columns={column: named[1]})
                units[named[1]] = named[2]
        for job in self._keys.values():
            metrics = (self.store.read(job) or {}).get("metrics") if self.store.status(job) else None
            if metrics:
                units.update({f"{name} {k}": key_unit(values, k) for name, values in metrics.items()
                              for k in values if k != "unit"})
                break
        table.attrs["units"] = units
        return table

    to_pandas = table

    @property
    def labels(self) -> list[str]:
        return list(self._keys)

    def _key(self, label: str) -> str:
        if label not in self._keys:
            raise KeyError(f"no run {label!r} in campaign {self.campaign.name}")
        return self._keys[label]

    def series(self, label: str) -> dict:
        """{metric: (t, values)} of one run (a failed one: as far as it got)."""
        return self.store.series(self._key(label))

    def records(self, label: str) -> Records:
        """One run's recorded variables (the campaign must set keep_records = true)."""
        path = self.store.path(self._key(label), engine.RECORDS)
        if not path.exists():
            raise FileNotFoundError(f"run {label!r} of campaign {self.campaign.name}: no records kept "
                                    "(set keep_records = true in the campaign file)")
        return read_records(path)

    def __len__(self) -> int:
        return len(self._keys)

    @property
    def statuses(self) -> dict[str, str]:
        """{run label: its status} (scenarios/runs/status.py: ok, flagged, failed, not run)."""
        return campaigns.summary_statuses(self.summary_path)

    @property
    def ok(self) -> bool:
        """True if every run ran and nothing flagged it."""
        return all(s == run_status.OK for s in self.statuses.values())

    def __repr__(self) -> str:
        return (f"<CampaignResult {self.campaign.name!r}: {run_status.told(self.statuses.values())}, "
                f"table in {self.summary_path}>")

    def _repr_html_(self) -> str:
        """How many runs are results, then the table (its first 20 rows)."""
        table = self.table()
        said = run_status.told(table["status"])
        return (f"<p><b>Campaign {html.escape(self.campaign.name)}</b>: "
                f'<span style="{_STATUS_STYLE[run_status.worst(table["status"])]}">{html.escape(said)}</span></p>'
                + table.head(20).to_html(index=False, float_format=lambda v: f"{v:.4g}"))


@_public
def campaign(path: str | os.PathLike[str], *, out: str | os.PathLike[str] = "out", ci: bool = False,
             jobs: int | None = None, progress: bool = True) -> CampaignResult:
    """Run a campaign file as ``movingbase campaign`` does: on ``jobs`` worker processes,
    results in a store under out/<name>/ (so a campaign always writes: an interrupted one
    resumes, a finished one is read back)."""
    if engine.started_by_a_worker():     # the worker exits with the rule, not a traceback
        raise SystemExit(f"movingbase.campaign in a worker process: {engine.MAIN_GUARD}")
    _flags_given(ci=ci, progress=progress)
    warning = resources.check_jobs(jobs, "jobs")     # 0 once meant "all cores", silently
    if warning:
        print(warning, file=sys.stderr, flush=True)
    jobs = None if jobs is None else int(jobs)       # numpy's integers too
    ran, job_list, store, outcome, summary = campaigns.run_campaign(path, out, ci=ci, jobs_=jobs, progress=progress)
    runner.unlock_folder(summary.parent)
    if outcome.interrupted:   # Ctrl-C: an exception, as Python's own, not a result with runs "not run"
        raise KeyboardInterrupt(f"campaign {ran.name} interrupted: {len(outcome.computed)} runs done now and "
                                f"{len(outcome.skipped)} before are on disk in {store.folder}; call it again to resume")
    return CampaignResult(ran, job_list, store, summary)


class BudgetResult(Mapping[str, Any]):
    """What ``movingbase.budget`` returns: a geometric tolerance budget's results as a reader
    sees them. ``status`` ("ok": every target met at the probability, its interval's upper
    end below it; "flagged": not, ``flags`` say which), ``met`` per target, tables with their
    units in ``.attrs["units"]`` (``quantiles()``, ``sobol()``, ``allocation()``,
    ``leading()``), charts a notebook draws (``plot()``) and the report on disk
    (``report(out)``: <name>.json, its charts and <name>.md). It reads as the JSON's dict
    too: ``result["quantiles"]["focus"]["high"]`` (SI), as earlier versions returned it."""

    def __init__(self, data: dict[str, Any], report_path: pathlib.Path | None = None):
        self.data = data
        self.report_path = report_path
        self.status, self.flags = budget_report.status(data)

    def __getitem__(self, key: str) -> Any:
        return self.data[key]

    def __iter__(self) -> Iterator[str]:
        return iter(self.data)

    def __len__(self) -> int:
        return len(self.data)

    @property
    def name(self) -> str:
        return str(self.data["name"])

    @property
    def ok(self) -> bool:
        return self.status == "ok"

    @property
    def met(self) -> dict[str, bool]:
        """{metric: met} per target, judged on the upper end of the quantile's interval."""
        return {m: bool(q["met"]) for m, q in self.data["quantiles"].items()}

    def quantiles(self) -> pandas.DataFrame:
        """One row per target: the pose error at the probability, its interval (exact order
        statistics), the target, met, the interval's coverage; in µm (µrad for tilt), the unit
        of each row in ``.attrs["units"]`` ({"focus": "µm"}) and its "unit" column."""
        rows, units_ = {}, {}
        for metric, q in self.data["quantiles"].items():
            unit = budget_report.METRIC_UNITS[metric]
            shown = {k: budget_report.shown(q[k], unit)[0] for k in ("value", "low", "high", "target")}
            units_[metric] = budget_report.SHOWN[unit][1]
            rows[metric] = {**shown, "unit": units_[metric], "met": bool(q["met"]), "coverage": q.get("coverage")}
        table = _pandas().DataFrame.from_dict(rows, orient="index")
        table.index.name = "metric"
        table.attrs["units"] = units_
        table.attrs["probability"] = self.data["probability"]
        return table

    def sobol(self) -> pandas.DataFrame:
        """One row per (component, group): first-order and total Sobol indices with their 95 %
        bootstrap half-widths, and the first-order model's share; all shares of the variance
        (unit "1")."""
        s = self.data.get("sobol")
        if s is None:
            raise KeyError(f"budget {self.name} ran without Sobol indices (sobol_samples = 0)")
        shares = self.data.get("linear_shares", {})
        rows = {(c, g): {"first": s["first"][i][j], "first_conf": s["first_conf"][i][j], "total": s["total"][i][j],
                         "total_conf": s["total_conf"][i][j], "linear_share": shares.get(c, {}).get(g)}
                for i, c in enumerate(s["components"]) for j, g in enumerate(s["groups"])}
        table = _pandas().DataFrame.from_dict(rows, orient="index")
        table.index.names = ["component", "group"]
        table.attrs["units"] = dict.fromkeys(table.columns, "1")
        return table

    def allocation(self) -> pandas.DataFrame:
        """One row per input group: the scale factor on the file's tolerances, the tolerance as
        given and allocated (µm, or ppm for the encoder scale: each row's "unit", and
        ``.attrs["units"]``), its weight and cost (the ASSUMED model cost = weight / scale)."""
        a = self.data.get("allocation")
        if a is None:
            raise KeyError(f"budget {self.name} ran without an allocation")
        rows, units_ = {}, {}
        for group, g in a["groups"].items():
            value, unit = budget_report.shown(*g["tolerance"])
            given = budget_report.shown(*g["given"])[0] if "given" in g else value / g["scale"]
            rows[group] = {"scale": g["scale"], "given": given, "allocated": value, "unit": unit,
                           "weight": g["weight"], "cost": g["cost"]}
            units_[group] = unit
        table = _pandas().DataFrame.from_dict(rows, orient="index")
        table.index.name = "group"
        table.attrs["units"] = units_
        table.attrs["verified"] = a["verified"]
        return table

    def leading(self) -> pandas.DataFrame:
        """The inputs with the largest first-order variance shares per target (unit "1")."""
        rows = [{"metric": m, "input": name, "share": share}
                for m, leading in self.data.get("leading_inputs", {}).items() for name, share in leading]
        table = _pandas().DataFrame(rows, columns=["metric", "input", "share"])
        table.attrs["units"] = {"share": "1"}
        return table

    def plot(self) -> Charts:
        """The report's charts: each target's quantile and interval against it, the Sobol
        indices by group, the allocation (those the budget computed)."""
        return Charts(budget_report.charts(self.data).values())

    def report(self, out: str | os.PathLike[str]) -> pathlib.Path:
        """Write <out>/<name>.json, its charts (<name>_<chart>.png) and <name>.md, each whole
        or not at all; the report's path."""
        self.report_path = budget_report.write(self.data, out)
        return self.report_path

    def _said(self, metric: str, q: dict) -> tuple[str, str]:
        unit = budget_report.METRIC_UNITS[metric]
        value, low, high, target = (budget_report.shown(q[k], unit)[0] for k in ("value", "low", "high", "target"))
        u = budget_report.SHOWN[unit][1]
        return (f"{value:.3g} {u} ({low:.3g}..{high:.3g})", f"{target:g} {u}")

    def __repr__(self) -> str:
        targets = "; ".join(f"{m} {'met' if q['met'] else 'NOT met'}: {self._said(m, q)[0]} against "
                            f"{self._said(m, q)[1]}" for m, q in self.data["quantiles"].items())
        return (f"<BudgetResult {self.name!r}: {self.status}, at {budget_report.percent(self.data['probability'])} "
                f"({self.data['samples']:,d} samples): {targets}>")

    def _repr_html_(self) -> str:
        """The status and each target met or not first, then the leading inputs and the
        allocation's factors."""
        probability = budget_report.percent(self.data["probability"])
        rows = [[m, "met" if q["met"] else "NOT met", *self._said(m, q), f"{q.get('coverage', 0.95):.3f}"]
                for m, q in self.data["quantiles"].items()]
        head = ["metric", "verdict", f"at {probability} (interval)", "target", "coverage"]
        said = "every target met" if self.ok else "; ".join(self.flags)
        parts = [f"<p><b>Budget {html.escape(self.name)}</b>: {self.data['samples']:,d} samples, "
                 f'<span style="{_STATUS_STYLE["ok" if self.ok else "flagged"]}">{self.status}: '
                 f"{html.escape(said)}</span></p>", _html_table(head, rows)]
        if "allocation" in self.data:
            a = self.data["allocation"]
            parts.append(f"<p>allocation: cost {a['cost']:.3g} against {a['cost_as_given']:.3g} as given, checked: "
                         f"{'met' if a['verified'] else 'NOT met'}</p>" + _html_table(
                             ["group", "scale", "tolerance"], [[g, f"x{v['scale']:.3f}", "{:.4g} {}".format(
                                 *budget_report.shown(*v["tolerance"]))] for g, v in a["groups"].items()]))
        return "".join(parts)


@_public
def budget(path: str | os.PathLike[str], *, samples: int | None = None, out: str | os.PathLike[str] | None = None,
           progress: bool = True) -> BudgetResult:
    """Run a geometric tolerance budget file (or a shipped name: ``"default"``, ``"nanshan"``) as
    ``movingbase budget`` does: the pose error's quantile per target with its exact 95 %
    interval, Sobol indices by input group with their intervals, the leading inputs and the
    allocation (scenarios/runs/budget.py says what each holds), as a BudgetResult. ``samples``
    (any integer) overrides the file's Monte Carlo draws; ``out`` writes <out>/<name>.json, its
    charts and <name>.md. The cost is told before it runs (with ``progress``). No FMU runs:
    the kinematics alone."""
    from scenarios.runs.budget import run_budget
    _flags_given(progress=progress)
    data = run_budget(path, samples=samples, out=out, progress=progress)
    return BudgetResult(data, pathlib.Path(out) / f"{data['name']}.md" if out is not None else None)


@_public
def regress(scenarios: str | os.PathLike[str] | Sequence[str | os.PathLike[str]], *,
            baseline: str | os.PathLike[str], update: bool = False, ci: bool = False,
            tolerances: Mapping[str, str] | None = None, time_tolerance: str | float = 0.0,
            junit: str | os.PathLike[str] | None = None, report: str | os.PathLike[str] | None = None,
            jobs: int | None = None, fmi_version: int | None = None, progress: bool = True,
            signals: Sequence[str] | None = None) -> Any:
    """Hold scenario files as ``movingbase regress`` does: re-run each and compare it with
    its baseline in the folder ``baseline`` (signals within their tubes, metrics within
    their tolerances, status and flags unchanged), or with ``update`` store the baselines.
    ``tolerances`` overrides one metric number or signal each, with units
    (``{"pose error peak": "0.5 µm", "plant.pose": "1 um"}``); ``time_tolerance`` widens
    the tubes in time ("5 ms"); ``signals`` (with ``update``) the recorded variables to
    store instead of those the metrics read; ``junit`` and ``report`` write the JUnit file and the
    Markdown report. Returns a Regression: ``.passed``, ``.exit_code`` (0 pass, 1 a
    regression, 2 could not run), ``.findings()``, and its summary as its repr."""
    from scenarios.output.regress_report import write_junit, write_report
    from scenarios.runs import regress as regression
    _flags_given(update=update, ci=ci, progress=progress)
    try:
        time_tol = units.to_si(time_tolerance, "s")
    except UnitError as exc:
        raise regression.BaselineError(f"time_tolerance: {exc}") from None
    outcome = regression.regress(scenarios, baseline, update, ci, tolerances, time_tol, jobs, None, fmi_version,
                                 progress, signals)
    if junit is not None:
        write_junit(outcome, junit)
    if report is not None:
        write_report(outcome, report)
    return outcome
