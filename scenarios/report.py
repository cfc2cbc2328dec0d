"""Charts and a short Markdown report of a scenario's runs: the metrics table, tracking
error against time for every run on one figure, a summary bar chart against the
telescope's 0.1 mm and 10 µm marks, and what the base motion adds and why."""
import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt

MARKS_UM = {"0.1 mm": 100.0, "10 µm": 10.0}
TRACKING = ("leg_tracking", "pose_tracking", "tracking")


def _error_chart(scenario, runs, metric, path):
    fig, ax = plt.subplots(figsize=(9, 4.5))
    for run in runs:
        t, values = run.series[metric.name]
        ax.plot(t, values, label=run.label, lw=1)
    for text, level in MARKS_UM.items():
        ax.axhline(level, color="grey", ls="--", lw=0.8)
        ax.text(1.0, level, text + " ", transform=ax.get_yaxis_transform(), ha="right", va="bottom",
                fontsize=8, color="grey")
    ax.set_yscale("log")
    ax.set_xlabel("time [s]")
    ax.set_ylabel(f"{metric.name}, RMS over legs/axes [µm]")
    ax.set_title(f"{scenario.name}: {metric.name}")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(title=scenario.sweep[0] if scenario.sweep else None)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _summary_chart(scenario, runs, tracked, path):
    fig, axes = plt.subplots(1, len(tracked), figsize=(4.5 * len(tracked), 4), squeeze=False)
    labels = [r.label for r in runs]
    for ax, metric in zip(axes[0], tracked):
        rms = [r.metrics[metric.name]["rms"] for r in runs]
        peak = [r.metrics[metric.name]["peak"] for r in runs]
        x = range(len(runs))
        ax.bar([i - 0.2 for i in x], rms, 0.4, label="RMS")
        ax.bar([i + 0.2 for i in x], peak, 0.4, label="peak")
        for text, level in MARKS_UM.items():
            ax.axhline(level, color="grey", ls="--", lw=0.8)
            ax.text(1.0, level, text + " ", transform=ax.get_yaxis_transform(), ha="right", va="bottom",
                    fontsize=8, color="grey")
        ax.set_yscale("log")
        ax.set_xticks(list(x), labels)
        ax.set_ylabel("µm")
        ax.set_title(metric.name)
        ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _fmt(value):
    if isinstance(value, float):
        return "n/a" if value != value else f"{value:.4g}"
    return str(value)


def _stopped(scenario, run):
    """'failed at t = 5.01 s, partial: 5.01 of 8 s' for a failed run, else ''."""
    if not run.failure:
        return ""
    return (f"failed at t = {scenario.start_time + run.sim_time:g} s, partial: {run.sim_time:g} of "
            f"{scenario.stop_time - scenario.start_time:g} s")


def write(scenario, runs, outdir):
    """Write charts and report.md into outdir; return the report's path."""
    tracked = [m for m in scenario.metrics if m.kind in TRACKING]
    lines = [f"# {scenario.name}", "", scenario.description, "",
             f"Master {scenario.master}, extrapolation {scenario.extrapolation}, communication step "
             f"{scenario.step * 1e3:g} ms, {scenario.stop_time - scenario.start_time:g} s simulated.", "",
             "| run | " + " | ".join(f"{m.name} ({runs[0].metrics[m.name]['unit']})" for m in scenario.metrics)
             + " | wall time [s] | real-time factor |",
             "|---" * (len(scenario.metrics) + 3) + "|"]
    for run in runs:
        cells = []
        for m in scenario.metrics:
            result = run.metrics[m.name]
            cells.append(", ".join(f"{k} {_fmt(v)}" for k, v in result.items() if k != "unit"))
        label = f"{run.label} **{_stopped(scenario, run)}**" if run.failure else run.label
        lines.append(f"| {label} | " + " | ".join(cells) + f" | {run.wall_time:.2f} | {run.real_time_factor:.1f} |")
    lines.append("")
    lines += [f"- **run {r.label} {_stopped(scenario, r)}**; its row covers the run up to then: {r.failure}"
              for r in runs if r.failure]
    lines += [f"- {note}" for note in scenario.notes]
    lines += _findings(scenario, runs, tracked)
    for metric in tracked:
        chart = outdir / f"{metric.name.replace(' ', '_')}_vs_time.png"
        _error_chart(scenario, runs, metric, chart)
        lines += [f"![{metric.name} against time]({chart.name})", ""]
    if tracked and len(runs) > 1:
        _summary_chart(scenario, runs, tracked, outdir / "summary.png")
        lines += ["![summary](summary.png)", ""]
    lines += [f"Results per run: {', '.join(f'`{r.csv_path.name}`' for r in runs if r.csv_path)} "
              "(CSV, units in the header)."]
    path = outdir / "report.md"
    path.write_text("\n".join(lines) + "\n")
    return path


def _findings(scenario, runs, tracked):
    """Plain sentences: what ignoring base motion costs (fixed- vs moving-base feedforward)
    and the size of the base-motion terms."""
    lines = []
    by_label = {r.label: r for r in runs}
    for metric in tracked:
        if {"fixed_base", "moving_base"} <= set(by_label):
            fixed = by_label["fixed_base"].metrics[metric.name]
            moving = by_label["moving_base"].metrics[metric.name]
            failed = [r for r in (by_label["fixed_base"], by_label["moving_base"]) if r.failure]
            partial = "".join(f" (run {r.label} {_stopped(scenario, r)})" for r in failed)
            if any(result["rms"] != result["rms"] for result in (fixed, moving)):
                lines.append(f"- **{metric.name}**: no fixed- against moving-base comparison: the metric counted "
                             f"nothing before the run stopped{partial}.")
                continue
            lines.append(f"- **{metric.name}**: ignoring the base motion in the feedforward gives RMS "
                         f"{fixed['rms']:.3g} µm and peak {fixed['peak']:.3g} µm, against {moving['rms']:.3g} µm "
                         f"and {moving['peak']:.3g} µm with the moving-base model "
                         f"({fixed['rms'] / max(moving['rms'], 1e-30):.3g}x the RMS){partial}.")
    for metric in scenario.metrics:
        if metric.kind == "base_effect":
            r = runs[0].metrics[metric.name]
            partial = f" (run {runs[0].label} {_stopped(scenario, runs[0])})" if runs[0].failure else ""
            lines.append(f"- **why**: along this motion the base changes the leg forces by up to {r['peak']:.3g} kN; "
                         f"gravity turning with the base accounts for up to {r['gravity_peak']:.3g} kN, the "
                         f"transport, centripetal and Coriolis terms for up to {r['transport_peak']:.3g} kN{partial}.")
    return lines + [""] if lines else []
