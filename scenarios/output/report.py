"""Charts and a short Markdown report of a scenario's runs: the settings, the metrics
table, tracking error against time for every run with the base motion that causes it
underneath, a summary bar chart against the telescope's 0.1 mm and 10 µm marks, and
what the base motion adds and why.

The sentences and numbers comparing the runs come from ``compare`` and ``fmt``, which
the README's generated headline (``scenarios.output.headline``) uses too: one source for each
number."""
import textwrap

import numpy as np

from fmu_src import atomic
from scenarios.cosim.records import run_records
from scenarios.output.charts import (  # noqa: F401
    FLOOR,
    FLOOR_NOTE,
    MARKS_UM,
    draw_marks,
    fmt,
    length,
    plain_log_axis,
    ratio,
    run_colour,
    save,
)
from scenarios.spec import judge

TRACKING = ("leg_tracking", "pose_tracking", "tracking")
COINCIDE = 0.02      # two curves closer than this fraction of their peak are said to coincide
# runs told apart by line style as well as colour: a wide pale line under a dashed one
# shows two coinciding runs
RUN_STYLES = ({"ls": "-", "lw": 3.0, "alpha": 0.45}, {"ls": (0, (5, 2)), "lw": 1.4},
              {"ls": "-", "lw": 1.0}, {"ls": "-.", "lw": 1.0}, {"ls": ":", "lw": 1.4})
CHARTS = ("all", "summary", "none")   # what a run draws: every chart, the summary bars only, none
RUN_MEANING = {"none": "PID alone, no feedforward",
               "fixed_base": "PID + feedforward from the fixed-base model (the base motion ignored)",
               "moving_base": "PID + feedforward from the moving-base model"}


def _figure(rows, cols, size, left, right, top, bottom, gap, **kw):
    """A figure of rows x cols axes with margins and gaps fixed in inches, room for the
    kit's labels: constrained layout measured every tick label in two passes and cost
    ~45 % of a chart's time (docs/speed.md). A plain Figure, not pyplot's: drawing leaves the
    caller's backend and pyplot's figures alone (a notebook's inline plots), and
    matplotlib is imported here, so a run without charts does not pay its import."""
    from matplotlib.figure import Figure
    w, h = size
    inner_w, inner_h = w - left - right, h - top - bottom
    fig = Figure(figsize=size)
    axes = fig.subplots(rows, cols, squeeze=False, gridspec_kw={
        "left": left / w, "right": 1 - right / w, "top": 1 - top / h, "bottom": bottom / h,
        "hspace": gap * rows / (inner_h - gap * (rows - 1)), "wspace": gap * cols / (inner_w - gap * (cols - 1)),
        **kw.pop("gridspec_kw", {})}, **kw)
    return fig, axes


def _log_axis(ax):
    """A log error axis labelled at the decades in plain numbers (0.001, 10), no minor
    ticks: the major grid is what a person reads, and the minor ticks' objects and the
    mathtext of 10^n labels were a third of a chart's drawing."""
    from matplotlib import ticker
    ax.set_yscale("log")
    plain_log_axis(ax.yaxis, subs=(1.0,))
    ax.yaxis.set_minor_locator(ticker.NullLocator())


def compare(metrics_by_run, metric, unit="µm", flagged=None):
    """The fixed- against moving-base sentence for one tracking metric, or None. ``flagged``
    {run: [Flag]}: if either run is flagged, only the sentence that says no comparison
    is made (a flagged run's numbers are not results)."""
    if not {"fixed_base", "moving_base"} <= set(metrics_by_run):
        return None
    bad = {k: v for k, v in (flagged or {}).items() if k in ("fixed_base", "moving_base") and v}
    if bad:
        return "no fixed- against moving-base comparison: " + "; ".join(
            f"run `{k}` is flagged ({', '.join(dict.fromkeys(f.kind for f in v))})" for k, v in bad.items()) + "."
    fixed, moving = metrics_by_run["fixed_base"][metric], metrics_by_run["moving_base"][metric]
    text = (f"ignoring the base motion (run `fixed_base`: the feedforward uses the fixed-base model) gives "
            f"RMS {length(fixed['rms'], unit)} and peak {length(fixed['peak'], unit)}, against "
            f"{length(moving['rms'], unit)} and {length(moving['peak'], unit)} with the moving-base model "
            f"(run `moving_base`)")
    if moving["peak"] < FLOOR:
        return text + ("; the moving-base error stays under the 1 nm the model resolves, so its ratio to the "
                       "fixed-base error means nothing.")
    text += f": {ratio(fixed['rms'], moving['rms'])} the RMS, {ratio(fixed['peak'], moving['peak'])} the peak"
    if "rotation_rms" in fixed:
        text += (f"; rotation error RMS {length(fixed['rotation_rms'], 'µrad')} against "
                 f"{length(moving['rotation_rms'], 'µrad')} "
                 f"({ratio(fixed['rotation_rms'], moving['rotation_rms'])})")
    return text + "."


def _series(run, name, scale):
    t, values = run.series[name]
    return np.asarray(t), np.asarray(values) * scale


def _error_panel(ax, runs, name, scale, unit, marks):
    """One log panel of an error for every run, in its run kind's colour; returns notes on
    coinciding curves and curves under the floor (they would otherwise be invisible).
    ``marks``: draw the 10 µm and 0.1 mm pose marks (platform position only)."""
    data = [(run.label, *_series(run, name, scale)) for run in runs]
    for k, (label, t, v) in enumerate(data):
        ax.plot(t, v, label=label, color=run_colour(label, k), **RUN_STYLES[k % len(RUN_STYLES)])
    notes = []
    for i in range(len(data)):
        for j in range(i + 1, len(data)):
            (a, ta, va), (b, tb, vb) = data[i], data[j]
            if len(va) and va.shape == vb.shape and np.allclose(ta, tb):
                peak = max(va.max(), vb.max())
                diff = float(np.abs(va - vb).max())
                if peak > FLOOR and diff <= COINCIDE * peak:
                    notes.append(f"{a} and {b} coincide: largest difference {length(diff, unit)} "
                                 f"({100 * diff / peak:.2g} % of the peak)")
    for label, t, v in data:
        if len(v) and v.max() < FLOOR:
            notes.append(f"{label}: under the floor throughout (peak {length(v.max(), unit)})")
    top = max([v.max() for _, _, v in data if len(v)] + [FLOOR * 10])
    if marks:
        top = max([top] + [MARKS_UM[m] for m in draw_marks(ax, top)])
    _log_axis(ax)
    ax.set_ylim(FLOOR, top * 2.5)
    ax.grid(True, which="major", alpha=0.3)
    if notes:
        ax.text(0.01, 0.03, "\n".join(notes), transform=ax.transAxes, fontsize=7.5, va="bottom",
                bbox={"facecolor": "white", "alpha": 0.85, "edgecolor": "0.7"})
    return notes


def _telescope(scenario):
    return next((inst for inst, fmu in scenario.fmus.items() if fmu == "telescope"), None)


def base_motion(scenario, run):
    """Time, rates [deg/s] and accelerations [deg/s^2] (differenced from the recorded
    rates) of the scenario's telescope axes, from the run's records; None if the axis
    rates were not recorded (or the run failed before recording any), or the plant holds its
    base fixed (moving_base = 0)."""
    inst = _telescope(scenario)
    plants = [i for i, fmu in scenario.fmus.items() if fmu == "hexapod_plant"]
    if inst is None or (plants and all(str(scenario.parameters.get(i, {}).get("moving_base", 1)) == "0"
                                       for i in plants)):
        return None     # no telescope, or its motion is not applied to the plant
    records = run_records(run)
    if records is None:
        return None
    want = [f"{inst}.axis_rate[{k}]" for k in (1, 2)]
    if not all(w in records.names for w in want):
        return None
    data = np.column_stack([records.time] + [records[w] for w in want])
    t, rate = data[:, 0], np.degrees(data[:, 1:])
    if len(t) < 3:
        return None
    return t, rate, np.gradient(rate, t, axis=0)


def _motion_panels(ax_rate, ax_acc, motion, interval):
    t, rate, acc = motion
    for k, name in enumerate(("azimuth", "elevation")):
        ax_rate.plot(t, rate[:, k], color=f"C{k + 5}", label=name, lw=1.2)
        ax_acc.plot(t, acc[:, k], color=f"C{k + 5}", label=name, lw=1.2)
    ax_rate.set_ylabel("axis rate\n[deg/s]")
    ax_acc.set_ylabel("axis acceleration\n[deg/s²]")
    ax_acc.text(0.01, 0.04, f"acceleration: difference of the rates recorded every {interval * 1e3:g} ms",
                transform=ax_acc.transAxes, fontsize=7.5, color="0.3")
    for ax in (ax_rate, ax_acc):
        ax.grid(True, alpha=0.3)
        ax.axhline(0.0, color="0.5", lw=0.6)


def _error_chart(scenario, runs, metric, path):
    """Error against time, one colour and line style per run (coinciding runs noted), log
    axis floored at 1 nm, the settling cut-off marked; a pose metric gets a position panel
    with the 10 µm and 0.1 mm marks and a rotation panel; the telescope's axis rates and accelerations underneath on
    the same
    time axis. Returns the figure's data panels {title: axes} (the figure is closed)."""
    motion = base_motion(scenario, next((r for r in runs if r.records is not None or r.record_path), runs[0]))
    rows = [("position", 1.0, "µm", False)]      # the pose marks are no leg-length requirement
    if metric.kind == "pose_tracking":
        rows = [("position", 1.0, "µm", True), ("rotation", 1e6, "µrad", False)]
    n = len(rows) + (2 if motion else 0)
    fig, axes = _figure(n, 1, (10, 1.6 + 2.1 * n), left=1.15, right=0.6, top=0.55, bottom=1.1, gap=0.2,
                        sharex=True, gridspec_kw={"height_ratios": [3] * len(rows) + [1.6] * (n - len(rows))})
    axes = axes[:, 0]
    panels = {}
    for ax, (kind, scale, unit, marks) in zip(axes, rows):
        name = metric.name if kind == "position" else metric.name + " rotation"
        _error_panel(ax, runs, name, scale, unit, marks)
        if metric.kind == "pose_tracking":
            label = ("platform position error\n|p - p_ref| [µm]" if kind == "position"
                     else "platform rotation error\nangle of R_ref^T R [µrad]")
        elif metric.kind == "leg_tracking":
            label = "leg length error\nRMS over the 6 legs [µm]"
        else:
            label = f"{metric.name}\nRMS over components [µm]"
        ax.set_ylabel(label)
        panels[kind] = ax
    if motion:
        _motion_panels(axes[-2], axes[-1], motion, scenario.record_interval)
        panels["axis rate"], panels["axis acceleration"] = axes[-2], axes[-1]
    for ax in axes:
        ax.set_xlim(scenario.start_time, scenario.stop_time)
        if metric.start > scenario.start_time:
            ax.axvspan(scenario.start_time, metric.start, color="0.93", zorder=0)
            ax.axvline(metric.start, color="0.4", lw=0.9, ls=":")
    if metric.start > scenario.start_time:
        axes[0].text(0.5 * (scenario.start_time + metric.start), 0.5,
                     f"settling {scenario.start_time:g}-{metric.start:g} s: not measured", rotation=90,
                     transform=axes[0].get_xaxis_transform(), ha="center", va="center", fontsize=7.5, color="0.3")
    mark_flagged(axes[:len(rows)], runs)
    handles, labels = axes[0].get_legend_handles_labels()
    fig.legend(handles, labels, title=(scenario.sweep[0] if scenario.sweep else None), fontsize=8.5,
               title_fontsize=8.5, loc="lower left", bbox_to_anchor=(0.005, 0.005), ncol=len(runs))
    if motion:
        fig.legend(*axes[-1].get_legend_handles_labels(), title="base motion: telescope axes", fontsize=8.5,
                   title_fontsize=8.5, loc="lower right", bbox_to_anchor=(0.995, 0.005), ncol=2)
    axes[-1].set_xlabel("time [s]")
    fig.suptitle(f"{scenario.name}: {metric.name} against time (measured from {metric.start:g} s)\n{FLOOR_NOTE}",
                 fontsize=10)
    save(fig, path)
    return panels


FLAG_COLOR = "red"


def variables_chart(label, time, columns, status=""):
    """One panel per recorded variable against time, a vector's components as lines
    ``[k]``, each axis labelled with the variable's unit; ``columns`` is [(name, unit,
    values rows x n, the components' labels)]. A failed or flagged run says so in the
    title, in red: its numbers are not results. Returns the figure."""
    fig, axes = _figure(len(columns), 1, (9, 1.0 + 1.9 * len(columns)), left=1.1, right=1.4, top=0.5,
                        bottom=0.6, gap=0.25, sharex=True)
    for ax, (name, unit, values, labels) in zip(axes[:, 0], columns):
        for column, component in zip(values.T, labels):
            ax.plot(time, column, lw=1.0, label=component or None)
        ax.set_ylabel(f"{name}\n[{unit or '-'}]")
        ax.grid(True, lw=0.4, color="0.85")
        if values.shape[1] > 1:
            ax.legend(loc="center left", bbox_to_anchor=(1.0, 0.5), fontsize=7.5, frameon=False)
    axes[-1, 0].set_xlabel("time [s]")
    title = textwrap.shorten(f"run {label}" + (f": {status}" if status else ""), 230, placeholder=" ...")
    fig.suptitle("\n".join(textwrap.wrap(title, 115)), fontsize=9.5,
                 color="0.1" if not status else "#b00020")
    return fig


def mark_flagged(axes, runs, bars=False):
    """Mark a flagged run where a chart shows it: its curves get red crosses and
    "(FLAGGED)" in the legend, its bars a red hatched band and a red tick label; a red
    note in the first panel says which runs and why (their numbers are not results)."""
    flagged = {r.label: r for r in runs if r.flags}
    if not flagged:
        return
    for ax in axes:
        if bars:
            ticks = ax.get_xticklabels()
            for k, run in enumerate(runs):
                if run.label in flagged:
                    ax.axvspan(k - 0.45, k + 0.45, facecolor="none", edgecolor=FLAG_COLOR, hatch="//", lw=0,
                               alpha=0.35, zorder=0)
                    ticks[k].set_text(f"{run.label}\nFLAGGED")
                    ticks[k].set_color(FLAG_COLOR)
            ax.set_xticks(ax.get_xticks(), ticks)
        else:
            for line in ax.get_lines():
                if line.get_label() in flagged:
                    line.set(marker="x", markevery=0.04, markeredgecolor=FLAG_COLOR, markersize=6,
                             label=f"{line.get_label()} (FLAGGED)")
    why = "\n".join(f"{label}: {', '.join(dict.fromkeys(f.kind for f in run.flags))}" for label, run in flagged.items())
    note = axes[0].text(0.01, 0.97, f"FLAGGED, not results (why: report.md)\n{why}", transform=axes[0].transAxes,
                        fontsize=7.5, color=FLAG_COLOR, va="top", ha="left",
                        bbox={"facecolor": "white", "edgecolor": FLAG_COLOR, "alpha": 0.85, "pad": 2})
    note.set_in_layout(False)


def _summary_quantities(tracked):
    """(title, metric name, rms key, peak key, unit) of every bar panel."""
    out = []
    for m in tracked:
        if m.kind == "pose_tracking":
            out += [(f"{m.name}: platform position", m.name, "rms", "peak", "µm"),
                    (f"{m.name}: platform rotation", m.name, "rotation_rms", "rotation_peak", "µrad")]
        elif m.kind == "leg_tracking":
            out.append((f"{m.name}: leg length (6 legs)", m.name, "rms", "peak", "µm"))
        else:
            out.append((m.name, m.name, "rms", "peak", "µm"))
    return out


def _summary_chart(scenario, runs, tracked, path):
    """RMS (pale, hatched) and peak per run in the run kind's colour, on a log scale
    floored at 1 nm (a run 100x better than another still shows), each bar labelled with
    its value ("< 1 nm" under the floor); the 10 µm and 0.1 mm marks on the platform
    position panel, where they fit (else said). Returns {panel title: axes} (the figure is
    closed)."""
    from matplotlib.patches import Patch
    quantities = _summary_quantities(tracked)
    fig, axes = _figure(1, len(quantities), (4.4 * len(quantities), 4.4), left=0.85, right=0.6, top=0.75,
                        bottom=0.75, gap=1.4)   # a gap holds a panel's mark names and the next one's labels
    labels = [r.label for r in runs]
    colours = [run_colour(label, k) for k, label in enumerate(labels)]
    x = np.arange(len(runs))
    panels = {}
    for ax, (title, name, rms_key, peak_key, unit) in zip(axes[0], quantities):
        rms = [r.metrics[name][rms_key] for r in runs]
        peak = [r.metrics[name][peak_key] for r in runs]
        top = max([v for v in peak + rms if np.isfinite(v)] + [10 * FLOOR])   # a failed run's NaN: no bar
        for offset, values, style in ((-0.2, rms, {"alpha": 0.45, "hatch": "//"}), (0.2, peak, {})):
            heights = [max(v - FLOOR, 0.0) if np.isfinite(v) else np.nan for v in values]
            bars = ax.bar(x + offset, heights, 0.4, bottom=FLOOR, color=colours, edgecolor=colours, **style)
            ax.bar_label(bars, [length(v, unit).removesuffix(f" {unit}") for v in values], fontsize=7.5, padding=2)
        off_scale = []
        if unit == "µm" and "position" in title:
            drawn = draw_marks(ax, top)
            top = max([top] + [MARKS_UM[m] for m in drawn])
            off_scale = [m for m in MARKS_UM if m not in drawn]
        if off_scale:
            ax.text(0.02, 0.97, f"{' and '.join(off_scale)} marks: off the scale, above it", transform=ax.transAxes,
                    fontsize=7.5, va="top", color="0.3")
        _log_axis(ax)
        ax.set_ylim(FLOOR, top * 4)
        ax.set_xticks(x, labels)
        ax.set_ylabel(f"error [{unit}] (log scale, floored at 1 n{unit[1:]})")
        ax.grid(True, axis="y", which="major", alpha=0.3)
        ax.set_title(title, fontsize=10)
        panels[title] = ax
    mark_flagged(axes[0], runs, bars=True)
    start = max(m.start for m in tracked)
    fig.suptitle(f"{scenario.name}: tracking error after the {start:g} s settling, by "
                 f"{scenario.sweep[0] if scenario.sweep else 'run'}", fontsize=10)
    fig.legend(handles=[Patch(facecolor="0.5", alpha=0.45, hatch="//", edgecolor="0.5", label="RMS"),
                        Patch(facecolor="0.5", label="peak")], loc="lower center", bbox_to_anchor=(0.5, 0.005), ncol=2,
               fontsize=8.5)
    save(fig, path)
    return panels


def settings(scenario):
    """Markdown lines: what was run and what each number measures against what."""
    duration = scenario.stop_time - scenario.start_time
    lines = ["## Settings", "",
             f"- co-simulation: master {scenario.master}, input extrapolation {scenario.extrapolation}, "
             f"communication step {scenario.step * 1e3:g} ms, {scenario.start_time:g}-{scenario.stop_time:g} s "
             f"({duration:g} s) simulated, recorded every {scenario.record_interval * 1e3:g} ms"]
    for inst, fmu in scenario.fmus.items():
        params = scenario.parameters.get(inst, {})
        shown = ", ".join(f"{k} {v}" for k, v in params.items() if not str(v).startswith("@"))
        lines.append(f"- `{inst}` ({fmu}): {shown or 'defaults'}")
    if scenario.sweep:
        param, values = scenario.sweep
        meant = "; ".join(f"`{v}` = {RUN_MEANING[v]}" if v in RUN_MEANING else f"`{v}`" for v in values)
        lines.append(f"- runs: one per value of `{param}`: {meant}")
    for m in scenario.metrics:
        lines.append(f"- **{m.name}** ({m.kind}): {_measures(m)}"
                     + (f", from {m.start:g} s (before that the loops settle)" if m.start else ""))
    lines += ["- wall time: the co-simulation stepping loop only (FMU loading, instantiation and initialisation "
              "excluded); real-time factor = simulated time / that wall time", ""]
    return lines


def _measures(m):
    a = m.args
    if m.kind == "leg_tracking":
        return f"`{a['measured']}` against the leg lengths of `{a['reference_pose']}` (inverse kinematics), µm"
    if m.kind == "pose_tracking":
        return (f"`{a['measured']}` against `{a['reference']}`: position error |p - p_ref| [µm] and rotation "
                f"error angle [µrad]")
    if m.kind == "tracking":
        return f"`{a['measured']}` against `{a['reference']}`, µm"
    if m.kind == "peak":
        return f"largest |`{a['variable']}`|, kN"
    if m.kind == "base_effect":
        return ("leg-force change the base motion causes along the reference and base motion (inverse "
                "dynamics, full against no-base model); the same for every run, kN")
    if m.kind == "pointing":
        return (f"`{a['measured']}` against `{a['reference']}` in the telescope's units (Tianma's Cassegrain, "
                "plant/telescope/optics.py): pointing error [arcsec], path-length error over the aperture less "
                "piston and tilt [µm], aperture efficiency lost by Ruze's law at 15-43 GHz [%]")
    return m.kind


def _cell(result):
    if "rotation_rms" in result:   # a pose: position and rotation, each with its unit
        return (f"position RMS {fmt(result['rms'])} µm, peak {fmt(result['peak'])} µm; rotation RMS "
                f"{fmt(result['rotation_rms'])} µrad, peak {fmt(result['rotation_peak'])} µrad")
    if "path_rms" in result:       # pointing: angle, path-length error, efficiency losses
        losses = ", ".join(f"{k.removeprefix('efficiency_loss_').replace('GHz', ' GHz')} {fmt(v)} %"
                           for k, v in result.items() if k.startswith("efficiency_loss_"))
        return (f"pointing RMS {fmt(result['rms'])} arcsec, peak {fmt(result['peak'])} arcsec; path error RMS "
                f"{fmt(result['path_rms'])} µm, peak {fmt(result['path_peak'])} µm; efficiency lost {losses}")
    return ", ".join(f"{k} {fmt(v)}" for k, v in result.items() if k != "unit")


def _stopped(scenario, run):
    """'failed at t = 5.01 s, partial: 5.01 of 8 s' for a failed run, else ''."""
    if not run.failure:
        return ""
    return (f"failed at t = {scenario.start_time + run.sim_time:g} s, partial: {run.sim_time:g} of "
            f"{scenario.stop_time - scenario.start_time:g} s")


def write(scenario, runs, outdir, charts="all", interrupted=()):
    """Write report.md and the ``charts`` (one of CHARTS: every chart, the summary bars
    of several runs only, or none) into outdir; return the report's path. ``interrupted``:
    the labels of the runs Ctrl-C left unrun (said first: the report is not the sweep's)."""
    if charts not in CHARTS:
        raise ValueError(f"charts must be one of {', '.join(CHARTS)}, got {charts!r}")
    tracked = [m for m in scenario.metrics if m.kind in TRACKING]
    per_run = [m for m in scenario.metrics if m.kind != "base_effect"]   # base effect: same for every run
    lines = [f"# {scenario.name}", "", scenario.description, ""]
    if interrupted:
        lines += [f"**Interrupted** (Ctrl-C): runs {', '.join(f'`{label}`' for label in interrupted)} were not run "
                  "to their end; this report holds the runs that finished.", ""]
    lines += flag_lines(runs) + settings(scenario)
    lines += ["## Results", "",
              "| run | " + " | ".join(f"{m.name} ({runs[0].metrics[m.name]['unit']})" for m in per_run)
              + " | wall time [s] | real-time factor |",
              "|---" * (len(per_run) + 3) + "|"]
    for run in runs:
        cells = [_cell(run.metrics[m.name]) for m in per_run]
        label = f"{run.label} **{_stopped(scenario, run)}**" if run.failure else run.label
        label += " **FLAGGED**" if any(f.kind != "cut_short" for f in run.flags) else ""   # a stop: said above
        lines.append(f"| {label} | " + " | ".join(cells) + f" | {run.wall_time:.2f} | {run.real_time_factor:.1f} |")
    lines.append("")
    lines += [f"- **run {r.label} {_stopped(scenario, r)}**; its row covers the run up to then: {r.failure}"
              for r in runs if r.failure]
    lines += [f"- {note}" for note in scenario.notes]
    lines += requirement_lines(scenario, runs)
    lines += _findings(scenario, runs, tracked)
    for metric in tracked if charts == "all" else ():
        chart = outdir / f"{metric.name.replace(' ', '_')}_vs_time.png"
        _error_chart(scenario, runs, metric, chart)
        lines += [f"![{metric.name} against time]({chart.name})", ""]
    if tracked and len(runs) > 1 and charts != "none":
        _summary_chart(scenario, runs, tracked, outdir / "summary.png")
        lines += ["![summary](summary.png)", ""]
    lines += [f"Results per run: {', '.join(f'`{r.record_path.name}`' for r in runs if r.record_path)} "
              "(npz, one array per column named with its unit: `pandas.DataFrame(dict(numpy.load(file)))`)."]
    path = outdir / "report.md"
    atomic.write_text(path, "\n".join(lines) + "\n")
    return path


def requirement_lines(scenario, runs):
    """Markdown: the file's requirements judged per run, a table ([] if it has none)."""
    judged = [(run.label, j) for run in runs for j in judge(scenario.requirements, run.label, run.metrics)]
    if not judged:
        return []
    lines = ["", "### Requirements", "", "| run | requirement | value | |", "|---|---|---|---|"]
    lines += [f"| {label} | {j['requirement']} | {'not counted' if j['value'] is None else fmt(j['value'])} "
              f"{j['unit'] if j['value'] is not None else ''} | {'met' if j['met'] else '**NOT MET**'} |"
              for label, j in judged]
    return lines + [""]


def flag_lines(runs):
    """Markdown: each flagged run and why, first in the report ([] if none)."""
    flagged = [r for r in runs if r.flags]
    if not flagged:
        return []
    lines = ["## Flagged runs: their numbers are not results", ""]
    for run in flagged:
        lines += [f"- **{run.label}** {flag.kind}: {flag.message}" for flag in run.flags]
    return lines + [""]


def base_effect_text(result):
    """The 'why' sentence of a base_effect metric (one value: it depends on the motion only)."""
    return (f"along this motion the base changes the leg forces by up to {fmt(result['peak'])} kN; gravity turning "
            f"with the base accounts for up to {fmt(result['gravity_peak'])} kN, the transport, centripetal and "
            f"Coriolis terms for up to {fmt(result['transport_peak'])} kN (the same for every run: it depends on "
            f"the reference and base motion only)")


def _findings(scenario, runs, tracked):
    """Plain sentences: what ignoring base motion costs (fixed- vs moving-base feedforward)
    and the size of the base-motion terms."""
    lines = []
    by_label = {r.label: r.metrics for r in runs}
    by_label_run = {r.label: r for r in runs}
    flagged = {r.label: r.flags for r in runs if r.flags}
    for metric in tracked:
        failed = [by_label_run[k] for k in ("fixed_base",
                                            "moving_base") if k in by_label_run and by_label_run[k].failure]
        partial = "".join(f" (run {r.label} {_stopped(scenario, r)})" for r in failed)
        if failed and any(
            by_label[r.label][metric.name]["rms"] != by_label[r.label][metric.name]["rms"] for r in failed
        ):
            lines.append(f"- **{metric.name}**: no fixed- against moving-base comparison: the metric counted "
                         f"nothing before the run stopped{partial}.")
            continue
        sentence = compare(by_label, metric.name, flagged=flagged)
        if sentence:
            lines.append(f"- **{metric.name}**: {sentence}{partial}")
    source = next((r for r in runs if not r.flags), None)   # the motion's terms, from a run that is not flagged
    for metric in scenario.metrics:
        if metric.kind == "base_effect":
            if source is None:
                lines.append("- **why**: not written: every run is flagged.")
                continue
            partial = f" (run {source.label} {_stopped(scenario, source)})" if source.failure else ""
            lines.append(f"- **why**: {base_effect_text(source.metrics[metric.name])}{partial}.")
    return lines + [""] if lines else []
