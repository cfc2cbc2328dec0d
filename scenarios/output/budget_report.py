"""A geometric tolerance budget's result (scenarios.runs.budget.run_budget's dict) as a reader
sees it: its charts (Sobol indices by group, the allocation, each target's quantile against
it) and a Markdown report beside the JSON, all written whole or not at all.

It reads the result dict alone (no budget file, no model), so a stored JSON draws again;
studies/tolerance_budget.py draws its two shipped budgets with the same axes."""
import io
import json
import pathlib

import numpy as np
from matplotlib.figure import Figure

from fmu_src import atomic
from scenarios.output.charts import DPI, MARK_COLOUR, OTHER_COLOURS, plain_log_axis

# SI unit -> (factor, the unit a reader reads): pose errors in µm and µrad, a scale in ppm
SHOWN = {"m": (1e6, "µm"), "rad": (1e6, "µrad"), "1": (1e6, "ppm")}
METRIC_UNITS = {"focus": "m", "lateral": "m", "position": "m", "tilt": "rad"}
CHARTS = ("quantiles", "sobol", "allocation")


def percent(probability):
    """A probability as a percentage with every digit it has: 0.9999 -> "99.99 %", not 100.0."""
    return f"{round(probability * 100, 10):.10g} %"


def shown(value, si_unit):
    """(number, unit) of an SI value as the report shows it (µm, µrad, ppm)."""
    factor, unit = SHOWN[si_unit]
    return value * factor, unit


def status(result):
    """(status, flags): "ok" when every target is met at the interval's upper end (and the
    allocation, if any, is verified), else "flagged", each flag saying which and by how much."""
    flags = []
    for metric, q in result["quantiles"].items():
        if not q["met"]:
            high, unit = shown(q["high"], METRIC_UNITS[metric])
            target, _ = shown(q["target"], METRIC_UNITS[metric])
            flags.append(f"target {metric} not met: the upper end of the {percent(result['probability'])} quantile's "
                         f"interval is {high:.4g} {unit}, the target {target:g} {unit}")
    allocation = result.get("allocation")
    if allocation is not None and not allocation["verified"]:
        flags.append("the allocation's check did not meet every target")
    return ("ok" if not flags else "flagged"), flags


def sobol_axes(ax, name, sobol, linear_shares):
    """One budget's Sobol indices by group on ``ax``: total (bars with their interval),
    first order (ticks) and the first-order model's shares (red dots), per component."""
    groups, components = sobol["groups"], sobol["components"]
    width = 0.8 / len(components)
    for i, component in enumerate(components):
        x = np.arange(len(groups)) + (i - (len(components) - 1) / 2) * width
        ax.bar(x, sobol["total"][i], width, yerr=sobol["total_conf"][i], capsize=2,
               color=OTHER_COLOURS[i % len(OTHER_COLOURS)], label=f"{component}: total", alpha=0.85)
        ax.errorbar(x, sobol["first"][i], yerr=sobol["first_conf"][i], fmt="k_", ms=8, capsize=0, lw=1,
                    label="first order" if i == 0 else None)
        shares = linear_shares.get(component, {})
        ax.plot(x, [shares.get(g, 0.0) for g in groups], "r.", ms=5,
                label="first-order model (analytic)" if i == 0 else None)
    ax.set_xticks(np.arange(len(groups)), groups, fontsize=7, rotation=30, ha="right")
    ax.set_title(f"{name}: Sobol indices of the pose error by input group\n"
                 f"({sobol['evaluations']:,d} evaluations, 95 % bootstrap intervals)", fontsize=9)
    ax.set_ylim(0, 1)
    ax.set_ylabel("share of the variance")
    ax.grid(axis="y", alpha=0.3)


def allocation_axes(ax, name, probability, allocation, given):
    """One budget's allocation on ``ax``: each group's tolerance as given (``given``: group ->
    SI scale) and allocated, log scale, with its scale factor and cost."""
    groups = allocation["groups"]
    names = list(groups)
    units = [groups[g]["tolerance"][1] for g in names]
    as_given = [shown(given[g], u)[0] for g, u in zip(names, units)]
    allocated = [shown(groups[g]["tolerance"][0], u)[0] for g, u in zip(names, units)]
    x = np.arange(len(names))
    ax.bar(x - 0.2, as_given, 0.4, color="0.7", label="as given")
    ax.bar(x + 0.2, allocated, 0.4, color=OTHER_COLOURS[0], label="allocated")
    for xi, g, value in zip(x, names, allocated):
        ax.text(xi + 0.2, value * 1.1, f"x{groups[g]['scale']:.2g}\ncost {groups[g]['cost']:.3g}", ha="center",
                fontsize=6)
    ax.set_yscale("log")
    ax.set_ylim(min(as_given + allocated) / 2, max(as_given + allocated) * 4)   # room for the labels
    plain_log_axis(ax.yaxis)
    ax.set_xticks(x, [f"{g.replace('_', chr(10))}\n[{SHOWN[u][1]}]" for g, u in zip(names, units)], fontsize=7)
    ax.set_title(f"{name}: tolerances (half-width) meeting the targets at {percent(probability)}\n"
                 f"cost {allocation['cost']:.3g} against {allocation['cost_as_given']:.3g} as given "
                 "(cost = weight / scale)", fontsize=9)
    ax.grid(axis="y", alpha=0.3)


def _quantiles_chart(result):
    """Each target's quantile with its interval against the target (met: the whole interval
    below it)."""
    quantiles = result["quantiles"]
    fig = Figure(figsize=(7, 0.9 + 0.6 * len(quantiles)))
    ax = fig.subplots()
    for row, (metric, q) in enumerate(quantiles.items()):
        unit = METRIC_UNITS[metric]
        value, low, high, target = (shown(q[k], unit)[0] for k in ("value", "low", "high", "target"))
        colour = OTHER_COLOURS[0] if q["met"] else MARK_COLOUR
        ax.errorbar([value], [row], xerr=[[value - low], [high - value]], fmt="o", color=colour, capsize=4)
        ax.plot([target], [row], "|", color="k", ms=18, mew=2)
        ax.annotate(f"target {target:g} {SHOWN[unit][1]}: {'met' if q['met'] else 'NOT met'}", (target, row),
                    xytext=(6, 6), textcoords="offset points", fontsize=8)
    ax.set_yticks(range(len(quantiles)), [f"{m} [{SHOWN[METRIC_UNITS[m]][1]}]" for m in quantiles])
    ax.set_ylim(-0.7, len(quantiles) - 0.3)
    ax.invert_yaxis()
    reach = max(max(q["high"], q["target"]) * SHOWN[METRIC_UNITS[m]][0] for m, q in quantiles.items())
    ax.set_xlim(0, 1.3 * reach)
    ax.set_xlabel("pose error (each row in its unit)")
    ax.set_title(f"{result['name']}: pose error at {percent(result['probability'])} "
                 f"({result['samples']:,d} samples; bars: the {percent(result.get('confidence', 0.95))} interval)",
                 fontsize=9)
    ax.grid(axis="x", alpha=0.3)
    fig.tight_layout()
    return fig


def charts(result):
    """{name: matplotlib Figure} of the result (not pyplot's): the quantiles always, the
    Sobol indices and the allocation when the result has them."""
    made = {"quantiles": _quantiles_chart(result)}
    if "sobol" in result:
        fig = Figure(figsize=(7, 4))
        ax = fig.subplots()
        sobol_axes(ax, result["name"], result["sobol"], result.get("linear_shares", {}))
        ax.legend(fontsize=7, loc="upper left")
        fig.tight_layout()
        made["sobol"] = fig
    if "allocation" in result and all("given" in g for g in result["allocation"]["groups"].values()):
        fig = Figure(figsize=(7, 4))
        ax = fig.subplots()
        allocation_axes(ax, result["name"], result["probability"], result["allocation"],
                        {g: v["given"][0] for g, v in result["allocation"]["groups"].items()})
        ax.legend(fontsize=7)
        fig.tight_layout()
        made["allocation"] = fig
    return made


def markdown(result, images=()):
    """The report: the verdict first, then each target, the Sobol indices, the leading inputs
    and the allocation; ``images`` the chart files beside it."""
    state, flags = status(result)
    lines = [f"# Tolerance budget `{result['name']}`", "",
             f"*From `{result['source']}`: {result['samples']:,d} Monte Carlo samples over the workspace and "
             f"elevation range (scenarios.runs.budget).*", "",
             f"**Status: {state}**" + (": " + "; ".join(flags) if flags else ": every target is met at "
                                       f"{percent(result['probability'])}, its interval's upper end below it"), "",
             f"| metric | at {percent(result['probability'])} | {percent(result.get('confidence', 0.95))} interval "
             "| target | met |", "|---|---|---|---|---|"]
    for metric, q in result["quantiles"].items():
        unit = METRIC_UNITS[metric]
        value, low, high, target = (shown(q[k], unit)[0] for k in ("value", "low", "high", "target"))
        u = SHOWN[unit][1]
        lines.append(f"| {metric} | {value:.4g} {u} | {low:.4g}..{high:.4g} {u} | {target:g} {u} | "
                     f"{'yes' if q['met'] else 'no'} |")
    lines += [""] + [f"![{name}]({path})" for name, path in images] + [""]
    if "sobol" in result:
        s = result["sobol"]
        lines += [f"Sobol total indices by group ({s['evaluations']:,d} evaluations; ± the 95 % bootstrap "
                  "half-width):", "", "| group | " + " | ".join(s["components"]) + " |",
                  "|---|" + "---|" * len(s["components"])]
        for g, group in enumerate(s["groups"]):
            lines.append(f"| {group} | " + " | ".join(f"{s['total'][i][g]:.3f} ± {s['total_conf'][i][g]:.3f}"
                                                     for i in range(len(s["components"]))) + " |")
        lines.append("")
    for metric, leading in result.get("leading_inputs", {}).items():
        lines.append(f"Leading inputs of {metric} (first-order variance shares): "
                     + ", ".join(f"{name} {share:.1%}" for name, share in leading[:5]) + ".")
    if "allocation" in result:
        a = result["allocation"]
        lines += ["", f"Allocation (cost {a['cost']:.3g} against {a['cost_as_given']:.3g} as given; checked by a "
                  f"fresh Monte Carlo: {'met' if a['verified'] else 'NOT met'}):", "",
                  "| group | scale | tolerance | cost |", "|---|---|---|---|"]
        for group, g in a["groups"].items():
            value, unit = shown(*g["tolerance"])
            lines.append(f"| {group} | x{g['scale']:.3f} | {value:.4g} {unit} | {g['cost']:.3g} |")
    return "\n".join(lines) + "\n"


def write(result, folder):
    """``folder``/<name>.json, <name>_<chart>.png and <name>.md, each whole or not at all; the
    report's path."""
    folder = pathlib.Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    name = result["name"]
    atomic.write_text(folder / f"{name}.json", json.dumps(result, indent=1) + "\n")
    images = []
    for chart, fig in charts(result).items():
        buffer = io.BytesIO()
        fig.savefig(buffer, format="png", dpi=DPI)
        atomic.write_bytes(folder / f"{name}_{chart}.png", buffer.getvalue())
        images.append((chart, f"{name}_{chart}.png"))
    return atomic.write_text(folder / f"{name}.md", markdown(result, images))
