"""Sky coverage: where on the sky, for which slews and which sources near the zenith
keyhole, does ignoring the base motion cross the 10 µm and 0.1 mm marks?

Three campaigns (scenarios/campaigns/): ``sky_slews`` (a +10 deg az, +5 deg el slew from a
grid of start pointings), ``slew_sizes`` (diagonal slews of 0.5-20 deg) and
``keyhole_tracks`` (sidereal tracks transiting 0.1-10 deg south or north of the
zenith), each with the fixed-base and the moving-base feedforward, run through one
engine (local worker processes or a Dask cluster), resumable.

    python -m studies.sky_coverage [--ci] [--jobs N] [--dask ADDR] [--out DIR] [--docs]

Charts: peak and RMS pose error as maps over start azimuth and elevation with the 10 µm
and 0.1 mm contours, error against slew size and against the keyhole miss distance, the
tracks on a compass sky chart coloured by error; a table of the worst cases (report.md).
Azimuths are astronomical (north through east) throughout.
"""
import argparse
import datetime
import math
import os
import pathlib
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from matplotlib.colors import LogNorm
from matplotlib.patches import Rectangle

from plant.telescope import model as telescope
from scenarios.output.charts import FLOOR, RUN_COLOURS, RUN_NAMES, draw_marks, length, plain_log_axis, save
from scenarios.runs import campaign as campaigns
from scenarios.runs import engine
from scenarios.spec.units import to_si

CAMPAIGNS = ("sky_slews", "slew_sizes", "keyhole_tracks")
MODES = ("fixed_base", "moving_base")
MARKS = (10.0, 100.0)            # µm: focus, hexapod metrology
METRIC = "pose error"
SKY_RADIUS = 0.6                 # deg of zenith distance shown on the sky chart
DOCS = pathlib.Path(__file__).resolve().parent.parent / "docs"


def run(out="out", ci=False, jobs=None, address=None, progress=True):
    """Run the three campaigns (what is not on disk yet) on one engine.
    Returns {name: (campaign, job list, store, outcome)}."""
    results = {}
    outdir = pathlib.Path(out) / "sky_coverage"
    with engine.Engine(jobs, address) as eng:
        for name in CAMPAIGNS:
            camp = campaigns.load(name, ci)
            job_list, files = campaigns.jobs(camp)
            store = engine.Store(outdir / name)
            outcome = eng.run(job_list, files, store, progress, name=name)
            if outcome.interrupted:
                raise KeyboardInterrupt
            results[name] = (camp, job_list, store, outcome)
    return results


def _deg(value):
    return math.degrees(to_si(value, "rad"))


def rows(camp, job_list, store):
    """One dict per finished run: the case's values (SI / deg), the pose error metrics."""
    out = []
    for case, record in campaigns.results(camp, store, job_list):
        if record is None or record["status"] != "ok":
            continue
        m = record["metrics"][METRIC]
        row = {"label": _short(camp.name, case), "key": record["key"], "mode": case.values["controller.feedforward"],
               "peak": m["peak"], "rms": m["rms"], "rotation_peak": m["rotation_peak"], "values": case.values,
               "flags": sorted({f["kind"] for f in record.get("flags") or []})}
        out.append(row)
    return out


def _short(name, case):
    """A run's label for the table: what varies, in degrees."""
    v = case.values
    if name == "sky_slews":
        return (f"az {_deg(v['base.start_azimuth']):g} -> {_deg(v['base.target_azimuth']):g}, "
                f"el {_deg(v['base.start_elevation']):g} -> {_deg(v['base.target_elevation']):g} deg")
    if name == "keyhole_tracks":
        miss = _deg(v["base.declination"]) - math.degrees(telescope.TelescopeParams.tianma().latitude)
        side = "north" if miss > 0 else "south"
        return f"dec {_deg(v['base.declination']):g} deg: {abs(miss):.2g} deg {side} of the zenith"
    return case.label.split(";")[0]


def _cell(value):
    """A map cell's number: 3 digits, '<1 nm' under the floor."""
    return length(value).removesuffix(" µm").replace("< 1 nm", "<1 nm")


def map_chart(rows_, path):
    """Peak and RMS pose error over start azimuth and elevation, per feedforward mode."""
    az = sorted({_deg(r["values"]["base.start_azimuth"]) for r in rows_})
    el = sorted({_deg(r["values"]["base.start_elevation"]) for r in rows_})
    grids = {(q, mode): np.full((len(el), len(az)), np.nan) for q in ("peak", "rms") for mode in MODES}
    flagged = {mode: set() for mode in MODES}   # (i, j) of the flagged runs' cells
    for r in rows_:
        i, j = el.index(_deg(r["values"]["base.start_elevation"])), az.index(_deg(r["values"]["base.start_azimuth"]))
        for q in ("peak", "rms"):
            grids[(q, r["mode"])][i, j] = r[q]
        if r["flags"]:
            flagged[r["mode"]].add((i, j))
    values = np.concatenate([g[np.isfinite(g)] for g in grids.values()])
    norm = LogNorm(max(values.min(), FLOOR), values.max())

    def edges(centres):
        c = np.asarray(centres, float)
        if c.size == 1:
            return np.array([c[0] - 5, c[0] + 5])
        mid = (c[1:] + c[:-1]) / 2
        return np.concatenate([[c[0] - (mid[0] - c[0])], mid, [c[-1] + (c[-1] - mid[-1])]])

    fig, axes = plt.subplots(2, 2, figsize=(12, 8.5), sharex=True, sharey=True, layout="constrained")
    for (row, q), (col, mode) in ((a, b) for a in enumerate(("peak", "rms")) for b in enumerate(MODES)):
        ax, grid = axes[row, col], grids[(q, mode)]
        mesh = ax.pcolormesh(edges(az), np.clip(edges(el), 0, 90), grid, norm=norm, cmap="viridis", shading="flat")
        for i, e in enumerate(el):
            for j, a in enumerate(az):
                if np.isfinite(grid[i, j]):
                    ax.text(a, e, _cell(grid[i, j]), ha="center", va="center", fontsize=7,
                            color="white" if grid[i, j] < np.sqrt(norm.vmin * norm.vmax) else "black")
        if len(az) > 1 and len(el) > 1:
            ax.contour(az, el, grid, levels=list(MARKS), colors="k", linestyles=["-", "--"], linewidths=1.2)
        above = [f"{(grid > m).sum()} of {np.isfinite(grid).sum()} above {t}"
                 for m, t in zip(MARKS, ("10 µm", "0.1 mm"))]
        above += [f"{len(flagged[mode])} FLAGGED (red frame, not results)"] if flagged[mode] else []
        _mark_flagged_cells(ax, edges(az), np.clip(edges(el), 0, 90), flagged[mode])
        ax.set_title(f"{q} pose error, {mode.replace('_', '-')} feedforward\n{'; '.join(above)}", fontsize=10)
        ax.set_xticks(az, [f"{a:g}" for a in az])         # a tick at every grid column and row
        ax.set_yticks(el, [f"{e:g}" for e in el])
        if row == 1:
            ax.set_xlabel("start azimuth [deg] (astronomical, north through east)")
        if col == 0:
            ax.set_ylabel("start elevation [deg]")
    contours = [plt.Line2D([], [], color="k", lw=1.2, label="10 µm"),
                plt.Line2D([], [], color="k", lw=1.2, ls="--", label="0.1 mm")]
    fig.legend(handles=contours, loc="outside lower center", ncol=2, fontsize=8, title="contours",
               title_fontsize=8, frameon=False)
    bar = fig.colorbar(mesh, ax=axes, label="platform position error [µm] (log scale, floored at 1 nm; numbers in the "
                       "cells)", shrink=0.8)
    plain_log_axis(bar.ax.yaxis, subs=(1.0,))
    fig.suptitle("Slews of +10 deg in azimuth and +5 deg in elevation from each start pointing "
                 "(rate/acc limited, 25 m lever arm)")
    save(fig, path)
    return path


def _mark_flagged_cells(ax, az_edges, el_edges, cells):
    """A red frame and a red F on each flagged run's cell (scenarios.runs.flags)."""
    for i, j in cells:
        ax.add_patch(Rectangle((az_edges[j], el_edges[i]), az_edges[j + 1] - az_edges[j], el_edges[i + 1] - el_edges[i],
                               fill=False, edgecolor="red", lw=2.2, zorder=3))
        ax.text(az_edges[j + 1], el_edges[i + 1], "F ", ha="right", va="top", color="red", fontsize=8,
                fontweight="bold", zorder=4)


def size_chart(rows_, path):
    """Pose error against the size of a diagonal slew, a tick at every size run; values
    under 1 nm drawn on the floor."""
    fig, ax = plt.subplots(figsize=(8, 5), layout="constrained")
    sizes = set()
    for mode in MODES:
        mine = sorted((r for r in rows_ if r["mode"] == mode), key=lambda r: _deg(r["values"]["base.target_azimuth"]))
        size = [_deg(r["values"]["base.target_azimuth"]) - _deg(r["values"]["base.start_azimuth"]) for r in mine]
        sizes.update(size)
        for key, style in (("peak", {"marker": "o", "ls": "-"}), ("rms", {"marker": "s", "ls": "--", "mfc": "white"})):
            ax.plot(size, [max(r[key], FLOOR) for r in mine], color=RUN_COLOURS[mode], **style,
                    label=f"{RUN_NAMES[mode]}: {'peak' if key == 'peak' else 'RMS'}")
        bad = [k for k, r in enumerate(mine) if r["flags"]]
        if bad:
            ax.plot([size[k] for k in bad], [max(mine[k]["peak"], FLOOR) for k in bad], "x", color="red", ms=11,
                    mew=2.5, label=f"{RUN_NAMES[mode]}: FLAGGED run (not a result)")
    draw_marks(ax)
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xticks(sorted(sizes), [f"{v:g}" for v in sorted(sizes)])
    ax.xaxis.set_minor_locator(plt.NullLocator())
    plain_log_axis(ax.yaxis, subs=(1.0,))
    ax.set_ylim(FLOOR, None)
    ax.set_xlabel("slew size [deg] (the same in azimuth and in elevation, from az 0, el 40 deg)")
    ax.set_ylabel("platform position error [µm] (log, floored at 1 nm)")
    ax.set_title("Pose error against slew size")
    ax.grid(True, which="major", alpha=0.3)
    ax.legend(fontsize=8, handlelength=3)
    save(fig, path)
    return path


def _miss(row, latitude):
    """Signed zenith distance at transit [deg]: negative south of the zenith."""
    return _deg(row["values"]["base.declination"]) - math.degrees(latitude)


def keyhole_chart(rows_, store, path):
    """Error against the miss distance, and the tracks on a compass sky chart coloured
    by the fixed-base error along them."""
    params = telescope.TelescopeParams.tianma()
    fig = plt.figure(figsize=(13, 5.5), layout="constrained")
    ax = fig.add_subplot(1, 2, 1)
    under_any = False
    sides = {"south": ("o", -1), "north": ("^", 1)}
    for mode in MODES:
        for side, (marker, sign) in sides.items():
            mine = sorted((r for r in rows_ if r["mode"] == mode and np.sign(_miss(r, params.latitude)) == sign),
                          key=lambda r: abs(_miss(r, params.latitude)))
            x = np.array([abs(_miss(r, params.latitude)) for r in mine])
            for key, ls, alpha in (("peak", "-", 1.0), ("rms", ":", 0.6)):
                values = np.array([r[key] for r in mine])
                under = values < FLOOR        # drawn on the floor, as downward triangles
                under_any |= bool(under.any())
                ax.plot(x, np.maximum(values, FLOOR), ls, color=RUN_COLOURS[mode], alpha=alpha)
                ax.plot(x[~under], values[~under], marker, color=RUN_COLOURS[mode], alpha=alpha, ls="none")
                ax.plot(x[under], np.full(under.sum(), FLOOR), "v", color=RUN_COLOURS[mode], alpha=alpha, ls="none",
                        clip_on=False)
    # the legend names each encoding once, with the markers as plotted
    keys = [plt.Line2D([], [], color=RUN_COLOURS[m], lw=2, label=RUN_NAMES[m]) for m in MODES]
    keys += [plt.Line2D([], [], color="0.3", ls="-", label="peak"), plt.Line2D([], [], color="0.3", ls=":",
                                                                               label="RMS")]
    keys += [plt.Line2D([], [], color="0.3", marker=m, ls="none", label=f"transits {side} of the zenith")
             for side, (m, _) in sides.items()]
    if under_any:
        keys.append(plt.Line2D([], [], color="0.3", marker="v", ls="none", label="< 1 nm (drawn on the floor)"))
    draw_marks(ax)
    ax.set_xscale("log")
    ax.set_yscale("log")
    plain_log_axis(ax.xaxis)
    plain_log_axis(ax.yaxis, subs=(1.0,))
    ax.set_ylim(FLOOR, None)
    ax.set_xlabel("zenith distance at transit [deg]")
    ax.set_ylabel("platform position error [µm] (log, floored at 1 nm)")
    ax.set_title("Sidereal tracks near the keyhole")
    ax.grid(True, which="major", alpha=0.3)
    ax.legend(handles=keys, fontsize=7.5, ncol=3, loc="upper center", bbox_to_anchor=(0.5, -0.13))   # off the data

    sky = fig.add_subplot(1, 2, 2, projection="polar")
    sky.set_theta_zero_location("N")
    sky.set_theta_direction(-1)               # compass: north up, east to the right
    fixed = [r for r in rows_ if r["mode"] == "fixed_base"]
    errors = np.concatenate([store.series(r["key"])[METRIC][1] for r in fixed]) if fixed else np.ones(1)
    norm = LogNorm(FLOOR, max(errors.max(), 10 * FLOOR))   # colours floored at what the model resolves
    for r in fixed:
        t, err = store.series(r["key"])[METRIC]
        v = r["values"]
        utc = datetime.datetime.fromtimestamp(float(v["base.utc_start"]), tz=datetime.timezone.utc)
        axes = telescope.sidereal_track(params, to_si(v["base.right_ascension"], "rad"),
                                        to_si(v["base.declination"], "rad"), utc, t)
        az, zd = axes.azimuth, 90.0 - np.degrees(axes.E)
        points = sky.scatter(az, zd, c=np.maximum(err, norm.vmin), norm=norm, cmap="plasma", s=4)
    sky.set_rmax(SKY_RADIUS)
    sky.set_title(f"the tracks within {SKY_RADIUS:g} deg of the zenith (compass view, radius = zenith\n"
                  f"distance [deg]), coloured by the fixed-base pose error", fontsize=10)
    if fixed:
        bar = fig.colorbar(points, ax=sky, label="fixed-base platform position error [µm] (floored at 1 nm)",
                           shrink=0.8)
        plain_log_axis(bar.ax.yaxis, subs=(1.0,))
    save(fig, path)
    return path


def worst_table(all_rows, n=6):
    """Markdown: the n worst runs by peak pose error for each feedforward mode."""
    lines = ["| campaign | run | feedforward | peak [µm] | RMS [µm] | peak rotation [µrad] | past |",
             "|---|---|---|---|---|---|---|"]
    for mode in MODES:
        mine = sorted(((name, r) for name, rs in all_rows.items() for r in rs if r["mode"] == mode),
                      key=lambda nr: -nr[1]["peak"])[:n]
        for name, r in mine:
            past = "0.1 mm" if r["peak"] > 100 else "10 µm" if r["peak"] > 10 else "-"
            flag = f" **FLAGGED: {', '.join(r['flags'])}**" if r["flags"] else ""
            lines.append(f"| {name} | {r['label']}{flag} | {mode} | {r['peak']:.3g} | {r['rms']:.3g} | "
                         f"{r['rotation_peak']:.3g} | {past} |")
    return lines


def report(results, outdir, figures=None, name="report.md"):
    """Charts and the report; ``figures`` (default: outdir) is where the PNGs go."""
    outdir = pathlib.Path(outdir)
    figures = pathlib.Path(figures or outdir)
    outdir.mkdir(parents=True, exist_ok=True)
    figures.mkdir(parents=True, exist_ok=True)
    all_rows = {name: rows(c, j, s) for name, (c, j, s, _) in results.items()}
    charts = [map_chart(all_rows["sky_slews"], figures / "sky_slews_map.png"),
              size_chart(all_rows["slew_sizes"], figures / "sky_slew_sizes.png"),
              keyhole_chart(all_rows["keyhole_tracks"], results["keyhole_tracks"][2],
                            figures / "sky_keyhole_tracks.png")]
    failed = {name: o.failed for name, (_, _, _, o) in results.items() if o.failed}
    lines = ["# Sky coverage", "", __doc__.split("\n\n")[0].replace("\n", " "), "",
             f"Runs: {', '.join(f'{n} {len(r)}' for n, r in all_rows.items())} (ok)."
             + (f" Failed: {failed}." if failed else "")
             + "".join(f" Flagged (numbers not results, marked in the charts and table): {name} "
                       f"{', '.join(r['label'] + ' ' + r['mode'] for r in rs if r['flags'])}."
                       for name, rs in all_rows.items() if any(r["flags"] for r in rs)), "",
             "## Worst cases", "", *worst_table(all_rows), ""]
    lines += [f"![{c.stem}]({os.path.relpath(c, outdir)})" for c in charts]
    path = outdir / name
    path.write_text("\n".join(lines) + "\n")
    return path, charts


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--ci", action="store_true", help="the campaigns' [ci] versions (seconds)")
    parser.add_argument("--jobs", type=int, help="local worker processes (default: all cores)")
    parser.add_argument("--dask", metavar="ADDR", help="the Dask cluster at ADDR")
    parser.add_argument("--out", default="out")
    parser.add_argument("--docs", action="store_true", help="write the charts to docs/figures and the report to docs/")
    args = parser.parse_args(argv)
    try:
        results = run(args.out, args.ci, args.jobs, args.dask)
    except KeyboardInterrupt:
        sys.exit("interrupted: the runs finished so far are on disk; run the same command again to resume")
    if args.docs:
        path, charts = report(results, DOCS, DOCS / "figures", "sky_coverage.md")
    else:
        path, charts = report(results, pathlib.Path(args.out) / "sky_coverage")
    print(f"report {path}; charts {', '.join(str(c) for c in charts)}")


if __name__ == "__main__":
    main()
