"""Scenes held in CI: a baseline per scenario file and run (the signals its metrics read,
the metrics, status, flags, provenance and tolerances), and the comparison of a new run
with it (``movingbase regress``).

Each tolerance is sized from the run's own numerical error, as the kit's golden metrics
always were (and its shipped scenes' baselines, tests/golden/regress, are): twice the
change when every plant's integrator step is halved, floored for rounding across
processors (RELATIVE, FLOOR). A signal is compared within a tube in time and value: the
funnel of BuildingsPy's pyfunnel (each baseline point widened by the time tolerance, then
by the value tolerance), computed here on the kit's fixed record grid (``tube``; pyfunnel
ships a prebuilt library and talks through CSV files in a folder, for a comparison that
is a sliding maximum here).
"""
import dataclasses
import hashlib
import importlib.metadata
import json
import math
import os
import pathlib
import platform
import shutil
import sys
import tempfile
import time

import numpy as np

from scenarios import spec
from scenarios.cosim.fmi import FmuFileError, content_digest
from scenarios.cosim.records import read_records
from scenarios.runs import runner
from scenarios.runs.engine import EngineError
from scenarios.runs.estimates import ResourceError
from scenarios.runs.metrics import key_unit
from scenarios.spec import units

# Floors of a tolerance, for rounding across processors (glibc picks its FMA or SSE2 sin,
# cos and exp by the processor: last bits apart). Measured on telescope_slew [ci]
# (tests/scenarios/runs/test_regress.py pins it): the lever arm moved by one ulp moves a
# metric or a metric's series by at most 7e-10 of its value, a signal by at most 4e-13 of
# its variable's largest |value| where the change is above SI_FLOOR. The floors leave a
# margin of 100 or more over that, and sit decades under the smallest planted change the
# tests catch (the payload mass by 1 %).
RELATIVE = 1e-7          # of a metric's value, or of the largest |value| of a metric's series
SIGNAL_RELATIVE = 1e-10  # of the largest |value| of a signal's variable (its components of one unit)
FLOOR = 1e-6             # in a metric's unit: 1 pm, 1 prad, 1 mN, 1e-6 arcsec, 1e-6 %
SI_FLOOR = 1e-12         # of a signal, SI: 1 pm, 1 prad, 1 pN (a variable that stays near zero)
MAX_ROWS = 1000    # rows of a signal kept in a baseline (every k-th row beyond): files stay small
FORMAT = 1         # of baseline.json: a later kit reading an earlier file knows what it holds


class BaselineError(ValueError):
    """A baseline that cannot be used (missing, of another length, not the kit's)."""


@dataclasses.dataclass
class Finding:
    """One thing outside its tolerance: a signal (``kind`` "signal"), a metric, the status
    or the flags. ``first``: first time outside the tube [s]; ``excursion``: the largest
    distance beyond the tube's edge, at ``worst`` [s]; ``old``/``new`` the values compared;
    ``curve``: the signal or metric series it is drawn on ("" if none)."""

    kind: str
    name: str
    text: str
    first: float = math.nan
    worst: float = math.nan
    excursion: float = math.nan
    unit: str = ""
    old: object = None
    new: object = None
    tolerance: float = math.nan
    curve: str = ""


@dataclasses.dataclass
class RunOutcome:
    """A run compared with its baseline: its findings (empty: it passed) and what was
    compared, for the report's charts (``curves``: name -> (time, baseline, lower, upper,
    new time, new values, unit))."""

    label: str
    findings: list
    compared: int
    curves: dict = dataclasses.field(default_factory=dict)


@dataclasses.dataclass
class SceneOutcome:
    """A scenario compared (``runs``), recorded (``updated``: what changed against the
    baseline it replaced, or None for a first one) or not run (``error``)."""

    name: str
    source: str
    runs: list = dataclasses.field(default_factory=list)
    error: str = ""
    updated: list | None = None
    notes: list = dataclasses.field(default_factory=list)
    wall_time: float = 0.0

    @property
    def verdict(self):
        """"error" (could not run), "regression" or "pass"."""
        return "error" if self.error else "regression" if any(r.findings for r in self.runs) else "pass"


# ------------------------------------------------------------------------ the tube
def tube(t, y, value_tol, time_tol=0.0):
    """(lower, upper) of the tube around the baseline (t, y) at its own times: each point
    widened by ``time_tol`` in time (the largest and smallest y within +-time_tol) and
    then by ``value_tol`` (a number or one per point) in value, as pyfunnel's funnel."""
    t, y = np.asarray(t, float), np.asarray(y, float)
    high, low = y.copy(), y.copy()
    if time_tol > 0 and len(t) > 1:
        first = np.searchsorted(t, t - time_tol, "left")
        last = np.searchsorted(t, t + time_tol, "right") - 1
        index = np.arange(len(t))
        for shift in range(1, int(max((index - first).max(), (last - index).max())) + 1):
            for other in (index - shift, index + shift):
                within = (other >= first) & (other <= last)
                high[within] = np.fmax(high[within], y[other[within]])
                low[within] = np.fmin(low[within], y[other[within]])
    return low - value_tol, high + value_tol


def outside(t, low, high, t_new, y_new):
    """How the new curve (t_new, y_new), taken at the tube's times t, leaves the tube:
    (distance beyond its edge per point, 0 inside). A time the new curve does not reach
    (it ended early) counts as infinitely far; NaN against a finite tube too."""
    t_new, y_new = np.asarray(t_new, float), np.asarray(y_new, float)
    at = np.interp(t, t_new, y_new) if len(t_new) else np.full(len(t), np.nan)
    if len(t_new):
        at[(t > t_new[-1] + 1e-9 * max(1.0, abs(t_new[-1]))) | (t < t_new[0] - 1e-9)] = np.nan
    beyond = np.fmax(at - high, low - at)
    both_nan = np.isnan(at) & np.isnan(high)
    return np.where(both_nan, 0.0, np.where(np.isnan(beyond), np.inf, np.maximum(beyond, 0.0)))


# ------------------------------------------------------------------------ what a run holds
def series_of(run):
    """{name: (time, values, unit)}: the run's metric series (each metric's error against
    time, in the metric's unit: "pose error" µm, "pose error rotation" µrad)."""
    found = {}
    for name, (t, v) in run.series.items():
        metric, key = metric_of(name, run.metrics)
        if metric is not None:
            found[name] = (np.asarray(t, float), np.asarray(v, float), key_unit(run.metrics[metric], key))
    return found


def metric_of(series_name, metrics):
    """(metric, key) whose unit a metric series is in: "pose error rotation" -> ("pose
    error", "rotation_peak"); (None, None) if no metric has it."""
    for suffix, key in ((" rotation", "rotation_peak"), (" path", "path_peak")):
        if series_name.endswith(suffix) and series_name[:-len(suffix)] in metrics:
            return series_name[:-len(suffix)], key
    return (series_name, "peak") if series_name in metrics else (None, None)


def series_for(metric, key):
    """The series a metric's number is taken from (metric_of reversed)."""
    return metric + (" rotation" if key.startswith("rotation") else
                     " path" if key.startswith(("path", "efficiency")) else "")


def read_variables(scenario):
    """The variables the scenario's metrics read ("plant.pose", "base.reference_pose")."""
    return list(dict.fromkeys(v for m in scenario.metrics for v in m.args.values()
                              if isinstance(v, str) and "." in v and not v.startswith("@")))


def signals_of(run, names):
    """{column: (time, values, unit)} of the run's recorded columns of the variables
    ``names`` (a vector by its name: every component)."""
    records = run.records
    if records is None:
        return {}
    found = {}
    for column, unit in zip(records.names, records.units):
        if column in names or column.split("[", 1)[0] in names:
            found[column] = (records.time, records[column], unit)
    return found


def thinned(count):
    """The row indices a baseline keeps of ``count`` rows: every k-th, and the last."""
    stride = max(1, math.ceil(count / MAX_ROWS))
    rows = np.arange(0, count, stride)
    return np.union1d(rows, [count - 1]) if count else rows


# ------------------------------------------------------------------------ tolerances
def metric_tolerance(value, finer):
    """Twice the change of a metric when the plant's step is halved, floored (RELATIVE of
    the value, FLOOR); NaN where the metric is NaN (nothing counted: it must stay so)."""
    if value is None or finer is None or not (math.isfinite(value) and math.isfinite(finer)):
        return math.nan
    return 2 * max(abs(value - finer), RELATIVE * abs(value), FLOOR)


def signal_tolerances(base, fine, relative, floor):
    """{name: tolerance} of each signal: twice its largest change when the plant's step is
    halved (at the baseline's times), floored at ``relative`` of the largest |value| of its
    variable (a vector's components of one unit share it: a pose's metres, its radians)
    and at ``floor``."""
    scale = {}
    for name, (_, v, unit) in base.items():
        group = (name.split("[", 1)[0], unit)
        scale[group] = max(scale.get(group, 0.0), float(np.nanmax(np.abs(v), initial=0.0)))
    tolerances = {}
    for name, (t, v, unit) in base.items():
        change = 0.0
        if name in fine:
            tf, vf, _ = fine[name]
            n = min(len(t), len(tf))
            change = float(np.nanmax(np.abs(v[:n] - np.interp(t[:n], tf, vf)), initial=0.0))
        tolerances[name] = 2 * max(change, relative * scale[name.split("[", 1)[0], unit], floor)
    return tolerances


def halved(scenario, descriptions, values):
    """The bound values with every plant's integrator step (parameter max_step) halved,
    and the instances changed; the FMU's default where the file sets none."""
    finer = {inst: dict(v) for inst, v in values.items()}
    changed = []
    for inst, md in descriptions.items():
        variable = next((v for v in md.modelVariables if v.name == "max_step"), None)
        if variable is None:
            continue
        step = finer[inst].get("max_step", float(variable.start))
        finer[inst]["max_step"] = step / 2
        changed.append(inst)
    return finer, changed


# ------------------------------------------------------------------------ overrides
def parse_override(text):
    """("name", "key" or None, "quantity") of a tolerance override as a user writes it:
    "pose error peak = 0.5 µm", "plant.pose = 1 um", "pointing rms=0.01 arcsec"."""
    if not isinstance(text, str) or "=" not in text:
        raise BaselineError(f"tolerance {text!r}: write 'NAME = QUANTITY', e.g. 'pose error peak = 0.5 µm' "
                            "or 'plant.pose = 1 um'")
    name, quantity = (part.strip() for part in text.split("=", 1))
    if not name or not quantity:
        raise BaselineError(f"tolerance {text!r}: write 'NAME = QUANTITY', e.g. 'pose error peak = 0.5 µm'")
    return name, quantity


def apply_overrides(overrides, metric_tols, signal_tols, metrics, signal_units, where):
    """Replace the tolerances ``overrides`` ({name: quantity}) name, each converted to the
    unit of what it names (a metric's number: "pose error peak"; a signal or a vector
    variable: "plant.pose", its SI unit; a metric's series: "pose error"). BaselineError
    naming an unknown name or a unit of the wrong dimension."""
    for name, quantity in overrides.items():
        done = False
        for metric, values in metrics.items():
            for key in values:
                if key != "unit" and name == f"{metric} {key}":
                    metric_tols[metric][key] = _converted(quantity, key_unit(values, key), name, where)
                    done = True
        for column, unit in signal_units.items():
            if name == column or name == column.split("[", 1)[0]:
                signal_tols[column] = _converted(quantity, unit, name, where)
                done = True
        if not done:
            known = [f"{m} {k}" for m, values in metrics.items() for k in values if k != "unit"]
            known += list(dict.fromkeys(c.split("[", 1)[0] for c in signal_units))
            raise BaselineError(f"{where}: tolerance {name!r}: no metric number, series or recorded signal of that "
                                f"name; known: {', '.join(known)}")


def _converted(quantity, unit, name, where):
    try:
        value = units.in_unit(quantity, unit)
    except units.UnitError as exc:
        raise BaselineError(f"{where}: tolerance {name!r}: {exc}") from None
    if not value > 0:
        raise BaselineError(f"{where}: tolerance {name!r}: must be positive, got {quantity!r}")
    return value


# ------------------------------------------------------------------------ provenance
def provenance(scenario, paths, descriptions, values, ci):
    """What a baseline was made with: the kit's version, each FMU's GUID and checksum (of
    what decides its numbers, fmi.content_digest), the parameters as bound, the master's
    settings and the platform."""
    try:
        version = importlib.metadata.version("movingbase")
    except importlib.metadata.PackageNotFoundError:
        version = "unknown"
    return {
        "kit": version,
        "fmus": {inst: {"fmu": scenario.fmus[inst], "file": pathlib.Path(path).name,
                        "fmi": descriptions[inst].fmiVersion, "guid": descriptions[inst].guid,
                        "checksum": content_digest(path)} for inst, path in paths.items()},
        "parameters": {inst: {k: (f"@{v.instance}.{v.variable}" if isinstance(v, spec.Link) else v)
                              for k, v in params.items()} for inst, params in values.items()},
        "master": {"master": scenario.master, "extrapolation": scenario.extrapolation, "step": scenario.step,
                   "start_time": scenario.start_time, "stop_time": scenario.stop_time,
                   "record_interval": scenario.record_interval, "ci": bool(ci)},
        "platform": {"system": platform.platform(), "machine": platform.machine(),
                     "python": sys.version.split()[0], "numpy": np.__version__},
        "scenario_sha256": hashlib.sha256(pathlib.Path(scenario.source).read_bytes()).hexdigest()
        if pathlib.Path(scenario.source).is_file() else None,
    }


# ------------------------------------------------------------------------ a baseline on disk
def folder_of(baseline, source):
    """baseline/<the scenario file's stem>: one folder per scenario file."""
    return pathlib.Path(baseline) / pathlib.Path(source).stem


def status_of(run):
    """The shared status word of a run: failed (cut short), flagged or ok."""
    return "failed" if run.failure else "flagged" if run.flags else "ok"


def _run_data(run, signals, series, metric_tols, signal_tols):
    return {"status": status_of(run), "flags": sorted({f.kind for f in run.flags}),
            "flag_messages": [f"{f.kind}: {f.message}" for f in run.flags], "failure": run.failure or "",
            "metrics": _plain(run.metrics),
            "tolerances": {"metrics": _plain(metric_tols), "signals": _plain(signal_tols)},
            "units": {name: unit for name, (_, _, unit) in {**signals, **series}.items()},
            "series": list(series), "signals": list(signals)}


def _arrays(signals, series):
    """The npz arrays of a run's baseline: each signal and series at its kept rows; the
    signals' times once (they are the records' rows: a third of the file, stored 30 times)."""
    arrays = {}
    for k, (name, (t, v, _)) in enumerate(signals.items()):
        keep = thinned(len(t))
        arrays["signal_t"], arrays[f"signal{k}_v"] = np.asarray(t)[keep], np.asarray(v)[keep]
    for k, (name, (t, v, _)) in enumerate(series.items()):
        keep = thinned(len(t))
        arrays[f"series{k}_t"], arrays[f"series{k}_v"] = np.asarray(t)[keep], np.asarray(v)[keep]
    return arrays


def _plain(value):
    """JSON of numbers: NaN as null (JSON has none), numpy numbers as floats."""
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    if isinstance(value, (float, np.floating)):
        return None if not math.isfinite(value) else float(value)
    return value


def _number(value):
    return math.nan if value is None else value


def read_baseline(baseline, source):
    """(baseline.json's data, {label: {name: (t, v)}}) of a scenario's stored baseline;
    BaselineError if there is none or it is not the kit's."""
    folder = folder_of(baseline, source)
    path = folder / "baseline.json"
    if not path.is_file():
        raise BaselineError(f"no baseline for {pathlib.Path(source).stem} in {baseline} (no {path}); make one with "
                            f"movingbase regress {spec.shown(source)} --baseline {baseline} --update")
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
        curves = {}
        for label, run in data["runs"].items():
            with np.load(folder / f"{spec.file_label(label)}.npz") as arrays:
                curves[label] = {name: (arrays["signal_t"], arrays[f"signal{k}_v"])
                                 for k, name in enumerate(run["signals"])}
                curves[label].update({name: (arrays[f"series{k}_t"], arrays[f"series{k}_v"])
                                      for k, name in enumerate(run["series"])})
    except (OSError, ValueError, KeyError) as exc:
        raise BaselineError(f"baseline {folder}: cannot be read ({exc}); make it again with --update") from None
    if data.get("format") != FORMAT:
        raise BaselineError(f"baseline {folder}: format {data.get('format')!r}, this kit reads {FORMAT}; "
                            "make it again with --update")
    return data, curves


def write_baseline(baseline, scenario, runs, finer, prov, overrides, signals=None):
    """Store the baseline of ``runs`` (their tolerances from ``finer``, the same runs at
    half the plant's step) as baseline/<stem>/: baseline.json and one compressed npz per
    run; the recorded variables ``signals`` ("plant.pose") or, without them, those the
    metrics read. Everything is computed (and the overrides checked) first, the files written into
    a new folder beside it, which then takes the old one's place: a reader finds the old
    baseline or the new one, never a mix."""
    target = folder_of(baseline, scenario.source)
    runner.make_folder(target.parent)
    by_label = {r.label: r for r in finer}
    variables = list(signals) if signals else read_variables(scenario)
    recorded = {c.split("[", 1)[0] for r in runs if r.records is not None for c in r.records.names}
    missing = [v for v in variables if recorded and v not in recorded]
    if missing:
        raise BaselineError(f"scenario {scenario.name}: signal {missing[0]!r} is not recorded; recorded: "
                            f"{', '.join(sorted(recorded))} (add it to [record] variables)")
    data = {"format": FORMAT, "scene": scenario.name, "source": pathlib.Path(scenario.source).name, "provenance": prov,
            "overrides": dict(overrides), "rule": f"tolerance = 2 x the change with every plant's max_step halved, "
                                                  f"at least {RELATIVE:g} of the value and {FLOOR:g} in a metric's "
                                                  f"unit (a signal: {SIGNAL_RELATIVE:g} of its variable's "
                                                  f"largest value and {SI_FLOOR:g} SI)", "runs": {}}
    files = {}
    for run in runs:
        fine = by_label.get(run.label)
        signals, series = signals_of(run, variables), series_of(run)
        metric_tols = {m: {k: metric_tolerance(v, _finer_metric(fine, m, k)) for k, v in values.items() if k != "unit"}
                       for m, values in run.metrics.items()}
        signal_tols = signal_tolerances(signals, signals_of(fine, variables) if fine else {},
                                        SIGNAL_RELATIVE, SI_FLOOR)
        signal_tols.update(signal_tolerances(series, series_of(fine) if fine else {}, RELATIVE, FLOOR))
        apply_overrides(overrides, metric_tols, signal_tols, run.metrics,
                        {n: u for n, (_, _, u) in {**signals, **series}.items()}, f"scenario {scenario.name}")
        data["runs"][run.label] = _run_data(run, signals, series, metric_tols, signal_tols)
        files[f"{spec.file_label(run.label)}.npz"] = _arrays(signals, series)
    fresh, old = (target.with_name(f".{target.name}.{os.getpid()}.{end}") for end in ("new", "old"))
    try:
        fresh.mkdir()
        for name, arrays in files.items():
            np.savez_compressed(fresh / name, **arrays)
        (fresh / "baseline.json").write_text(json.dumps(_plain(data), indent=1, ensure_ascii=False) + "\n",
                                             encoding="utf-8")
        if target.exists():
            os.replace(target, old)
        try:
            os.replace(fresh, target)
        except BaseException:
            if old.exists():
                os.replace(old, target)     # the old baseline back in its place
            raise
    finally:
        shutil.rmtree(fresh, ignore_errors=True)
    shutil.rmtree(old, ignore_errors=True)
    return target


def _finer_metric(fine, metric, key):
    if fine is None:
        return None
    return fine.metrics.get(metric, {}).get(key)


# ------------------------------------------------------------------------ comparing
def compare_run(stored, curves, run, overrides=None, time_tol=0.0, where=""):
    """The findings of ``run`` against its stored baseline (``stored``: baseline.json's run,
    ``curves``: its signals): status and flags unchanged, each metric within its tolerance,
    each signal and series within its tube. Ordered by the first time outside."""
    findings, shown = [], {}
    metric_tols = {m: {k: _number(v) for k, v in tols.items()} for m, tols in stored["tolerances"]["metrics"].items()}
    signal_tols = {n: _number(v) for n, v in stored["tolerances"]["signals"].items()}
    if overrides:
        apply_overrides(overrides, metric_tols, signal_tols, stored["metrics"], stored["units"], where)
    status = status_of(run)
    if status != stored["status"]:
        said = run.failure or "; ".join(f"{f.kind}: {f.message}" for f in run.flags)
        findings.append(Finding("status", "status", f"status {stored['status']} -> {status}"
                                + (f" ({said})" if said else ""), old=stored["status"], new=status))
    kinds = sorted({f.kind for f in run.flags})
    if kinds != stored["flags"] and status == stored["status"]:
        findings.append(Finding("flags", "flags", f"flags {', '.join(stored['flags']) or 'none'} -> "
                                f"{', '.join(kinds) or 'none'}", old=stored["flags"], new=kinds))
    new_curves = {**{n: (t, v) for n, (t, v, _) in signals_of(run, set(n.split("[", 1)[0]
                                                                       for n in stored["signals"])).items()},
                  **{n: (t, v) for n, (t, v, _) in series_of(run).items()}}
    firsts, groups = {}, {}
    for name, (t, y) in curves.items():
        tol = signal_tols.get(name, math.nan)
        unit = stored["units"].get(name, "")
        new = new_curves.get(name)
        low, high = tube(t, y, tol, time_tol)
        beyond = outside(t, low, high, *(new if new is not None else ((), ())))
        shown[name] = (t, y, low, high, *(new if new is not None else (np.array([]), np.array([]))), unit)
        if not beyond.any():
            continue
        first, worst = int(np.argmax(beyond > 0)), int(np.argmax(beyond))
        firsts[name] = float(t[first])
        if name in stored["series"]:
            continue   # told with its metric (below), or alone if its numbers stayed within
        groups.setdefault((name.split("[", 1)[0], unit), []).append(
            _signal_finding(name, t, beyond, first, worst, unit, tol))
    for (variable, unit), group in groups.items():   # a vector's components of one unit told once
        finding = min(group, key=lambda f: (f.first, -f.excursion / max(f.tolerance, 1e-300)))
        if len(group) > 1:
            worst = max(group, key=lambda f: f.excursion / max(f.tolerance, 1e-300))
            finding = dataclasses.replace(worst, first=finding.first,
                                          text=_group_text(variable, group, finding, worst))
        findings.append(finding)
    for metric, values in stored["metrics"].items():
        for key, old in values.items():
            if key == "unit":
                continue
            new = run.metrics.get(metric, {}).get(key)
            tol = metric_tols.get(metric, {}).get(key, math.nan)
            unit = key_unit(values, key)
            if _metric_within(_number(old), _number(new), tol):
                continue
            first = firsts.get(series_for(metric, key), math.nan)
            findings.append(Finding("metric", f"{metric} {key}", _metric_text(metric, key, old, new, unit, tol, first),
                                    first=first, unit=unit, old=old, new=new, tolerance=tol,
                                    curve=series_for(metric, key)))
    told = {f.curve for f in findings if f.kind == "metric"}
    for name in stored["series"]:
        if name in firsts and name not in told:
            t, y, low, high, tn, yn, unit = shown[name]
            beyond = outside(t, low, high, tn, yn)
            findings.append(_signal_finding(name, t, beyond, int(np.argmax(beyond > 0)), int(np.argmax(beyond)),
                                            unit, signal_tols.get(name, math.nan)))
    order = {"status": 0, "flags": 1, "requirement": 2}
    findings.sort(key=lambda f: (order.get(f.kind, 3), f.first if math.isfinite(f.first) else math.inf,
                                 f.kind != "metric"))   # at one time, the metric (the domain's terms) first
    return RunOutcome(run.label, findings, len(curves) + sum(len(v) - 1 for v in stored["metrics"].values()),
                      {f.curve: shown[f.curve] for f in findings if f.curve in shown})


def _group_text(variable, group, first, worst):
    """One line for a vector's components outside their tubes: when the first left, which
    went farthest (relative to its tube) and by how much."""
    far = "ended before the baseline" if math.isinf(worst.excursion) else \
        f"largest excursion {worst.excursion:.3g} {worst.unit} beyond its tube"
    return (f"{variable} ({', '.join(f.name[len(variable):] for f in group)}) first outside its tube at "
            f"t = {first.first:.4g} s ({first.name}); {worst.name}: {far} at t = {worst.worst:.4g} s "
            f"(tube +-{worst.tolerance:.3g} {worst.unit})")


def _metric_within(old, new, tol):
    if math.isnan(old) or math.isnan(new):
        return math.isnan(old) and math.isnan(new)
    return abs(new - old) <= tol


def _signal_finding(name, t, beyond, first, worst, unit, tol):
    excursion = float(beyond[worst])
    said = "ended before" if math.isinf(excursion) else f"largest excursion {excursion:.3g} {unit} beyond it"
    return Finding("signal", name, f"{name} first outside its tube at t = {t[first]:.4g} s, {said} at "
                   f"t = {t[worst]:.4g} s (tube +-{tol:.3g} {unit})", first=float(t[first]), worst=float(t[worst]),
                   excursion=excursion, unit=unit, tolerance=tol, curve=name)


def _metric_text(metric, key, old, new, unit, tol, first):
    """'pose error peak +12 % (0.953 -> 1.07 µm), first outside its tube at t = 23.4 s'."""
    if old is None or new is None:
        change = f"{_shown(old)} -> {_shown(new)} {unit}"
    else:
        relative = f"{100 * (new - old) / abs(old):+.3g} %" if old else f"{new - old:+.3g} {unit}"
        change = f"{relative} ({_shown(old)} -> {_shown(new)} {unit}; tolerance {tol:.2g} {unit})"
    where = f", first outside its tube at t = {first:.4g} s" if math.isfinite(first) else ""
    return f"{metric} {key} {change}{where}"


def _shown(value):
    """A metric's number with as many digits as it takes to see a small change."""
    return "n/a" if value is None or value != value else f"{value:.6g}"


def requirement_findings(scenario, run):
    """A finding per requirement of the file that ``run`` does not meet."""
    return [Finding("requirement", j["requirement"], f"requirement {j['requirement']} NOT MET: "
                    + ("not counted" if j["value"] is None else f"{j['value']:.4g} {j['unit']}"),
                    unit=j["unit"], new=j["value"])
            for j in spec.judge(scenario.requirements, run.label, run.metrics) if not j["met"]]


def _said(value):
    """A parameter's value as bound, or the FMU's default where the file set none."""
    return "(the FMU's default)" if value is None else repr(value)


def describe_changes(data, prov):
    """Lines saying what differs between a stored baseline's provenance and a new one."""
    old = data.get("provenance", {})
    lines = []
    if old.get("kit") != prov["kit"]:
        lines.append(f"kit {old.get('kit')} -> {prov['kit']}")
    for inst, fmu in prov["fmus"].items():
        before = old.get("fmus", {}).get(inst)
        if before is None:
            lines.append(f"FMU {inst}: new ({fmu['fmu']})")
        elif before.get("checksum") != fmu["checksum"]:
            lines.append(f"FMU {inst} ({fmu['fmu']}): rebuilt from other sources (checksum "
                         f"{before.get('checksum', '')[:12]} -> {fmu['checksum'][:12]})")
    for inst, params in prov["parameters"].items():
        before = old.get("parameters", {}).get(inst, {})
        for key, value in params.items():
            if before.get(key) != value:
                lines.append(f"{inst}.{key} {_said(before.get(key))} -> {_said(value)}")
    for key, value in prov["master"].items():
        if old.get("master", {}).get(key) != value:
            lines.append(f"{key} {old.get('master', {}).get(key)!r} -> {value!r}")
    if old.get("platform") != prov["platform"]:
        lines.append(f"platform {old.get('platform', {}).get('system')} -> {prov['platform']['system']}")
    return lines


# ------------------------------------------------------------------------ a scenario
def regress_scene(name, baseline, update=False, ci=False, overrides=None, time_tol=0.0, jobs=None,
                  implementation=None, fmi_version=None, progress=False, signals=None):
    """Compare one scenario file's runs with its baseline, or (``update``) record the
    baseline anew, saying first what changed against the one it replaces. A SceneOutcome;
    anything that keeps it from running is its ``error``."""
    began = time.perf_counter()
    path = runner.resolve(name)
    outcome = SceneOutcome(pathlib.Path(name).stem, str(path))
    try:
        if not path.is_file():
            raise BaselineError(runner.not_found([name]))
        stored = None
        if not update or (folder_of(baseline, path) / "baseline.json").is_file():
            try:
                stored = read_baseline(baseline, path)
            except BaselineError:
                if not update:
                    raise
        if stored is not None and bool(stored[0]["provenance"]["master"]["ci"]) != bool(ci) and not update:
            length = "[ci]" if stored[0]["provenance"]["master"]["ci"] else "full"
            raise BaselineError(f"baseline {folder_of(baseline, path)} holds the {length} runs; run with"
                                f"{'out' if length == 'full' else ''} --ci, or --update")
        with runner.announcing_builds(progress):
            scenario, paths, descriptions, values = runner.prepare(path, ci, implementation, None, fmi_version)
        outcome.name = scenario.name
        before = runner.pre_run_flags(scenario, paths, descriptions, values, ci)
        runs = _run(scenario, paths, descriptions, values, progress, jobs, before)
        prov = provenance(scenario, paths, descriptions, values, ci)
        if stored is not None:
            data, curves = stored
            outcome.notes = describe_changes(data, prov)
            compared = []
            for run in runs:
                if run.label not in data["runs"]:
                    compared.append(RunOutcome(run.label, [Finding("status", "run", "a run the baseline does not "
                                                                   "hold")] if not update else [], 0))
                    continue
                compared.append(compare_run(data["runs"][run.label], curves[run.label], run, overrides, time_tol,
                                            f"scenario {scenario.name}, run {run.label}"))
            gone = [label for label in data["runs"] if label not in {r.label for r in runs}]
            compared += [RunOutcome(label, [Finding("status", "run", "the baseline's run is no longer in the "
                                                    "scenario")], 0) for label in gone]
            if update:
                outcome.updated = compared
            else:
                outcome.runs = compared
        if update:
            finer_values, changed = halved(scenario, descriptions, values)
            if not changed:
                outcome.notes.append("no plant integrator step (max_step) to halve: tolerances are the floors")
            finer = _run(scenario, paths, descriptions, finer_values, progress, jobs, before) if changed else []
            write_baseline(baseline, scenario, runs, finer, prov, overrides or {}, signals)
            outcome.runs = [RunOutcome(r.label, [], 0) for r in runs]
        for run, told in zip(runs, outcome.runs):   # the file's absolute specs, whatever the baseline says
            told.findings[:0] = requirement_findings(scenario, run)
    except (spec.ScenarioError, BaselineError, runner.OutputError, FmuFileError, ResourceError, EngineError,
            OSError) as exc:
        outcome.error = f"{exc.filename}: {exc.strerror}" if isinstance(exc, OSError) and exc.filename else str(exc)
    outcome.wall_time = time.perf_counter() - began
    return outcome



def _run(scenario, paths, descriptions, values, progress, jobs, before):
    """The scenario's runs, in memory; with ``jobs`` on worker processes, whose records
    pass through a temporary folder (the engine's store is on disk)."""
    if not jobs:
        return runner.run_prepared(scenario, paths, descriptions, values, None, progress, None, None, before)
    with tempfile.TemporaryDirectory(prefix="movingbase-regress-") as scratch:
        runs = runner.run_prepared(scenario, paths, descriptions, values, pathlib.Path(scratch), progress, jobs, None,
                                   before)
        for run in runs:
            if run.records is None and run.record_path:
                run.records = read_records(run.record_path)
        return runs


# ------------------------------------------------------------------------ many scenarios
@dataclasses.dataclass
class Regression:
    """What ``movingbase regress`` found over its scenario files: one SceneOutcome each,
    the exit code (0 pass, 1 a regression, 2 a scenario that could not run) and the
    terminal summary."""

    scenes: list
    baseline: str
    update: bool = False

    @property
    def exit_code(self):
        verdicts = {s.verdict for s in self.scenes}
        return 2 if "error" in verdicts else 1 if "regression" in verdicts else 0

    @property
    def passed(self):
        return self.exit_code == 0

    def findings(self):
        """(scene, run, Finding) of every finding, in the order the summary tells them."""
        return [(s.name, r.label, f) for s in self.scenes for r in s.runs for f in r.findings]

    def summary(self, most=5):
        """The terminal summary: per scene its verdict, per regressed run its ``most`` first
        findings (first outside its tube first), what changed since the baseline."""
        lines = []
        for scene in self.scenes:
            if scene.error:
                lines.append(f"{scene.name}: COULD NOT RUN: {scene.error}")
                continue
            if self.update:
                lines.append(f"{scene.name}: baseline written to {folder_of(self.baseline, scene.source)} "
                             f"({len(scene.runs)} run{'s' * (len(scene.runs) != 1)}, {scene.wall_time:.1f} s)")
                changed = [(r.label, f) for r in scene.updated or [] for f in r.findings]
                if scene.updated is not None:
                    lines.append(f"  it replaced a baseline; {len(changed) or 'nothing'} outside the old tolerances"
                                 + (":" if changed else ""))
                lines += [f"    {label}: {f.text}" for label, f in changed[:most * 2]]
                lines += [f"  changed since: {note}" for note in scene.notes]
                lines += [f"  {run.label}: {f.text}" for run in scene.runs for f in run.findings]   # requirements
                continue
            bad = [r for r in scene.runs if r.findings]
            lines.append(f"{scene.name}: {'REGRESSION' if bad else 'pass'} ({len(scene.runs)} run"
                         f"{'s' * (len(scene.runs) != 1)}"
                         f"{f', {len(bad)} regressed' if bad else ''}; {scene.wall_time:.1f} s)")
            for run in scene.runs:
                if not run.findings:
                    continue
                for k, finding in enumerate(run.findings[:most]):
                    lines.append(f"  {run.label if k == 0 else ' ' * len(run.label)}: {finding.text}")
                if len(run.findings) > most:
                    lines.append(f"  {' ' * len(run.label)}  and {len(run.findings) - most} more (--report)")
            if bad:
                lines += [f"  changed since the baseline: {note}" for note in scene.notes]
        verdict = {0: "passed", 1: "REGRESSION", 2: "COULD NOT RUN every scenario"}[self.exit_code]
        lines.append("baselines updated" if self.update and self.exit_code == 0 else
                     "baselines updated; REQUIREMENTS NOT MET" if self.update and self.exit_code == 1 else
                     f"regress: {verdict} ({sum(s.verdict == 'pass' for s in self.scenes)} of {len(self.scenes)} "
                     "scenarios passed)")
        return "\n".join(lines)

    def __repr__(self):
        return self.summary()


def regress(names, baseline, update=False, ci=False, overrides=None, time_tol=0.0, jobs=None, implementation=None,
            fmi_version=None, progress=False, signals=None):
    """Compare (or with ``update`` record) every scenario file of ``names`` against its
    baseline in the folder ``baseline``; a Regression. ``overrides``: {name: quantity}
    tolerances ("pose error peak": "0.5 µm", "plant.pose": "1 um"); ``time_tol`` the
    tube's width in time [s]; ``signals``: with ``update``, the recorded variables to store
    ("plant.pose") instead of those the metrics read."""
    if not isinstance(baseline, (str, pathlib.PurePath)) or not str(baseline).strip():
        raise BaselineError(f"baseline must name a folder, got {baseline!r}")
    names = [names] if isinstance(names, (str, pathlib.PurePath)) else list(names)
    if not names:
        raise BaselineError("no scenario given; name scenario files or shipped scenarios")
    if not (isinstance(time_tol, (int, float)) and math.isfinite(time_tol) and time_tol >= 0):
        raise BaselineError(f"time tolerance must be a duration >= 0, got {time_tol!r}")
    overrides = dict(overrides or {})
    for name in overrides:
        if not isinstance(name, str) or not name.strip():
            raise BaselineError(f"tolerance: a name of a metric number or signal, got {name!r}")
    signals = [signals] if isinstance(signals, str) else list(signals or [])
    if signals and not update:
        raise BaselineError("signals are chosen when a baseline is stored (--update); a comparison compares "
                            "what its baseline holds")
    if any(not isinstance(v, str) or "." not in v for v in signals):
        raise BaselineError(f"signals are recorded variables 'instance.variable' ('plant.pose'), got {signals!r}")
    stems = [pathlib.Path(str(n)).stem for n in names]
    shared = sorted({stem for stem in stems if stems.count(stem) > 1})
    if shared:
        raise BaselineError(f"{', '.join(shared)}: more than one scenario file of that name; a baseline is kept per "
                            "file name (baseline/<stem>/): hold them in separate --baseline folders")
    scenes = [regress_scene(str(n), baseline, update, ci, overrides, time_tol, jobs, implementation, fmi_version,
                            progress, signals) for n in names]
    return Regression(scenes, str(baseline), update)
