"""A night at the telescope as a campaign: an observing schedule replayed through the
realistic loop with the disturbance observer, in the night's wind, and which scans the
hexapod spoils.

    python -m studies.night [--night FILE] [--out DIR] [--jobs N] [--reuse]   # docs/night.md + charts

The schedule (scenarios/nights/tianma_43ghz.toml, assumed) becomes the 20 Hz table of
scenarios/schedule.py. The night is cut into runs that tile it: run i covers the hold after
scan i-1, the slew to scan i and scan i itself, back to back (``tiles``), so the runs
together simulate the whole night at 1 ms once. Each run is a scenario file of its own
(``scan_data``): the shipped wind configuration (scenarios/files/telescope_slew_observer.toml:
the realistic loop, load cells, the disturbance observer as that scene ships it, Kaimal wind), replaying its
stretch of the table from a prepared replay table this study writes beside it, in the mean
wind the night file gives at the scan's start (held over the run), started at its operating
point (start_equilibrium, start_force). The night file's [requirements] are the files'
[requirements]; the metrics they name ("pose error", "pointing") count from the scan's start,
"run pose error" the whole run from its first second. The metrics read every step
(record.metric_interval), the records keep every RECORD s. The runs go to the kit's Dask
engine (scenarios/runs/engine.py) on --jobs worker processes, longest first; each is judged
by the regression machinery's requirement findings (scenarios/runs/regress.py), its status in
the one vocabulary (scenarios/runs/status.py). Why a scan breaks is read from when its error
peaked: within SLEW_END of the arrival, the slew's end; near the keyhole, the keyhole; else
the wind. It also writes the synthetic encoder log shipped beside the night (noise and a
dropout) and shows what the table checks make of it.

What it writes under --out/night (overwritten by the next run, so bounded by the night's scan
count): per scan its window of the table (CSV), the prepared table the FMUs read
(.mbreplay: given prepared, nothing goes to the kit's replay cache in the temp folder) and its
scenario file; the engine's results (runs/, emptied first: the cost printed is this run's).
"""
import argparse
import dataclasses
import json
import math
import os
import pathlib
import shutil
import time
import tomllib

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from fmu_src import atomic, replay_table
from plant.errors import InvalidInputError
from plant.telescope import model as telescope
from plant.telescope import replay
from scenarios import schedule
from scenarios.cosim.records import run_records
from scenarios.output.charts import plain_log_axis, save
from scenarios.runs import engine, regress, runner, status
from scenarios.runs.metrics import LOSS_BANDS, loss_key
from scenarios.spec.parsing import parse_quantity
from studies.realistic_loop import toml_text

ROOT = pathlib.Path(__file__).resolve().parent.parent
NIGHT = ROOT / "scenarios" / "nights" / "tianma_43ghz.toml"
ENCODER_LOG = ROOT / "scenarios" / "nights" / "tianma_encoder_log.csv"
REPORT = ROOT / "docs" / "night.md"
ERROR_CHART = ROOT / "docs" / "figures" / "night_error.png"
SKY_CHART = ROOT / "docs" / "figures" / "night_sky.png"
BUDGET_CHART = ROOT / "docs" / "figures" / "night_budget.png"
SCENE = "telescope_slew_observer"
STEP = 1e-3            # s: the loop's step (the scene's)
SETTLE = 1.0           # s: a run is counted from its first second (it starts at its operating point)
RECORD = 0.1           # s: the rows kept; the metrics read every step
SLEW_END = 5.0         # s after the arrival: a peak this early in a scan is the slew's end
KEYHOLE_NEAR = math.radians(5.0)   # a peak this close below the keyhole is the keyhole's
JOBS = 2               # worker processes (the goal's 2 cores)
GOAL = 900.0           # s: issue 42's goal for the night on 2 cores
BANDS = {loss_key(b): b for b in LOSS_BANDS}
SLEW_KEYS = ("start_azimuth", "start_elevation", "target_azimuth", "target_elevation")   # the scene's own motion


@dataclasses.dataclass(frozen=True)
class Tile:
    """One run of the night: its steps [first, first + steps) of STEP from the night's start."""

    first: int
    steps: int

    @property
    def start(self):
        return self.first * STEP

    @property
    def stop(self):
        return (self.first + self.steps) * STEP


def tiles(night):
    """The runs that tile the night, one per scan: from the end of the scan before (the
    night's start for the first) to the end of its own scan (the night's end for the last),
    each boundary on the table's grid, so the runs meet without gap or overlap."""
    grid = round(schedule.SAMPLE_INTERVAL / STEP)
    ends = [s.end for s in night.scans[:-1]] + [night.time[-1]]
    bounds = [0] + [grid * round(e / schedule.SAMPLE_INTERVAL) for e in ends]
    return [Tile(a, b - a) for a, b in zip(bounds, bounds[1:])]


def settings(path=NIGHT):
    """The night file's [requirements] (as a scenario file writes them), [wind] and keyhole
    [rad] (the schedule's keys: scenarios/schedule.py)."""
    data = tomllib.loads(pathlib.Path(path).read_text())
    keyhole = parse_quantity(str(path), "keyhole", data["keyhole"], "rad") if "keyhole" in data else schedule.KEYHOLE
    return data.get("requirements", {}), data.get("wind", {"hours": [0.0], "speed": [10.0]}), keyhole


def wind_at(wind, hours):
    """Mean wind speed [m/s] at ``hours`` after the night's start (linear between the file's points)."""
    return float(np.interp(hours, wind["hours"], wind["speed"]))


def window_table(night, tile, path):
    """The night's rows from the tile's start to 1 s past its end (where the night has
    them), its first row the run's t = 0 (CSV, written whole)."""
    rows = (night.time >= tile.start - 1e-6) & (night.time <= tile.stop + 1.0)
    lines = ["time [s],azimuth [deg],elevation [deg]"]
    lines += [f"{t - tile.start:.3f},{a:.9f},{e:.9f}" for t, a, e in zip(
        night.time[rows], np.degrees(night.azimuth[rows]), np.degrees(night.elevation[rows]))]
    with atomic.replacing(path) as f:
        f.write(("\n".join(lines) + "\n").encode())
    return path


def shipped_observer():
    """The observer SCENE ships, as the page names it (its model's mass, its bandwidth)."""
    shipped = tomllib.loads(runner.resolve(SCENE).read_text())["fmus"]["controller"]["parameters"]
    model = {"leg_space": "leg-space mass", "scalar": "one mass"}[shipped.get("observer_model", "scalar")]
    return f"{model}, {shipped['observer_bandwidth']}"


def scan_data(scan, index, tile, table, speed, requirements, name="night"):
    """The scenario file (as a dict, studies.realistic_loop.toml_text writes it) of one scan's
    run: SCENE's FMUs, parameters and connections, replaying ``table`` (a prepared table) over
    the tile, in ``speed`` m/s of mean wind, the night's ``requirements`` judged on metrics
    from the scan's start."""
    data = tomllib.loads(runner.resolve(SCENE).read_text())
    for key in ("ci", "sweep", "requirements"):
        data.pop(key, None)
    from_scan = max(SETTLE, scan.start - tile.start)
    data.update(name=f"{name}_scan{index + 1:02d}", stop_time=f"{tile.steps * STEP:.3f} s",
                description=f"{name}, scan {index + 1} ({scan.source}): the hold, the slew and the scan from "
                            f"{tile.start / 3600:.3f} h to {tile.stop / 3600:.3f} h in {speed:.1f} m/s of wind "
                            f"(studies/night.py)")
    base = data["fmus"]["base"]["parameters"]
    for key in SLEW_KEYS:
        base.pop(key, None)
    base.update(profile="replay", replay_table=str(table), start_delay="0 s")
    data["fmus"]["wind"]["parameters"].update(mean_speed=f"{speed:.6g} m/s", seed=index + 1)
    data["record"] = {"interval": f"{RECORD * 1e3:g} ms", "metric_interval": f"{STEP * 1e3:g} ms",
                      "variables": ["base.axis", "base.axis_rate", "plant.pose"]}
    data["metrics"] = [
        {"name": "pose error", "kind": "pose_tracking", "from": f"{from_scan:.3f} s", "measured": "plant.pose",
         "reference": "base.reference_pose"},
        {"name": "pointing", "kind": "pointing", "from": f"{from_scan:.3f} s", "measured": "plant.pose",
         "reference": "base.reference_pose"},
        {"name": "run pose error", "kind": "pose_tracking", "from": f"{SETTLE:g} s", "measured": "plant.pose",
         "reference": "base.reference_pose"}]
    if requirements:
        data["requirements"] = dict(requirements)
    return data


def write_scan(night, scan, index, tile, speed, requirements, folder, params, name="night"):
    """One scan's window table, its prepared table and its scenario file, in ``folder``
    (overwritten each time); the scenario file's path."""
    stem = folder / f"scan{index + 1:02d}"
    log = window_table(night, tile, stem.with_suffix(".csv"))
    table = replay_table.write(log, stem.with_suffix(replay.PREPARED_SUFFIX), params)
    scene = stem.with_suffix(".toml")
    # the table by its name: a scenario file's paths are read from its own folder, where the table is
    atomic.write_text(scene, toml_text(scan_data(scan, index, tile, pathlib.Path(table.name), speed, requirements,
                                                 name)))
    return scene


def position_error(records):
    """The platform's position error against its reference [µm] (the pose error metric's) per recorded row."""
    return np.linalg.norm([records[f"plant.pose[{k}]"] - records[f"base.reference_pose[{k}]"] for k in (1, 2, 3)],
                          axis=0) * 1e6


def why(records, tile, scan, speed, params, keyhole):
    """Why a scan breaks a requirement, from when its recorded error peaked in the scan: the
    slew's end (within SLEW_END of the arrival, after a slew), the keyhole (within
    KEYHOLE_NEAR of it, or the azimuth at half its rate limit), else the wind."""
    t = records.time
    inside = np.flatnonzero(t >= scan.start - tile.start - 1e-9)
    k = inside[np.argmax(position_error(records)[inside])]
    after = tile.start + t[k] - scan.start
    elevation = records["base.axis[2]"][k]
    if scan.slew_start < scan.start and after < SLEW_END:
        return f"the slew's end (peak {after:.1f} s after the arrival)"
    if elevation > keyhole - KEYHOLE_NEAR or abs(records["base.axis_rate[1]"][k]) > 0.5 * params.az_rate_max:
        return f"the keyhole (peak at {math.degrees(elevation):.1f} deg elevation)"
    return f"the wind ({speed:.1f} m/s; peak {after / 60:.1f} min into the scan)"


def synthetic_log(night, path=ENCODER_LOG, noise_arcsec=2.0, dropout=(60.0, 0.6), seed=7):
    """An encoder log of the night's second slew and the start of its scan: 20 Hz, Gaussian
    noise, one dropout (rows missing) the spline bridges. Written whole."""
    scan = night.scans[1]
    t0 = scan.slew_start - 30.0
    rows = (night.time >= t0) & (night.time <= scan.start + 90.0)
    t, az, el = night.time[rows] - t0, night.azimuth[rows], night.elevation[rows]
    keep = ~((t >= dropout[0]) & (t < dropout[0] + dropout[1]))
    rng = np.random.default_rng(seed)
    sigma = math.radians(noise_arcsec / 3600)
    az, el = az + sigma * rng.normal(size=t.size), el + sigma * rng.normal(size=t.size)
    lines = [f"# synthetic encoder log (studies/night.py): the slew to {scan.source} and its scan's start, "
             f"20 Hz, {noise_arcsec:g} arcsec noise, a {dropout[1]:g} s dropout at {dropout[0]:g} s; "
             "azimuth in [0, 360)",
             "time [s],azimuth [deg],elevation [deg]"]
    lines += [f"{a:.3f},{b:.7f},{c:.7f}" for a, b, c in zip(t[keep], np.degrees(np.mod(az[keep], 2 * np.pi)),
                                                            np.degrees(el[keep]))]
    with atomic.replacing(path) as f:
        f.write(("\n".join(lines) + "\n").encode())
    return path


def log_checks(path, params):
    """What the table checks make of the log, and of it with a 3 s dropout (refused)."""
    table = dataclasses.replace(replay.read_table(path), source=pathlib.Path(path).name)
    loaded = replay.replay_table(table, params)
    gap = table.time.copy()
    gap[len(gap) // 2:] += 3.0
    try:
        replay.replay_table(dataclasses.replace(table, time=gap), params)
        refused = "accepted (unexpected)"
    except InvalidInputError as exc:
        refused = str(exc)
    return loaded, refused


@dataclasses.dataclass
class ScanRun:
    """One scan's run and what the study reads from it."""

    scan: object
    tile: Tile
    speed: float              # m/s, mean wind held over the run
    scenario: object          # the checked scenario of its file
    run: object               # master.Run read back from the engine's store
    status: str = ""          # scenarios.runs.status
    findings: list = dataclasses.field(default_factory=list)   # regress.requirement_findings: what it breaks
    reason: str = ""


def run_night(night, requirements, wind, keyhole, folder, params, jobs=JOBS, progress=True, name="night",
              reuse=False):
    """Every scan's files written and checked, the runs on the engine (longest first), read
    back and judged: ([ScanRun], cost {wall_s, start_s, worker_cpu_s, client_cpu_s, ...}).
    ``reuse``: the engine's results already in ``folder`` are kept (the kit's code and the
    files unchanged: its run keys), and the cost told is that of the campaign that made them."""
    folder.mkdir(parents=True, exist_ok=True)
    made, files = [], {}
    for i, (scan, tile) in enumerate(zip(night.scans, tiles(night))):
        speed = wind_at(wind, scan.start / 3600)
        scene = write_scan(night, scan, i, tile, speed, requirements, folder, params, name)
        scenario, paths, descriptions, values = runner.prepare(scene)
        before = runner.pre_run_flags(scenario, paths, descriptions, values)
        (job,), found = engine.prepared_jobs(scenario, paths, values, [(f"scan{i + 1:02d}", {})])
        made.append((ScanRun(scan, tile, speed, scenario, None), dataclasses.replace(job, flags=tuple(before["run"]))))
        files.update(found)
    store_folder, cost_file = folder / "runs", folder / "cost.json"
    if not reuse:
        shutil.rmtree(store_folder, ignore_errors=True)      # the cost told is this run's, none found on disk
    store = engine.Store(store_folder)
    began, client_cpu = time.perf_counter(), time.process_time()
    with engine.Engine(jobs) as eng:
        order = [j for _, j in sorted(made, key=lambda m: -m[0].tile.steps)]
        outcome = eng.run(order, files, store, progress, name="night", batch=1)
        start = eng.start_time or 0.0
    if outcome.interrupted:
        raise KeyboardInterrupt
    if outcome.computed:
        cost = {"wall_s": time.perf_counter() - began, "start_s": start,
                "client_cpu_s": time.process_time() - client_cpu, "jobs": jobs, "computed": len(outcome.computed),
                "worker_cpu_s": sum(store.read(j.key).get("task_cpu_s", 0.0) for _, j in made
                                    if store.status(j.key) is not None),
                "run_cpu_s": [store.read(j.key).get("task_cpu_s", 0.0) for j in order],   # as dealt
                "load": os.getloadavg()[2]}
        atomic.write_text(cost_file, json.dumps(cost, indent=1))
    else:    # every run found on disk (--reuse): the cost of the campaign that ran them
        cost = json.loads(cost_file.read_text())
    scans = []
    for scan_run, job in made:
        if store.status(job.key) is None:
            raise SystemExit(f"{job.label} ({scan_run.scan.source}) was not run: {outcome.failed.get(job.key)}")
        scan_run.run = engine.stored_run(store, job)
        scan_run.status = status.of_run(scan_run.run.failure, scan_run.run.flags)
        scan_run.findings = regress.requirement_findings(scan_run.scenario, scan_run.run)
        if scan_run.findings:
            scan_run.reason = why(run_records(scan_run.run), scan_run.tile, scan_run.scan, scan_run.speed, params,
                                  keyhole)
        scans.append(scan_run)
    return scans, cost


def dealt(seconds, workers):
    """How long ``seconds`` of work (runs, in the order dealt) take on ``workers`` cores of
    their own, each run going to the first worker free."""
    free = [0.0] * workers
    for t in seconds:
        free[free.index(min(free))] += t
    return max(free)


def requirement_limit(scenario, metric, number):
    """The limit of the scenario's requirement on ``metric number`` (None if it has none)."""
    return next((r.limit for r in scenario.requirements if (r.metric, r.key) == (metric, number)), None)


def error_chart(night, scans):
    fig, ax = plt.subplots(figsize=(10, 4), layout="constrained")
    for s in scans:
        records = run_records(s.run)
        kept = records.time >= SETTLE
        bad = bool(s.findings)
        ax.axvspan(s.scan.start / 3600, s.scan.end / 3600, color="0.88", zorder=0)
        ax.plot((s.tile.start + records.time[kept]) / 3600, position_error(records)[kept],
                color="C3" if bad else "C0", lw=0.5)
        inside = np.flatnonzero(records.time >= s.scan.start - s.tile.start - 1e-9)
        k = inside[np.argmax(position_error(records)[inside])]
        ax.plot((s.tile.start + records.time[k]) / 3600, s.run.metrics["pose error"]["peak"], "v",
                color="C3" if bad else "C0", ms=5)
    limit = requirement_limit(scans[0].scenario, "pose error", "peak")
    if limit is not None:
        ax.axhline(limit, color="C3", lw=1, ls="--")
        ax.annotate(f"requirement: pose error peak < {limit:g} µm", (0.01, limit), xycoords=("axes fraction", "data"),
                    fontsize=7, color="C3", va="bottom")
    ax.set_yscale("log")
    plain_log_axis(ax.yaxis)
    ax.set_xlim(0, night.time[-1] / 3600)
    ax.set_xlabel("hours after the night's start (UTC " + night.utc_start.strftime("%Y-%m-%d %H:%M") + ")")
    ax.set_ylabel("pose error (position) [µm]")
    ax.set_title(f"The whole night at 1 ms, rows kept every {RECORD * 1e3:g} ms (grey bands: the scans; triangles: "
                 "each scan's peak from every step; red: a scan breaking a requirement)", fontsize=8)
    save(fig, ERROR_CHART)


def sky_chart(night, scans):
    fig = plt.figure(figsize=(5.5, 5.5))
    ax = fig.add_subplot(projection="polar")
    ax.set_theta_zero_location("N")
    ax.set_theta_direction(-1)
    ax.plot(night.azimuth[::200], 90 - np.degrees(night.elevation[::200]), color="0.7", lw=0.6)
    for s in scans:
        rows = (night.time >= s.scan.start) & (night.time <= s.scan.end)
        ax.plot(night.azimuth[rows], 90 - np.degrees(night.elevation[rows]), color="C3" if s.findings else "C0",
                lw=2.5)
        k = np.flatnonzero(rows)[0]
        ax.annotate(s.scan.source, (night.azimuth[k], 90 - np.degrees(night.elevation[k])), fontsize=7)
    ax.set_ylim(0, 90)
    ax.set_yticks([0, 30, 60], labels=["90°", "60°", "30°"])   # elevation rings; the rim is the horizon
    ax.set_title("Sky track (azimuth N through E; rings: elevation, rim: horizon; grey: slews)\nblue: scans, "
                 "red: scans breaking a requirement", fontsize=9)
    save(fig, SKY_CHART)


def budget_chart(scans):
    """The budget over the night: each scan's pose error peak (the scan) and its run's
    (hold and slew included), against the requirement, with each scan's wind."""
    fig, ax = plt.subplots(figsize=(10, 3.8), layout="constrained")
    x = np.arange(len(scans))
    ax.bar(x - 0.2, [s.run.metrics["run pose error"]["peak"] for s in scans], 0.4, color="0.65",
           label="the run: hold, slew and scan (from its first second)")
    ax.bar(x + 0.2, [s.run.metrics["pose error"]["peak"] for s in scans], 0.4,
           color=["C3" if s.findings else "C0" for s in scans], label="the scan (red: breaks a requirement)")
    limit = requirement_limit(scans[0].scenario, "pose error", "peak")
    if limit is not None:
        ax.axhline(limit, color="C3", lw=1, ls="--", label=f"requirement: pose error peak < {limit:g} µm")
    ax.set_yscale("log")
    lowest = min(min(s.run.metrics[m]["peak"] for m in ("pose error", "run pose error")) for s in scans)
    ax.set_ylim(bottom=lowest / 3)     # a log axis's bars start where the axis does: below them all
    plain_log_axis(ax.yaxis)
    ax.set_xticks(x, [f"{s.scan.source}\n{s.scan.start / 3600:.1f} h\n{s.speed:.1f} m/s" for s in scans], fontsize=7)
    ax.set_ylabel("pose error peak [µm]")
    ax.set_title("The budget over the night: each scan's pose error peak (every step counted), and its run's",
                 fontsize=9)
    ax.legend(fontsize=7, loc="upper left")
    save(fig, BUDGET_CHART)


def table_lines(scans):
    header = ("| # | source | run [h] | scan from [h] | wind [m/s] | status | pose rms [µm] | pose peak [µm] | "
              "run pose peak [µm] | pointing rms [arcsec] | pointing peak [arcsec] | "
              + " | ".join(f"loss {k[len('efficiency_loss_'):]} [%]" for k in BANDS) + " | breaks | why |")
    lines = [header, "|" + "---|" * (header.count("|") - 1)]
    for i, s in enumerate(scans):
        m = s.run.metrics
        said = s.status + (f" ({', '.join(sorted({f.kind for f in s.run.flags}))})" if s.run.flags else "")
        lines.append(f"| {i + 1} | {s.scan.source} | {s.tile.start / 3600:.3f}-{s.tile.stop / 3600:.3f} | "
                     f"{s.scan.start / 3600:.3f} | {s.speed:.1f} | {said} | {m['pose error']['rms']:.3g} | "
                     f"{m['pose error']['peak']:.3g} | {m['run pose error']['peak']:.3g} | "
                     f"{m['pointing']['rms']:.3g} | {m['pointing']['peak']:.3g} | "
                     + " | ".join(f"{m['pointing'][k]:.2g}" for k in BANDS)
                     + f" | {'; '.join(f.text for f in s.findings) or '-'} | {s.reason or '-'} |")
    return lines


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--night", default=str(NIGHT))
    parser.add_argument("--out", default="out")
    parser.add_argument("--jobs", type=int, default=JOBS, help="worker processes of the engine")
    parser.add_argument("--reuse", action="store_true",
                        help="keep the runs already in --out (same code and files), e.g. to redraw the page")
    args = parser.parse_args(argv)
    params = telescope.TelescopeParams.tianma()
    folder = pathlib.Path(args.out) / "night"
    began = time.perf_counter()
    night = schedule.plan(args.night, params)
    planned = time.perf_counter() - began
    requirements, wind, keyhole = settings(args.night)
    scans, cost = run_night(night, requirements, wind, keyhole, folder, params, args.jobs,
                            name=pathlib.Path(args.night).stem, reuse=args.reuse)
    for line in table_lines(scans)[2:]:
        print(line)
    shipped = pathlib.Path(args.night).resolve() == NIGHT   # the shipped log is the shipped night's
    log = synthetic_log(night, ENCODER_LOG if shipped else folder / ENCODER_LOG.name)
    loaded, refused = log_checks(log, params)
    error_chart(night, scans)
    sky_chart(night, scans)
    budget_chart(scans)
    simulated = sum(s.tile.steps for s in scans) * STEP
    broken = [s for s in scans if s.findings]
    outside = [s for s in scans if s.run.metrics["run pose error"]["peak"] > s.run.metrics["pose error"]["peak"]]
    night_path = pathlib.Path(args.night).resolve()
    shown = night_path.relative_to(ROOT) if night_path.is_relative_to(ROOT) else night_path
    ideal = dealt(cost["run_cpu_s"], 2)
    text = "\n".join([
        "# A night at the telescope", "",
        "<!-- written by `python -m studies.night`; do not edit -->", "",
        f"The night `{shown}` ({tomllib.loads(night_path.read_text()).get('description', 'no description')}), "
        f"planned by `scenarios/schedule.py` into a {night.time.size:,}-row 20 Hz table in {planned:.1f} s, runs "
        f"whole through the realistic loop with the disturbance observer (the FMUs and parameters of "
        f"`scenarios/files/{SCENE}.toml`: ball-screw actuators, leg encoders, the 0.8 Hz axis servo, load cells, "
        f"the observer as that scene ships it ({shipped_observer()}), Kaimal wind; no flexible support, which "
        "the night file does not ask for) at "
        f"{STEP * 1e3:g} ms, in {len(scans)} runs that tile it: each the hold after the scan before, the slew and "
        "its own scan, back to back, started at its operating point (the plant holding the mean wind load, the "
        "observer's estimate with it) and counted from its first second. Each run is a scenario file of its own "
        "(`out/night/scanNN.toml`), the native Telescope FMU replaying its stretch of the table from a prepared "
        "table the study writes beside it (`scanNN.mbreplay`: one per scan, replaced by the next run of the study, "
        "so nothing goes to the kit's replay cache in the temp folder); its Wind FMU holds the night file's mean "
        "wind at the scan's start over the run (turbulence intensity 0.15, its own gust seed), so the wind's "
        "statistics change over the night run by run. The "
        f"metrics read every step (`record.metric_interval`), the records keep every {RECORD * 1e3:g} ms.", "",
        "Requirements: the night file's `[requirements]`, each scan file's own "
        f"(`{'`, `'.join(f'{k} {v}' for k, v in requirements.items())}`), judged by the regression machinery "
        "(`movingbase regress`'s requirement findings) on the metrics \"pose error\" and \"pointing\", which count "
        "from the scan's start: what the scan sees. \"run pose error\" counts the whole run (hold and slew "
        "included). Status: the runs' own (`ok`, `flagged`, `failed`; scenarios/runs/status.py). Why a scan "
        f"breaks is read from when its error peaked: within {SLEW_END:g} s of the arrival, the slew's end; near "
        "the keyhole, the keyhole; else the wind.", "",
        *table_lines(scans), "",
        f"{status.told([s.status for s in scans], 'scan run')}. {len(broken)} of {len(scans)} scans break a "
        "requirement" + (f": {', '.join(s.scan.source for s in broken)}." if broken else ".")
        + f" In {len(outside)} runs the run's peak lies outside its scan (in the hold or the slew, the grey bars "
        "above the blue below), where no requirement reads it.", "",
        "![the night's error](figures/night_error.png)", "", "![the sky track](figures/night_sky.png)", "",
        "![the budget over the night](figures/night_budget.png)", "",
        "## Cost", "",
        f"The {len(scans)} runs, {simulated:,.0f} s simulated at {STEP * 1e3:g} ms ({simulated / STEP:,.0f} steps), "
        f"ran on the kit's Dask engine with {cost['jobs']} worker processes (scenarios/runs/engine.py, longest run "
        f"first) in {cost['wall_s']:.0f} s of wall time here ({cost['wall_s'] / 60:.1f} min, the cluster's start "
        f"{cost['start_s']:.1f} s of it), on a machine whose 2 cores other work shared (load average "
        f"{cost['load']:.1f} over the last 15 minutes). CPU time: {cost['worker_cpu_s']:.0f} s in the workers "
        f"({cost['worker_cpu_s'] / (simulated / STEP) * 1e6:.1f} µs per step of the whole loop, the metrics read "
        f"every step included), {cost['client_cpu_s']:.0f} s in the client. On 2 cores of its own the campaign "
        f"takes its runs' CPU times dealt longest first to 2 workers, each to the first free: "
        f"{ideal:.0f} s ({ideal / 60:.1f} min), {'within' if ideal <= GOAL else 'beyond'} the goal of "
        f"{GOAL / 60:g} minutes{'' if cost['wall_s'] <= GOAL else ', which the shared machine missed in wall time'}.",
        "",
        "## The synthetic encoder log", "",
        f"`{log.resolve().relative_to(ROOT) if log.resolve().is_relative_to(ROOT) else log}`: "
        f"{loaded.breakpoints.size:,} rows, 2 arcsec of noise, a 0.6 s "
        f"dropout the spline bridges, the azimuth written in [0, 360) ("
        f"{'wraps at rows ' + str(list(loaded.wraps)) if loaded.wraps else 'no wrap in this slew'}). "
        "With a 3 s dropout the checks refuse it:", "", "```text", refused, "```", ""])
    with atomic.replacing(REPORT) as f:
        f.write(text.encode())
    print(f"wrote {REPORT.relative_to(ROOT)}")


if __name__ == "__main__":
    main()
