"""The error budget in the telescope's units: each effect the kit can switch, alone, in µm
of pose error, arcsec of pointing and % of aperture efficiency at 22 and 43 GHz.

    python -m studies.error_budget [--jobs N] [--out DIR]   # runs, then docs/error-budget.md + chart

The runs are the realistic-loop study's (studies/realistic_loop.py: the same scenario
variants, engine and store) for the telescope slew at its [ci] length, 8 s: 5 s of
settling at the start pointing, then 3 s of the slew's acceleration, the part where the
base moves fastest. 15 runs of 8 s: about 10 s of wall time on two cores. The full-length effects
on the pose error are in docs/realistic_loop.md; this page puts the short runs' errors
into the telescope's units (plant/telescope/optics.py, the ``pointing`` metric), and adds the
rejection schemes of studies/wind_rejection.py (the same window) to the last row's loop.
"""
import argparse
import pathlib
import time

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from plant.telescope import optics
from scenarios import spec
from scenarios.cosim.records import read_records
from scenarios.output.charts import RUN_COLOURS, draw_marks, plain_log_axis, save
from scenarios.output.report import fmt
from scenarios.runs import engine, runner
from scenarios.runs.metrics import loss_key
from studies import realistic_loop, wind_rejection

ROOT = pathlib.Path(__file__).resolve().parent.parent
REPORT = ROOT / "docs" / "error-budget.md"
SCENE = "telescope_slew"
FEEDFORWARD = ("fixed_base", "moving_base")
# (row label, the realistic-loop study's loop key, the effects on, the feedforwards run)
ROWS = ([("ideal loop", "ideal", (), realistic_loop.MODES)]
        + [(realistic_loop.EFFECT_NAMES[e], e, (e,), FEEDFORWARD) for e in realistic_loop.EFFECTS]
        + [("all effects, 10 m/s wind", "realistic", realistic_loop.EFFECTS, FEEDFORWARD)])
FEEDFORWARD_NAMES = {"none": "none (PID only)", "fixed_base": "fixed-base model (base motion ignored)",
                     "moving_base": "moving-base model"}
BANDS = ("K", "Q")      # 22 and 43 GHz
WIND = 10.0             # m/s, the schemes' wind
# (row label, studies.wind_rejection scheme): all effects in a 10 m/s wind with a rejection scheme
SCHEME_ROWS = [(f"all effects, 10 m/s wind, {wind_rejection.SCHEMES[k]['name']}", k)
               for k in ("observer", "anemometer")]
POINTING_SPEC = 3.0     # arcsec: Tianma's pointing (ATI 2024)
SUPPORT = "telescope_slew_support"   # the shipped scene: sway modes at 1.8 / 2.2 Hz, 10 m/s wind, the slew
SUPPORT_ROW = "feed support sway, 10 m/s (the base; not corrected)"
CHART = ROOT / "docs" / "figures" / "error_budget.png"


def cases():
    """The realistic-loop study's cases this budget runs."""
    return [(SCENE, loop, "exact", effects, modes) for _, loop, effects, modes in ROWS]


def run(out="out", jobs=None, progress=True):
    """Run the cases not on disk yet: {loop: {mode: run record}} (realistic_loop.run's), and
    {scheme: the pose and pointing metrics} of SCHEME_ROWS (wind_rejection.run's)."""
    effects = realistic_loop.run(out, ci=True, jobs=jobs, progress=progress, scenes=(SCENE,),
                                 selected=cases())[SCENE]
    found = wind_rejection.run(out, jobs, progress=progress, window=False, ci=True,
                               selected=[((SCENE, k, "ci"), SCENE, k, WIND, None) for _, k in SCHEME_ROWS])
    schemes = {k: found[f"{SCENE}/{k}/ci"] for _, k in SCHEME_ROWS}
    schemes["support"] = support_sway(out, jobs, progress)
    return effects, schemes


def support_sway(out="out", jobs=None, progress=True):
    """The feed support's sway in the shipped support scene's [ci] run (moving-base
    feedforward), through the optics as a pose error of the subreflector against the primary:
    the hexapod holds its pose in {B}, so it carries the sway of its base uncorrected. The
    entry a scheme row has ({rms, peak} [µm] of the sway's position, "pointing"), from 5 s as
    the other rows; None for a failed run."""
    scenario, paths, descriptions, values = runner.prepare(runner.resolve(SUPPORT), True)
    inst, name, value = spec.sweep_value(scenario, descriptions, "moving_base")
    jobs_here, files = engine.prepared_jobs(scenario, paths, values, [("moving_base", {inst: {name: value}})])
    store = engine.Store(pathlib.Path(out) / "error_budget" / "runs")
    with engine.Engine(jobs) as eng:
        eng.run(jobs_here, files, store, progress, name="support sway")
    key = jobs_here[0].key
    if not store.status(key) or store.read(key).get("status") != "ok":
        return None
    records = read_records(store.path(key, engine.RECORDS))
    late = records.time >= 5.0
    sway = np.column_stack([records[f"base.support_sway[{i}]"] for i in range(1, 7)])[late]
    motion = optics.subreflector_motion(sway, np.zeros_like(sway))
    geometry = optics.Cassegrain.tianma()
    beam = np.linalg.norm(optics.pointing(motion, geometry), axis=1) / optics.ARCSEC
    path = optics.path_error(motion, geometry) * 1e6
    position = np.linalg.norm(sway[:, :3], axis=1) * 1e6
    path_rms = float(np.sqrt(np.mean(path ** 2)))
    pointing = {"rms": float(np.sqrt(np.mean(beam ** 2))), "peak": float(beam.max()), "path_rms": path_rms,
                "path_peak": float(path.max())}
    pointing.update({loss_key(b): 100.0 * float(optics.efficiency_loss(path_rms * 1e-6, optics.BANDS[b]))
                     for b in BANDS})
    return {"rms": float(np.sqrt(np.mean(position ** 2))), "peak": float(position.max()), "pointing": pointing}


def _cells(record):
    """The row's numbers from one run record, or 'failed' cells."""
    if record.get("status") != "ok":
        return ["failed"] * (4 + len(BANDS))
    pose, point = record["metrics"][realistic_loop.METRIC], record["metrics"]["pointing"]
    return ([f"{fmt(pose['rms'])} / {fmt(pose['peak'])}", f"{fmt(point['rms'])} / {fmt(point['peak'])}",
             f"{fmt(point['path_rms'])} / {fmt(point['path_peak'])}"]
            + [fmt(point[loss_key(band)]) for band in BANDS])


def _scheme_cells(entry):
    """A scheme row's numbers (wind_rejection.run's entry), or 'failed' cells."""
    if entry is None:
        return ["failed"] * (4 + len(BANDS))
    return _cells({"status": "ok", "metrics": {realistic_loop.METRIC: entry, "pointing": entry["pointing"]}})


def table(results):
    """The budget as a Markdown table, one row per effect and feedforward, then the schemes."""
    results, schemes = results
    head = (["effect (alone)", "feedforward", "pose error RMS / peak [µm]", "pointing RMS / peak [arcsec]",
             "path-length error RMS / peak [µm]"]
            + [f"efficiency lost at {band} {optics.BANDS[band] / 1e9:g} GHz [%]" for band in BANDS])
    lines = ["| " + " | ".join(head) + " |", "|---" * len(head) + "|"]
    for label, loop, _, modes in ROWS:
        for k, mode in enumerate(modes):
            record = results.get(loop, {}).get("exact", {}).get(mode, {"status": "not run"})
            lines.append(f"| {label if k == 0 else ''} | {FEEDFORWARD_NAMES[mode]} | "
                         + " | ".join(_cells(record)) + " |")
    for label, scheme in SCHEME_ROWS + [(SUPPORT_ROW, "support")]:
        lines.append(f"| {label} | {FEEDFORWARD_NAMES['moving_base']} | "
                     + " | ".join(_scheme_cells(schemes.get(scheme))) + " |")
    return "\n".join(lines)


def chart_rows(results):
    """[(label, {mode: (peak pose error [µm], peak pointing [arcsec]) or None})] of the chart."""
    results, schemes = results
    pair = lambda pose, point: (pose["peak"], point["peak"])
    rows = []
    for label, loop, _, modes in ROWS:
        row = {}
        for mode in ("fixed_base", "moving_base"):
            record = results.get(loop, {}).get("exact", {}).get(mode)
            if record is not None:
                row[mode] = (pair(record["metrics"][realistic_loop.METRIC], record["metrics"]["pointing"])
                             if record.get("status") == "ok" else None)
        rows.append((label, row))
    for label, scheme in SCHEME_ROWS + [(SUPPORT_ROW, "support")]:
        entry = schemes.get(scheme)
        rows.append((label, {"moving_base": pair(entry, entry["pointing"]) if entry else None}))
    return rows


def chart(results, path=CHART):
    """Horizontal bars per effect: the peak pose error [µm] against the 10 µm and 0.1 mm marks,
    and the peak pointing error [arcsec] against Tianma's 3 arcsec, each feedforward in its
    colour, the value written at the bar. Returns the two axes (the figure is closed)."""
    rows = chart_rows(results)
    fig, axes = plt.subplots(1, 2, figsize=(13, 0.5 * len(rows) + 1.9), sharey=True, layout="constrained")
    for ax, k, unit, floor in ((axes[0], 0, "µm", 1e-2), (axes[1], 1, "arcsec", 1e-4)):
        values = [v[k] for _, row in rows for v in row.values() if v]
        for i, (_, row) in enumerate(rows):
            for j, mode in enumerate(("fixed_base", "moving_base")):
                y = i + (j - 0.5) * 0.38
                if mode not in row:
                    continue
                value = row[mode]
                colour = RUN_COLOURS[mode] if value else "red"
                if value:
                    ax.barh(y, max(value[k], floor) - floor, left=floor, height=0.36, color=colour)
                ax.text(max(value[k], floor) * 1.15 if value else floor * 1.5, y, fmt(value[k]) if value else "failed",
                        va="center", fontsize=7.5, color=colour)
        if k == 0:
            draw_marks(ax, vertical=True)
        else:
            ax.axvline(POINTING_SPEC, color="tab:red", lw=1, ls="--")
            ax.text(POINTING_SPEC, 1.0, " Tianma's 3 arcsec pointing", transform=ax.get_xaxis_transform(),
                    ha="left", va="bottom", fontsize=8, color="tab:red")
        ax.set_xscale("log")
        plain_log_axis(ax.xaxis, subs=(1.0,))
        ax.set_xlim(floor, max(max(values) * 6, 3 * POINTING_SPEC if k else 300.0))
        ax.set_xlabel(f"peak {'pose' if k == 0 else 'pointing'} error [{unit}] (log scale)")
        ax.grid(axis="x", which="major", alpha=0.3)
    axes[0].set_yticks(range(len(rows)), [label for label, _ in rows], fontsize=8.5)
    axes[0].set_ylim(len(rows) - 0.5, -0.6)
    handles = [matplotlib.patches.Patch(color=RUN_COLOURS[m], label=FEEDFORWARD_NAMES[m])
               for m in ("fixed_base", "moving_base")]
    fig.legend(handles=handles, loc="outside lower center", ncol=2, fontsize=8.5, frameon=False)
    fig.suptitle(f"{SCENE}, 8 s ([ci]: settling, then the slew's acceleration): each effect alone, everything "
                 "in 10 m/s wind, and the wind rejection schemes", fontsize=10)
    save(fig, path)
    return axes


def report(results, seconds, jobs, path=REPORT):
    """Write docs/error-budget.md."""
    lines = ["# Error budget in the telescope's units", "",
             "Generated by `python -m studies.error_budget` (the runs took "
             f"{seconds:.0f} s of wall time on {jobs or 'all'} worker{'s' * (jobs != 1)}).", "",
             f"The `{SCENE}` scene at its [ci] length, 8 s: the loops settle for 5 s at the start pointing, then the "
             "slew accelerates for 3 s (numbers count from 5 s). Short on purpose, to keep the study cheap; the "
             "full 60 s slew and the keyhole track, in µm, are in [realistic_loop.md](realistic_loop.md). Each effect "
             "is switched on alone in the ideal loop, with the realistic loop's settings (studies/realistic_loop.py); "
             "the row 'all effects' has them all, with a 10 m/s wind, and the last rows add a wind rejection scheme "
             "to it ([wind-rejection.md](wind-rejection.md): the disturbance observer on load cells, the "
             "anemometer's feedforward).", "",
             "Units (plant/telescope/optics.py, [the telescope's conventions](conventions/telescope.md#what-an-error-"
             "costs-pointing-and-aperture-efficiency)): the pointing error of the beam from the subreflector's lateral "
             "offset and tilt; the path-length error over the aperture once piston and tilt are removed; the aperture "
             "efficiency it costs by Ruze's law at the RMS path-length error, K 22 GHz and Q 43 GHz (Tianma's "
             "receivers). The geometry beyond D = 65 m is assumed.", "",
             table(results), "", f"![error budget](figures/{CHART.name})", "",
             f"The last row is not the hexapod's error: the feed support's sway ([models.md](models.md#telescope-the-"
             f"flexible-feed-support); the shipped `{SUPPORT}` scene at its [ci] length, from 5 s) moves the hexapod's "
             "base and with it the subreflector, which the hexapod, holding its pose in {B}, does not correct. Its "
             "µm are the sway's position at the base, its arcsec and efficiency the subreflector's motion with it "
             "through the same optics; a steady part under the start's wind is in it (the scene's preload).", ""]
    chart(results)
    path.write_text("\n".join(lines))


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--jobs", type=int, help="worker processes (default: all cores)")
    parser.add_argument("--out", default="out")
    args = parser.parse_args(argv)
    began = time.perf_counter()
    results = run(args.out, args.jobs)
    report(results, time.perf_counter() - began, args.jobs)
    print(table(results))
    print(f"wrote {REPORT.relative_to(ROOT)}")


if __name__ == "__main__":
    main()
