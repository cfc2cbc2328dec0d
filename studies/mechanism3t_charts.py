"""Charts of the 3T mechanism: workspace (paper Fig. 11-12) and slider forces of the paper example (Fig. 13)."""
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

from plant.mechanism3t import model as m3t
from scenarios.output.charts import save

PAPER_PEAK_FORCE_N = 142.2


def _section(ax, points, axes, keep, **style):
    sel = points[keep(points)] * 1e3
    ax.scatter(sel[:, axes[0]], sel[:, axes[1]], s=2, **style)


def slider_force_chart(history, path):
    """Slider forces of the paper example against the paper's peak; returns the axes (the
    figure is closed)."""
    fig = Figure(figsize=(8, 4.5))
    ax = fig.subplots()
    for k, name in enumerate(("x_A2", "y_A1", "y_A3")):
        ax.plot(history.t, history.forces[:, k], label=f"slider {name}")
    ax.axhline(PAPER_PEAK_FORCE_N, color="k", ls=":", label=f"paper's peak {PAPER_PEAK_FORCE_N} N")
    ax.axhline(0.0, color="0.5", lw=0.6)
    ax.set(xlabel="t / s", ylabel="slider force / N", xlim=(history.t[0], history.t[-1]),
           title=f"Paper example, sliders 10 sin(0.5 t) mm, 10 kg payload: peak {history.peak:.1f} N "
                 f"({history.peak_slider})")
    ax.legend(fontsize=8, loc="center left", bbox_to_anchor=(1.01, 0.5))
    ax.grid(alpha=0.3)
    fig.tight_layout()
    save(fig, path)
    return ax


def write_charts(outdir, step=0.005):
    """Write the PNG charts into outdir; return the headline figures and the chart paths."""
    outdir = Path(outdir)
    outdir.mkdir(parents=True, exist_ok=True)
    params = m3t.Mechanism3TParams.paper()
    full = m3t.workspace(params, step)
    paper = m3t.workspace(params, step, passive_limbs=False)
    history = m3t.paper_example(params)
    paths = {}

    fig = Figure(figsize=(7, 6))
    ax = fig.add_subplot(projection="3d")
    pts = full.points[::7] * 1e3
    ax.scatter(pts[:, 0], pts[:, 1], pts[:, 2], c=pts[:, 2], s=1, cmap="viridis")
    ax.set(xlabel="x / mm", ylabel="y / mm", zlabel="z / mm",
           title=f"Workspace, all limbs closing: {full.volume:.4f} m$^3$\n(every 7th point of a {step * 1e3:g} mm "
                 "grid, "
                 "colour = z)")
    paths["workspace_3d"] = outdir / "workspace_3d.png"
    save(fig, paths["workspace_3d"])

    z_cut, y_cut = 0.35, 0.05
    fig = Figure(figsize=(12, 6.5))
    ax_xy, ax_xz = fig.subplots(1, 2, width_ratios=(1, 1.6))
    for ws, style in ((paper, dict(c="0.8", label=f"paper criterion, eq. 11 only ({paper.volume:.4f} m$^3$)")),
                      (full, dict(c="tab:blue", label=f"limbs I and II closing too ({full.volume:.4f} m$^3$)"))):
        _section(ax_xy, ws.points, (0, 1), lambda p: np.abs(p[:, 2] - z_cut) < step / 2, **style)
        _section(ax_xz, ws.points, (0, 2), lambda p: np.abs(p[:, 1] - y_cut) < step / 2, **style)
    ax_xy.set(xlabel="x / mm", ylabel="y / mm", title=f"section z = {z_cut * 1e3:.0f} mm", aspect="equal")
    ax_xz.set(xlabel="x / mm", ylabel="z / mm", title=f"section y = {y_cut * 1e3:.0f} mm", aspect="equal")
    fig.legend(*ax_xy.get_legend_handles_labels(), loc="lower center", ncol=2, markerscale=5,
               title=f"reachable points of a {step * 1e3:g} mm grid (blue lies inside grey)")
    fig.suptitle("3T mechanism workspace: the paper's criterion against all limbs closing")
    fig.tight_layout(rect=(0, 0.1, 1, 1))
    paths["workspace_sections"] = outdir / "workspace_sections.png"
    save(fig, paths["workspace_sections"])

    paths["slider_forces"] = outdir / "slider_forces.png"
    slider_force_chart(history, paths["slider_forces"])

    return {"peak_force_N": history.peak, "peak_slider": history.peak_slider,
            "force_at_reference_N": history.forces[0].tolist(), "paper_peak_force_N": PAPER_PEAK_FORCE_N,
            "workspace_volume_m3": full.volume, "paper_criterion_volume_m3": paper.volume,
            "charts": {k: str(v) for k, v in paths.items()}}


if __name__ == "__main__":
    print(write_charts(Path("out") / "mechanism3t"))
