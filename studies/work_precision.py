"""Work-precision study: what each co-simulation setting costs in CPU time and buys in
accuracy, against a reference solution of the same scene (studies.reference).

For each scene the user's choices are swept:

* communication step h: 0.25, 0.5, 1, 2, 4 ms;
* master: Jacobi, Gauss-Seidel, Jacobi with linear input extrapolation;
* plant integrator and substeps: rk4 / euler / radau, max_step (substeps = ceil(h / max_step));
  the FMUs are the shipped scenarios' (native), but radau runs the pythonfmu plant (the
  native one has no scipy), so its cost holds pythonfmu's per-step overhead too;
* plant model fidelity: full, massless_legs, base_gravity, no_base;

not as a full factorial but as the step sweep of every master with the shipped plant
settings, plus integrator and fidelity variants with the Jacobi master (the shipped one).
The controller always runs the shipped moving-base feedforward and default gains.

Cost: CPU time of the master's stepping loop (scenarios.cosim.master.Run.cpu_time, the stepping
thread's CPU time, FMU instantiation and initialisation excluded; CPU rather than wall time
because the machines these run on are shared: another process's load stretches wall time,
not this thread's CPU time), the median of ``repeats`` runs made in
interleaved rounds (every setting once per round, so a load change on the machine hits
all settings alike), after one short untimed warm-up run of each setting (lazy imports and
compiled-code loads land there); a setting whose first run takes over LONG_RUN seconds
is not repeated. Only the platform pose and the leg forces are recorded, every 4 ms (a multiple
of every step), so recording costs next to nothing.

Error: against the reference, over the scene's window: platform position error RMS and
max [µm], rotation error RMS and max [µrad], leg-force error RMS and max [N]. The chart
and the Pareto front use the position RMS (left panel) and the leg-force RMS (right).

Pareto front: the settings no other setting beats in both cost and error (lower or equal
in both, lower in one). Failed runs and unstable ones (the leg forces reach the
controller's force limit, which the reference never does) are listed but kept off the
front. Distance of a setting (the shipped default) from the front, with the front
interpolated linearly in log-log between its points (the step is continuous, so the
settings between two front points exist):

* cost at equal error: c / c_front(e), its CPU time over the front's at its error;
* error at equal cost: e / e_front(c), its error over the front's at its CPU time;

both 1 on the front; the same ratios against the runs made only (no interpolation) are
reported beside them. The default counts as "within 10 % of the front" when its cost at
equal error is at most 1.10 (the accuracy it delivers cannot be had for less than 91 %
of its CPU time); the verdict is given for the position RMS (what the hexapod is for)
and, as a second opinion, for the leg-force RMS.

The realistic plant's integrator (``--plant-integrator``): on the [ci] runs of two
realistic scenes (screw friction and force loop in the plant), the plant's fixed RK4
substeps (max_step 1 ms to 0.05 ms; 0.1 ms is what the scenes shipped before issue 41)
beside its error-controlled ones (tolerance 1e-8 to 1e-12 m a substep, at most 1 ms, the
lag exact; 1e-10 ships), each against the same co-simulation with RK4 at 0.01 ms fixed
substeps: platform position error, largest over the metrics' window, against the CPU time
of the stepping; the 1 % line is 1 % of the scene's pose error peak (issue 41's equal
accuracy). It writes docs/figures/work_precision_realistic_plant.png.

Run ``python -m studies.work_precision [--scenes ...] [--repeats N] [--quick]``; it prints a
table per scene and writes docs/figures/work_precision_<scene>.png.
"""
import argparse
import dataclasses
import json
import pathlib
import sys
import tempfile
import time
from dataclasses import dataclass

import numpy as np

from plant.hexapod.model import FIDELITIES
from plant.integrators import INTEGRATORS
from scenarios import spec
from scenarios.cosim.fmi import FmuError
from scenarios.cosim.records import run_records
from scenarios.runs import runner, single
from studies import reference

ROOT = pathlib.Path(__file__).resolve().parent.parent
FIGURES = ROOT / "docs" / "figures"
RECORD_INTERVAL = 4e-3
RTOL_CHECK = 5e-11       # the reference is checked against one at half its tolerances
LONG_RUN = 10.0          # s: a setting whose first run takes longer is not repeated
STEPS = (0.25e-3, 0.5e-3, 1e-3, 2e-3, 4e-3)
MASTERS = (("jacobi", "none"), ("gauss-seidel", "none"), ("jacobi", "linear"))
MASTER_LABELS = {("jacobi", "none"): "Jacobi", ("gauss-seidel", "none"): "Gauss-Seidel",
                 ("jacobi", "linear"): "Jacobi+lin"}
FEEDFORWARD = 2          # moving_base, the shipped controller default


# ------------------------------------------------------------------------------ scenes
@dataclass(frozen=True)
class SceneSpec:
    """A shipped scene, possibly shortened to a window: stop_time, base parameters
    changed (e.g. an earlier start of the slew), and the window errors are measured in."""

    file: str
    stop_time: float | None = None            # None: the file's
    base: tuple = ()                   # (("parameter", value), ...) set on the telescope FMU
    window_from: float = 0.0
    note: str = ""


SCENES = {
    "paper_manoeuvre": SceneSpec("paper_manoeuvre", window_from=2.0,
                                 note="as shipped: 2 s rest, the 6 s manoeuvre; errors over the manoeuvre"),
    "telescope_slew": SceneSpec("telescope_slew", stop_time=5.0, base=(("start_delay", 0.5),), window_from=0.5,
                                note="window: the slew starts at 0.5 s (shipped: 5 s); errors over its first 4.5 s "
                                     "(both axes' acceleration phases and the start of their cruise)"),
    "keyhole_tracking": SceneSpec("keyhole_tracking", stop_time=10.0, base=(("utc_start", 120.0),), window_from=1.0,
                                  note="window: utc_start + 120 s, so the 0.2 deg keyhole transit falls at 5 s of a "
                                       "10 s run (shipped: 125 s of 250 s); errors from 1 s on"),
}


@dataclass
class Prepared:
    name: str
    scenario: object
    paths: dict
    descriptions: dict
    values: dict
    window: tuple
    spec: SceneSpec

    def scene(self):
        return reference.Scene.from_prepared(self.scenario, self.descriptions, self.values)


def prepare(name, stop_time=None):
    """The scene ``name`` of SCENES ready to co-simulate (FMUs built, parameters bound)."""
    spec = SCENES[name]
    scenario, paths, descriptions, values = runner.prepare(runner.resolve(spec.file))
    stop = stop_time or spec.stop_time or scenario.stop_time
    scenario = dataclasses.replace(scenario, stop_time=stop, record=["plant.pose", "controller.leg_force"],
                                   record_interval=RECORD_INTERVAL, metrics=[], sweep=None)
    values = {inst: dict(v) for inst, v in values.items()}
    base = next(i for i, f in scenario.fmus.items() if f == "telescope")
    for key, value in spec.base:
        if key == "utc_start":
            value = values[base]["utc_start"] + value
        values[base][key] = value
    ctrl = next(i for i, f in scenario.fmus.items() if f == "leg_controller")
    values[ctrl]["feedforward"] = FEEDFORWARD
    return Prepared(name, scenario, paths, descriptions, values, (spec.window_from, stop), spec)


# ---------------------------------------------------------------------------- settings
@dataclass(frozen=True)
class Config:
    """One co-simulation setting."""

    step: float
    master: str = "jacobi"
    extrapolation: str = "none"
    integrator: str = "rk4"
    max_step: float = 1e-3
    fidelity: str = "full"

    @property
    def master_label(self):
        return MASTER_LABELS[(self.master, self.extrapolation)]

    @property
    def substeps(self):
        return max(1, int(np.ceil(self.step / self.max_step - 1e-9)))

    @property
    def label(self):
        return (f"h={self.step * 1e3:g}ms {self.master_label} {self.integrator}x{self.substeps} "
                f"{self.fidelity}")


def _shipped():
    """The shipped setting, read from the paper scenario: its step, master, extrapolation
    (plant: rk4, max_step 1 ms, full fidelity, as the scenario files set it)."""
    shipped = spec.load(runner.resolve("paper_manoeuvre"))
    return Config(shipped.step, shipped.master, shipped.extrapolation)


DEFAULT = _shipped()


def sweep(steps=STEPS):
    """The settings of the study (the default included once)."""
    configs = []
    for master_, extrapolation in MASTERS:                     # step x master, shipped plant
        configs += [Config(h, master_, extrapolation) for h in steps]
    for h in steps:                                            # integrators and substeps
        configs += [Config(h, max_step=h), Config(h, integrator="euler", max_step=h)]
    for h in (1e-3, 4e-3):
        configs += [Config(h, max_step=h / 4), Config(h, integrator="euler", max_step=h / 4),
                    Config(h, integrator="radau", max_step=h)]
    for fidelity in ("massless_legs", "base_gravity", "no_base"):  # model fidelity
        configs += [Config(h, fidelity=fidelity) for h in (0.5e-3, 1e-3, 2e-3)]
    return _unique(c for c in configs if c.step in steps)


def _unique(configs):
    """First of the settings that run alike (same step, master, integrator, substeps, fidelity)."""
    seen, out = set(), []
    for c in configs:
        key = (c.step, c.master, c.extrapolation, c.integrator, c.substeps, c.fidelity)
        if key not in seen:
            seen.add(key)
            out.append(c)
    return out


def quick_sweep():
    """A small sweep for a fast look: the default's neighbours."""
    return _unique([Config(h) for h in (0.5e-3, 1e-3, 2e-3)] +
                   [Config(1e-3, "gauss-seidel"), Config(1e-3, extrapolation="linear"),
                    Config(1e-3, integrator="euler", max_step=1e-3)])


# ------------------------------------------------------------------------ co-simulation
def cosimulate(prep, config, outdir, stop_time=None):
    """One co-simulation; returns (CPU time of its stepping [s], times, pose (n, 6), leg forces (n, 6))."""
    scenario = dataclasses.replace(prep.scenario, step=config.step, master=config.master,
                                   extrapolation=config.extrapolation,
                                   stop_time=stop_time or prep.scenario.stop_time)
    params = {inst: dict(v) for inst, v in prep.values.items()}
    plant = next(i for i, f in scenario.fmus.items() if f == "hexapod_plant")
    params[plant].update(integrator=INTEGRATORS.index(config.integrator), max_step=config.max_step,
                         fidelity=FIDELITIES.index(config.fidelity))
    paths = prep.paths
    if config.integrator == "radau":   # scipy's Radau: only the pythonfmu plant has it
        paths = runner.fmu_paths(dataclasses.replace(scenario, implementations={**scenario.implementations,
                                                                                plant: "python"}))
    run = single.run(scenario, paths, params, pathlib.Path(outdir), "run")
    records = run_records(run)
    pose = [k for k, c in enumerate(records.names) if c.startswith("plant.pose[")]
    force = [k for k, c in enumerate(records.names) if c.startswith("controller.leg_force[")]
    return run.cpu_time, records.time, records.values[:, pose], records.values[:, force]


_PROBE = """
import sys, tempfile
from studies import work_precision as W
prep = W.prepare(sys.argv[1])
try:
    with tempfile.TemporaryDirectory() as tmp:
        W.cosimulate(prep, W.Config(1e-3, integrator=sys.argv[2], max_step=1e-3), tmp, stop_time=4e-3)
    print("OK")
except Exception as exc:
    print(" ".join(str(exc).split())[:400])
"""


def probe(name, integrator):
    """'OK' or the failure of a 4-step run with this plant integrator, tried in a child
    process: an FMU that fails inside pythonfmu can corrupt its host process's heap
    (seen as 'corrupted double-linked list' with integrator radau), which must not take
    a long sweep down."""
    import subprocess
    done = subprocess.run([sys.executable, "-c", _PROBE, name, integrator], cwd=ROOT, capture_output=True,
                          text=True, timeout=600)
    lines = done.stdout.strip().splitlines()
    return lines[-1] if lines else f"probe exited with {done.returncode}: {done.stderr.strip()[-300:]}"


# ----------------------------------------------------------------------- Pareto front
def pareto_front(costs, errors):
    """Boolean mask of the points no other point dominates (both minimised; a point is
    dominated by one at most as costly and at most as wrong, strictly better in one).
    NaN points (failed runs) are never on the front."""
    costs, errors = np.asarray(costs, dtype=float), np.asarray(errors, dtype=float)
    ok = np.isfinite(costs) & np.isfinite(errors)
    front = np.zeros(costs.size, dtype=bool)
    for i in np.flatnonzero(ok):
        others = ok & (costs <= costs[i]) & (errors <= errors[i]) & ((costs < costs[i]) | (errors < errors[i]))
        front[i] = not others.any()
    return front


def _front_points(costs, errors):
    """Front points (costs, errors) sorted by cost (so errors fall)."""
    front = pareto_front(costs, errors)
    order = np.argsort(costs[front])
    return costs[front][order], errors[front][order]


def front_cost(costs, errors, error):
    """Cost of the front at ``error``: linear in log-log between the front's points
    (steps are continuous, so a setting between two front points is reachable), the
    cheapest front cost above its least accurate point, its most accurate point's cost
    below."""
    fc, fe = _front_points(np.asarray(costs, float), np.asarray(errors, float))
    if error >= fe[0]:
        return float(fc[0])
    if error <= fe[-1]:
        return float(fc[-1])
    return float(np.exp(np.interp(np.log(error), np.log(fe[::-1]), np.log(fc[::-1]))))


def front_error(costs, errors, cost):
    """Error of the front at ``cost``, interpolated the same way."""
    fc, fe = _front_points(np.asarray(costs, float), np.asarray(errors, float))
    if cost <= fc[0]:
        return float(fe[0])
    if cost >= fc[-1]:
        return float(fe[-1])
    return float(np.exp(np.interp(np.log(cost), np.log(fc), np.log(fe))))


def front_distance(costs, errors, index):
    """How far point ``index`` is from the front (failed points, NaN, ignored):

    * ``cost_ratio``: its cost / the front's cost at its error (cost at equal error);
    * ``error_ratio``: its error / the front's error at its cost (error at equal cost);

    both with the front interpolated in log-log (front_cost, front_error), both 1 on
    the front; and the same two against the runs made only, no interpolation
    (``attainable_*``: its cost / the least cost of a run at most as wrong, its error /
    the least error of a run at most as costly)."""
    costs, errors = np.asarray(costs, dtype=float), np.asarray(errors, dtype=float)
    ok = np.isfinite(costs) & np.isfinite(errors)
    c, e = costs[index], errors[index]
    on_front = bool(pareto_front(costs, errors)[index])
    at_error, at_cost = front_cost(costs, errors, e), front_error(costs, errors, c)
    return {"on_front": on_front, "cost": float(c), "error": float(e),
            "cost_ratio": 1.0 if on_front else float(c / at_error),
            "error_ratio": 1.0 if on_front else float(e / at_cost),
            "front_cost_at_error": at_error, "front_error_at_cost": at_cost,
            "attainable_cost_ratio": float(c / costs[ok & (errors <= e)].min()),
            "attainable_error_ratio": float(e / errors[ok & (costs <= c)].min())}


def near_front(distance, tolerance=0.10):
    """The study's criterion: on the front, or within ``tolerance`` of it in cost at
    equal error (the front interpolated in log-log): cost_ratio <= 1 + tolerance."""
    return distance["on_front"] or distance["cost_ratio"] <= 1.0 + tolerance + 1e-12


# -------------------------------------------------------------------------------- study
def check_reference(ref, prep, rtol=RTOL_CHECK):
    """errors() between the reference and one solved at ``rtol`` (tighter; the absolute
    tolerances scaled alike), over the window at the recording times: how converged the
    reference is."""
    other = reference.solve(ref.scene, rtol=rtol, atol_scale=rtol / ref.rtol)
    times = np.arange(prep.window[0], prep.window[1] + 1e-9, RECORD_INTERVAL)
    return reference.difference(ref, other, times)


def study(name, configs=None, repeats=3, progress=True, reference_solution=None, stop_time=None, prep=None):
    """Run the sweep on scene ``name``; returns (results, reference). ``results``: one
    dict per setting with its Config, CPU time (median), the times measured and the
    errors against the reference (or the failure message)."""
    from tqdm import tqdm
    configs = configs or sweep()
    prep = prep or prepare(name, stop_time)
    t0 = time.perf_counter()
    ref = reference_solution or reference.solve(prep.scene())
    if progress:
        print(f"{name}: reference (Radau, rtol {ref.rtol:g}) in {time.perf_counter() - t0:.1f} s, "
              f"{ref.rhs_calls} right-hand sides; peak |force| {ref.peak_force / 1e3:.2f} kN"
              f"{' (SATURATED)' if ref.saturated else ''}", flush=True)
    results = [{"config": c, "times": [], "error": None, "failure": None, "unstable": None} for c in configs]
    for integrator in sorted({c.integrator for c in configs} - {"rk4", "euler"}):
        answer = probe(name, integrator)
        if answer != "OK":
            if progress:
                print(f"{name}: plant integrator {integrator} fails, not run in this process: {answer}", flush=True)
            for result in results:
                if result["config"].integrator == integrator:
                    result["failure"] = f"fails at once (probe): {answer}"
    with tempfile.TemporaryDirectory() as tmp:
        for result in results:     # warm-up: lazy imports and compiled-code loads happen here, untimed
            if not result["failure"]:
                try:
                    cosimulate(prep, result["config"], tmp, stop_time=prep.scenario.start_time + 0.05)
                except FmuError:
                    pass
        bar = tqdm(total=len(configs) * repeats, desc=f"{name}", unit="run", disable=not progress)
        for round_ in range(repeats):
            for result in results:
                config = result["config"]
                bar.set_postfix_str(config.label)
                if result["failure"] or (round_ and (result["unstable"] or result["times"][0] > LONG_RUN)):
                    bar.update(1)
                    continue
                try:
                    cpu, times, pose, forces = cosimulate(prep, config, tmp)
                except FmuError as exc:
                    result["failure"] = str(exc).splitlines()[-1].strip()[:160]
                    bar.update(1)
                    continue
                result["times"].append(cpu)
                if result["error"] is None:
                    result["error"] = reference.compare(ref, times, pose, forces, prep.window)
                    peak = float(np.abs(forces).max())
                    if peak >= (1 - 1e-9) * ref.scene.gains["force_limit"] > ref.peak_force:
                        result["unstable"] = (f"unstable: leg forces at the {peak / 1e3:.0f} kN limit "
                                              f"(reference peak {ref.peak_force / 1e3:.1f} kN)")
                bar.update(1)
        bar.close()
    for result in results:
        result["cpu_time"] = float(np.median(result["times"])) if result["times"] else np.nan
    return results, ref


def measures(results, key):
    """(costs, errors) arrays; NaN for failed and unstable runs, which the front ignores.
    Position errors under the floor (1 nm) count as the floor: finer than the model
    resolves, they are equal, and the cheapest of them is the front there."""
    from scenarios.output.charts import FLOOR
    usable = [bool(r["error"]) and not r["unstable"] for r in results]
    costs = np.array([r["cpu_time"] if ok else np.nan for r, ok in zip(results, usable)])
    errors = np.array([r["error"][key] if ok else np.nan for r, ok in zip(results, usable)])
    return costs, np.maximum(errors, FLOOR) if key == "pose_rms_um" else errors   # NaN stays NaN


def verdict(results, key="pose_rms_um", default=DEFAULT):
    """front_distance of the default among the results (None if it was not run or
    failed), with ``near`` (the study's 10 % criterion, see near_front)."""
    index = next((i for i, r in enumerate(results) if r["config"] == default), None)
    if index is None or results[index]["failure"] or results[index]["unstable"]:
        return None
    distance = front_distance(*measures(results, key), index)
    distance["near"] = near_front(distance)
    distance["key"] = key
    return distance


def describe(v, what):
    status = "ON the front" if v["on_front"] else (
        "within 10 % of the front" if v["near"] else "NOT within 10 % of the front")
    return (f"shipped default, {what}: {status}: cost at equal error x{v['cost_ratio']:.3f} "
            f"({v['cost']:.3f} s against the front's {v['front_cost_at_error']:.3f} s at {v['error']:.3g}), "
            f"error at equal cost x{v['error_ratio']:.3f} ({v['error']:.3g} against {v['front_error_at_cost']:.3g}); "
            f"against the runs made only: cost x{v['attainable_cost_ratio']:.3f}, "
            f"error x{v['attainable_error_ratio']:.3f}")


def table(results):
    """The results as a text table, sorted by fidelity, master, integrator and step.
    front: P on the position-RMS front, F on the leg-force-RMS front."""
    front_pose = pareto_front(*measures(results, "pose_rms_um"))
    front_force = pareto_front(*measures(results, "force_rms_N"))
    lines = [f"{'step':>6} {'master':<12} {'integrator':<10} {'fidelity':<13} {'cpu':>7} "
             f"{'pos rms':>9} {'pos max':>9} {'rot rms':>8} {'F rms':>9} {'F max':>9}  front",
             f"{'[ms]':>6} {'':<12} {'x substeps':<10} {'':<13} {'[s]':>7} {'[µm]':>9} {'[µm]':>9} "
             f"{'[µrad]':>8} {'[N]':>9} {'[N]':>9}"]
    order = sorted(range(len(results)), key=lambda i: (
        results[i]["config"].fidelity != "full", results[i]["config"].fidelity,
        results[i]["config"].master_label, results[i]["config"].integrator, results[i]["config"].substeps,
        results[i]["config"].step))
    for i in order:
        r, c = results[i], results[i]["config"]
        head = (f"{c.step * 1e3:>6g} {c.master_label:<12} {c.integrator + ' x' + str(c.substeps):<10} "
                f"{c.fidelity:<13}")
        if r["failure"]:
            lines.append(f"{head} {'failed':>7}  {r['failure'][:150]}")
            continue
        e = r["error"]
        marks = ("P" if front_pose[i] else "-") + ("F" if front_force[i] else "-")
        note = "  <- shipped default" if c == DEFAULT else ""
        if r["unstable"]:
            marks, note = "  ", f"  {r['unstable']}"
        lines.append(f"{head} {r['cpu_time']:>7.3f} {e['pose_rms_um']:>9.3g} {e['pose_max_um']:>9.3g} "
                     f"{e['rot_rms_urad']:>8.3g} {e['force_rms_N']:>9.3g} {e['force_max_N']:>9.3g}  {marks}{note}")
    return "\n".join(lines)


# -------------------------------------------------------------------------------- chart
COLOURS = {"Jacobi": "tab:blue", "Gauss-Seidel": "tab:orange", "Jacobi+lin": "tab:green"}
MARKERS = {"rk4": "o", "euler": "s", "radau": "D"}
REDUCED = "0.55"     # every reduced-fidelity plant: one grey, its points named in the table


def chart(name, results, path, note=""):
    """Error against CPU time, log-log: position RMS (left) and leg-force RMS (right),
    the Pareto front (log-log interpolated), the shipped default as a star. Four encodings only:
    colour = master, marker = plant integrator, hollow = substeps, grey = reduced-fidelity
    plant; only the front's points carry their step, beside them; position errors under
    1 nm are drawn on the floor. Returns the path."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.lines import Line2D

    from scenarios.output.charts import FLOOR, label_points, plain_log_axis, ratio, save

    fig, axes = plt.subplots(1, 2, figsize=(13, 6.2), layout="constrained")
    labels = {}
    for ax, key, label in ((axes[0], "pose_rms_um", "platform position error against the reference, RMS [µm]"),
                           (axes[1], "force_rms_N", "leg-force error against the reference, RMS [N]")):
        costs, errors = measures(results, key)
        floor = FLOOR if key == "pose_rms_um" else 0.0
        shown = np.maximum(errors, floor)
        front = pareto_front(costs, errors)
        for i, r in enumerate(results):
            if r["failure"]:
                continue
            c = r["config"]
            x, y = r["cpu_time"], max(r["error"][key], floor)
            if r["unstable"]:
                ax.scatter(x, y, s=40, marker="x", color="0.5", zorder=3)
                continue
            colour = COLOURS[c.master_label] if c.fidelity == "full" else REDUCED
            filled = c.substeps == 1 or c.integrator == "radau"
            ax.scatter(x, y, s=40, marker="v" if r["error"][key] < floor else MARKERS[c.integrator], zorder=3,
                       facecolors=colour if filled else "none", edgecolors=colour, linewidths=1.2, clip_on=False)
        idx = np.flatnonzero(front)
        idx = idx[np.argsort(costs[idx])]
        ax.plot(costs[idx], shown[idx], color="k", lw=1.2, zorder=2)
        title = ""
        v = verdict(results, key)
        if v:
            d = next(i for i, r in enumerate(results) if r["config"] == DEFAULT)
            status = (
                "on the front" if v["on_front"] else ("within 10 % of it" if v["near"] else "not within 10 % of it")
            )
            ax.scatter(costs[d], shown[d], s=260, marker="*", facecolors="gold", edgecolors="k", zorder=4)
            title = (f"shipped default ({DEFAULT.label}): {status};\ncost {ratio(v['cost_ratio'], 1)} the front's at "
                     f"equal error, error {ratio(v['error_ratio'], 1)} at equal cost")
        ax.set_title(title, fontsize=9)
        ax.set_xscale("log")
        ax.set_yscale("log")
        plain_log_axis(ax.xaxis)
        plain_log_axis(ax.yaxis)
        if floor:                             # never below 1 nm, no lower than the data needs
            ax.set_ylim(max(floor, 0.5 * np.nanmin(shown)), None)
        ax.set_xlabel("CPU time of the stepping [s] (median of repeats)")
        ax.set_ylabel(label + (" (floored at 1 nm)" if floor else ""), fontsize=9)
        ax.grid(True, which="major", alpha=0.3)
        labels[ax] = (costs[idx], shown[idx], [f"{results[i]['config'].step * 1e3:g} ms"
                                               + ("" if results[i]["config"].fidelity == "full"
                                                  else f", {results[i]['config'].fidelity}") for i in idx])
    keys = [Line2D([], [], ls="", marker="o", color=c, label=f"master {m}") for m, c in COLOURS.items()]
    keys += [Line2D([], [], ls="", marker=m, color="0.3", label=f"plant {k}") for k, m in MARKERS.items()]
    keys += [Line2D([], [], ls="", marker="o", markerfacecolor="none", color="0.3", label="hollow: > 1 substep"),
             Line2D([], [], ls="", marker="o", color=REDUCED, label="reduced-fidelity plant (see the table)"),
             Line2D([], [], ls="", marker="x", color="0.5", label="unstable (forces at the limit)"),
             Line2D([], [], color="k", lw=1.2, label="Pareto front (labels: step)"),
             Line2D([], [], ls="", marker="*", ms=12, markerfacecolor="gold", color="k", label="shipped default")]
    fig.legend(handles=keys, loc="outside lower center", ncol=6, fontsize=8, frameon=False)
    failed = [r["config"] for r in results if r["failure"]]
    extra = ""
    if failed:
        extra = f"; failed, not shown: {', '.join(sorted({f'{c.integrator} plant' for c in failed}))}"
    fig.suptitle(f"Work-precision, {name}: error against CPU time (reference: coupled model, Radau rtol 1e-10, "
                 f"continuous PID){extra}\n{note}", fontsize=9)
    for ax, (xs, ys, texts) in labels.items():   # after the layout is final: free places beside the points
        label_points(ax, xs, ys, texts)
    path.parent.mkdir(parents=True, exist_ok=True)
    save(fig, path)
    return path


# ----------------------------------------------------------- the realistic plant's integrator
REALISTIC_SCENES = ("telescope_slew_realistic", "keyhole_tracking_observer")
FIXED_SUBSTEPS = (1e-3, 0.5e-3, 0.25e-3, 0.1e-3, 0.05e-3)   # s; 0.1 ms: the scenes before issue 41
TOLERANCES = (1e-8, 1e-9, 1e-10, 1e-11, 1e-12)           # m a substep; 1e-10: the scenes now
REFERENCE_SUBSTEP = 1e-5                                  # s, fixed RK4 substeps of the reference


def _realistic_run(name):
    """A realistic scene's [ci] run, its last sweep value: (scenario, paths, label, parameters,
    plant instance, the pose error metric's window start [s])."""
    scenario, paths, descriptions, values = runner.prepare(runner.resolve(name), ci=True)
    label, params = list(runner.sweep_runs(scenario, descriptions, values))[-1]
    plant = next(inst for inst, fmu in scenario.fmus.items() if fmu == "hexapod_plant")
    pose = next(m for m in scenario.metrics if m.kind == "pose_tracking")
    return scenario, paths, label, params, plant, pose.start


def _plant_run(run, plant_values, outdir):
    """(CPU time of the stepping [s], times, platform position (n, 3) [m], pose error peak [µm])."""
    from scenarios.runs import metrics
    scenario, paths, label, params, plant, _ = run
    params = {inst: dict(v) for inst, v in params.items()}
    params[plant].update(plant_values)
    outdir.mkdir(parents=True)
    done = single.run(scenario, paths, params, outdir, label, [metrics.make(m) for m in scenario.metrics])
    columns = [k for k, c in enumerate(done.records.names) if c.startswith(f"{plant}.pose[")][:3]
    return done.cpu_time, done.records.time, done.records.values[:, columns], done.metrics["pose error"]["peak"]


def plant_integrators(repeats=3):
    """{scene: {"reference_peak_um", "settings": [(kind, value, CPU [s], error max [µm])]}} of
    the realistic plant's fixed and error-controlled substeps (see the module's docstring);
    CPU times the median of ``repeats`` interleaved rounds."""
    out = {}
    with tempfile.TemporaryDirectory() as tmp:
        for name in REALISTIC_SCENES:
            run = _realistic_run(name)
            _, t, ref, peak = _plant_run(run, {"tolerance": 0.0, "max_step": REFERENCE_SUBSTEP},
                                         pathlib.Path(tmp) / name / "reference")
            window = t >= run[5]
            settings = [("fixed", h, {"tolerance": 0.0, "max_step": h}) for h in FIXED_SUBSTEPS]
            settings += [("controlled", tol, {"tolerance": tol, "max_step": 1e-3}) for tol in TOLERANCES]
            costs, errors = [[] for _ in settings], [0.0] * len(settings)
            for k in range(repeats):
                for i, (_, _, plant_values) in enumerate(settings):
                    cpu, _, pose, _ = _plant_run(run, plant_values, pathlib.Path(tmp) / name / f"{k}_{i}")
                    costs[i].append(cpu)
                    errors[i] = float(np.abs(pose - ref)[window].max() * 1e6)
            out[name] = {"reference_peak_um": peak,
                         "settings": [(kind, value, float(np.median(c)), e)
                                      for (kind, value, _), c, e in zip(settings, costs, errors)]}
    return out


def plant_integrators_table(results):
    lines = []
    for name, r in results.items():
        lines += [f"\n{name} [ci]: pose error peak {r['reference_peak_um']:.4g} µm (1 %: "
                  f"{0.01 * r['reference_peak_um'] * 1e3:.3g} nm)",
                  f"{'plant integrator':34s} {'CPU [s]':>8s} {'position error max [nm]':>24s}"]
        for kind, value, cpu, error in r["settings"]:
            what = f"RK4 fixed, max_step {value * 1e3:g} ms" if kind == "fixed" else f"RK4 controlled, tol {value:g} m"
            lines.append(f"{what:34s} {cpu:8.3f} {error * 1e3:24.3g}")
    return "\n".join(lines)


def plant_integrators_chart(results, path):
    """Position error against CPU time, log-log, one panel per scene: fixed substeps
    (circles, labelled by max_step) and error-controlled ones (squares, by tolerance); the
    scenes' old and new settings starred; the 1 % line dashed."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from scenarios.output.charts import label_points, plain_log_axis, save

    fig, axes = plt.subplots(1, len(results), figsize=(13, 5.6), layout="constrained")
    for ax, (name, r) in zip(np.atleast_1d(axes), results.items()):
        for kind, marker, colour, shipped in (("fixed", "o", "tab:blue", 1e-4), ("controlled", "s", "tab:orange",
                                                                                  1e-10)):
            rows = [row for row in r["settings"] if row[0] == kind]
            xs, ys = np.array([row[2] for row in rows]), np.array([row[3] * 1e3 for row in rows])
            ax.plot(xs, ys, marker=marker, color=colour, lw=1.0,
                    label=("RK4, fixed substeps (max_step)" if kind == "fixed"
                           else "RK4, error-controlled substeps (tolerance), lag exact"))
            star = [i for i, row in enumerate(rows) if row[1] == shipped]
            ax.scatter(xs[star], ys[star], s=260, marker="*", facecolors="gold", edgecolors="k", zorder=4)
            label_points(ax, xs, ys, [f"{row[1] * 1e3:g} ms" if kind == "fixed" else f"{row[1]:g}" for row in rows])
        ax.axhline(10 * r["reference_peak_um"], color="0.3", ls="--", lw=1.0, label="1 % of the pose error peak")
        ax.set_xscale("log")
        ax.set_yscale("log")
        plain_log_axis(ax.xaxis)
        ax.set_xlabel("CPU time of the stepping [s] (median of repeats)")
        ax.set_ylabel("platform position error against RK4 at 0.01 ms, max [nm]")
        ax.set_title(f"{name} [ci], its last sweep value", fontsize=9)
        ax.grid(True, which="major", alpha=0.3)
    np.atleast_1d(axes)[0].legend(fontsize=8, loc="lower left")
    fig.suptitle("The realistic plant's integrator (screw friction, force loop): fixed against error-controlled "
                 "RK4 substeps; stars: the scenes before issue 41 (0.1 ms) and now (tolerance 1e-10 m)", fontsize=9)
    path.parent.mkdir(parents=True, exist_ok=True)
    save(fig, path)
    return path


def summary(results):
    """JSON-ready results."""
    return [{**dataclasses.asdict(r["config"]), "label": r["config"].label, "cpu_time_s": r["cpu_time"],
             "cpu_times_s": r["times"], "error": r["error"], "failure": r["failure"], "unstable": r["unstable"]}
            for r in results]


def main(argv=None):
    parser = argparse.ArgumentParser(prog="python -m studies.work_precision", description=__doc__.split("\n\n")[0])
    parser.add_argument("--scenes", nargs="+", default=list(SCENES), choices=list(SCENES))
    parser.add_argument("--repeats", type=int, default=3, help="runs per setting; the CPU time is their median")
    parser.add_argument("--quick", action="store_true", help="a handful of settings around the default")
    parser.add_argument("--figures", type=pathlib.Path, default=FIGURES, help="where the PNGs go")
    parser.add_argument("--json", type=pathlib.Path, help="also write all results to this JSON file")
    parser.add_argument("--plant-integrator", action="store_true",
                        help="only the realistic plant's fixed against error-controlled substeps")
    args = parser.parse_args(argv)
    if args.plant_integrator:
        results = plant_integrators(args.repeats)
        print(plant_integrators_table(results))
        print(f"chart: {plant_integrators_chart(results, args.figures / 'work_precision_realistic_plant.png')}")
        return results
    everything = {}
    begin = time.perf_counter()
    # every scene bound (and its FMUs built) once, up front: FMUs rebuilt mid-study from
    # sources being edited would mix two codes in one chart
    preps = {name: prepare(name) for name in args.scenes}
    for name in args.scenes:
        start = time.perf_counter()
        results, ref = study(name, quick_sweep() if args.quick else sweep(), args.repeats, prep=preps[name])
        check = check_reference(ref, preps[name])
        print(f"\n{name}: {SCENES[name].note}")
        print(f"reference: Radau rtol {ref.rtol:g}, {ref.rhs_calls} right-hand sides, {ref.wall_time:.1f} s; "
              f"against rtol {RTOL_CHECK:g} (atol alike): position {check['pose_max_um']:.1e} µm max, rotation "
              f"{check['rot_max_urad']:.1e} µrad max, leg force {check['force_max_N']:.1e} N max")
        print(table(results))
        verdicts = {}
        for key, what in (("pose_rms_um", "position RMS"), ("force_rms_N", "leg-force RMS")):
            v = verdicts[key] = verdict(results, key)
            print(describe(v, what) if v else f"shipped default, {what}: not run or failed")
        path = chart(name, results, args.figures / f"work_precision_{name}.png", SCENES[name].note)
        print(f"chart: {path}  ({time.perf_counter() - start:.0f} s for this scene)\n", flush=True)
        everything[name] = {"reference": {"rtol": ref.rtol, "rhs_calls": ref.rhs_calls, "wall_time_s": ref.wall_time,
                                          "peak_force_N": ref.peak_force, "against_rtol_check": check},
                            "verdicts": verdicts,
                            "results": summary(results)}
    print(f"total {time.perf_counter() - begin:.0f} s")
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(everything, indent=1, default=float))
    return everything


if __name__ == "__main__":
    main(sys.argv[1:])
