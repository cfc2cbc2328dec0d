"""The dynamic tolerance budget (issues 30, 41): how much tracking error a model that is wrong
costs over the full telescope slew in the realistic loop in 10 m/s gusty wind with the
disturbance observer on, and which error drives it. The sampled campaign
scenarios/campaigns/dynamic_budget.toml draws the payload (mass, principal moments, centre of mass)
against the paper's values the feedforward keeps, the leg encoders' scale errors, the
base IMU's alignment and each sample's own sensor noise and gusts (the seeds).

    python -m studies.dynamic_budget [--ci] [--jobs N] [--dask ADDR] [--out DIR]   # run (resumable)
    python -m studies.dynamic_budget --docs           # the same, then docs/dynamic_budget.json,
                                                      # docs/dynamic-budget.md and its chart
    python -m studies.dynamic_budget --from-store     # the page and chart from the json (no runs)

Which inputs drive the spread, from the samples themselves (plain Monte Carlo, no
Saltelli design): standardised regression coefficients (SRC, a least-squares fit of the
standardised metric on the standardised inputs; SRC^2 is an input's share of the
variance for a linear response of independent inputs, as drawn; R^2 says how much of the
spread that covers, the rest being the gusts and sensor noise each sample draws and what
is not linear), with bootstrap intervals. Sobol indices would need N (D + 2) runs of a Saltelli
design for D = 16 inputs; this reads the N runs already made.
"""
import argparse
import csv
import json
import pathlib
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from fmu_src import atomic
from scenarios.output.charts import OTHER_COLOURS, save
from scenarios.output.report import fmt
from scenarios.runs import campaign as campaigns

ROOT = pathlib.Path(__file__).resolve().parent.parent
DOCS = ROOT / "docs"
STORE = DOCS / "dynamic_budget.json"
PAGE = DOCS / "dynamic-budget.md"
FIGURE = DOCS / "figures" / "dynamic_budget.png"
CAMPAIGN = "dynamic_budget"
METRICS = {"pose error peak": "peak pose error (µm)", "pose error rms": "RMS pose error (µm)"}
# the earlier page's figures (a short slew, 1.8 s of motion, in the ideal loop without wind; the same
# 256 draws of the model errors): what the page compares the realistic slew in wind against
SHORT_IDEAL = {"p95": 12.9, "mean": 9.04, "sd": 2.08, "r2": 0.37, "payload mass": 0.30}
GROUPS = {"payload mass": "plant.payload_mass_error", "payload inertia": "plant.payload_inertia_error",
          "payload centre of mass": "plant.payload_com_error",
          "encoder scale": "encoders.scale_error", "IMU alignment": "imu.imu_alignment"}


def run(out="out", ci=False, jobs=None, address=None, progress=True):
    """The campaign (what is not on disk yet); returns its summary.csv."""
    *_, outcome, summary = campaigns.run_campaign(CAMPAIGN, out, ci, jobs, address, progress)
    if outcome.interrupted:
        raise KeyboardInterrupt
    return summary


def redrawn(ci=False):
    """The samples whose first draws gave a payload no rigid body has (its principal moments
    against the triangle inequalities), drawn again (scenarios.runs.campaign.MAX_REDRAWS)."""
    made = campaigns.CampaignJobs(campaigns.load(CAMPAIGN, ci))
    for case in made.campaign.cases:
        made._case(case)
    return sorted(case.sample for case in made.campaign.cases if made.redrawn[case.label])


def _group(column):
    return next(g for g, prefix in GROUPS.items() if column.startswith(prefix))


def analyse(summary):
    """Spread of each metric and what drives it, from summary.csv's rows that ran."""
    with open(summary, newline="", encoding="utf-8") as file:
        rows = [r for r in csv.DictReader(file) if r["status"] == "ok"]
    if len(rows) < 8:
        raise ValueError(f"{summary}: {len(rows)} finished samples; the analysis needs at least 8")
    inputs = [c for c in rows[0] if any(c.startswith(p) for p in GROUPS.values())]
    x = np.array([[float(r[c]) for c in inputs] for r in rows])
    result = {"samples": len(rows), "inputs": inputs, "metrics": {}}
    for metric in METRICS:
        y = np.array([float(r[metric]) for r in rows])
        result["metrics"][metric] = {"mean": y.mean(), "sd": y.std(ddof=1), "p50": float(np.percentile(y, 50)),
                                     "p95": float(np.percentile(y, 95)), "max": y.max(), "values": y.tolist(),
                                     **_drivers(x, y, inputs)}
    return result


def _src(x, y):
    """Standardised regression coefficients and R^2 of the least-squares fit."""
    xs, ys = (x - x.mean(0)) / x.std(0), (y - y.mean()) / y.std()
    design = np.c_[xs, np.ones(len(y))]
    coefficients, *_ = np.linalg.lstsq(design, ys, rcond=None)
    return coefficients[:-1], 1 - np.sum((ys - design @ coefficients) ** 2) / np.sum(ys ** 2)


def _drivers(x, y, inputs, resamples=400):
    """SRC per input and R^2; each group's share SRC^2 summed over its inputs (the shares
    of independent inputs add), with a 95 % bootstrap interval (rows resampled)."""
    src, r2 = _src(x, y)
    names = [_group(c) for c in inputs]
    share = lambda c: {g: float(sum(c[j] ** 2 for j, n in enumerate(names) if n == g)) for g in GROUPS}
    rng = np.random.default_rng(30)
    boot = [share(_src(x[i], y[i])[0]) for i in (rng.integers(0, len(y), len(y)) for _ in range(resamples))]
    groups = {g: {"src2": v, "low": float(np.percentile([b[g] for b in boot], 2.5)),
                  "high": float(np.percentile([b[g] for b in boot], 97.5))} for g, v in share(src).items()}
    return {"r2": float(r2), "src": dict(zip(inputs, map(float, src))), "groups": groups}


def chart(result, path):
    """Left: the peak pose error's distribution over the samples; right: each group's share
    of its variance (SRC^2 and SALib S1 with its 95 % interval)."""
    m = result["metrics"]["pose error peak"]
    fig, (left, right) = plt.subplots(1, 2, figsize=(12, 4.6), width_ratios=(1, 1.1))
    left.hist(m["values"], bins=min(40, max(8, result["samples"] // 8)), color=OTHER_COLOURS[0], alpha=0.8)
    for q, style in (("p50", "-"), ("p95", "--")):
        left.axvline(m[q], color="k", ls=style, lw=1, label=f"{q}: {fmt(m[q])} µm")
    left.set(xlabel="peak pose error over the slew in wind, from 1 s (µm)", ylabel="samples",
             title=f"{result['samples']} samples: a model that is wrong")
    left.legend(frameon=False)
    names, groups = list(GROUPS), m["groups"]
    shares = [groups[g]["src2"] for g in names] + [1 - m["r2"]]
    # a percentile interval need not hold the estimate (SRC^2 of a weak input is biased upwards
    # by the fit's noise, the resamples' spread around it is not symmetric): clipped at it
    low = [max(groups[g]["src2"] - groups[g]["low"], 0.0) for g in names] + [0]
    high = [max(groups[g]["high"] - groups[g]["src2"], 0.0) for g in names] + [0]
    at = np.arange(len(shares))
    right.barh(at, shares, 0.6, xerr=[low, high], color=[OTHER_COLOURS[1]] * len(names) + ["#7f7f7f"])
    for y, value, above in zip(at, shares, high):
        right.text(value + above + 0.02, y, f"{value:.2f}", va="center")
    right.set_yticks(at, names + ["gusts, sensor noise\nand the rest (1 - R²)"])
    right.invert_yaxis()
    right.set(xlabel="share of the peak error's variance (SRC², 95 % bootstrap interval)", xlim=(0, 1),
              title="what drives it")
    fig.tight_layout()
    save(fig, path)


def page(result):
    """docs/dynamic-budget.md from the results."""
    lines = ["# Dynamic tolerance budget", "",
             "*Written by `python -m studies.dynamic_budget --docs` from `docs/dynamic_budget.json`; do not edit.*",
             "", f"The campaign `scenarios/campaigns/dynamic_budget.toml` ({result['samples']} samples; "
             "[campaigns](campaigns.md#sampled-campaigns)) runs the full telescope slew (az 0 -> 20 deg, el 30 -> "
             "45 deg at the axes' rate and acceleration limits, 51.2 s of motion from t = 1 s, 56 s run) in the "
             "realistic loop of [wind rejection](wind-rejection.md) (ball-screw actuators with lag and friction, "
             "the antenna's 0.8 Hz axis servo, a 10 m/s Kaimal wind at turbulence intensity 0.15, load cells and "
             "the disturbance observer (leg-space, 32 Hz); "
             "started at its operating point, counted from 1 s; the moving-base "
             "feedforward fed by an IMU on the base, leg encoders) with a model that is wrong: the payload's mass "
             "(sd 43 kg, 2 %), principal moments (uniform ±550 kg.m², 15 % of the "
             "smallest, each sample a rigid body: see below) and centre of mass (uniform ±20 mm along each axis "
             "of {P}) against the "
             "paper's values the feedforward keeps, the six encoders' scale errors (uniform ±1e-4 of the travel from "
             "home) and the IMU's alignment (uniform ±1 mrad about each axis), and each sample's own gusts (the wind's "
             "seed) and sensor noise (IMU, encoders, load cells). "
             "The tolerances are assumed (the campaign file says why).", "",
             "![Peak pose error over the samples, and what drives it](figures/dynamic_budget.png)", "",
             "| metric | mean | sd | median | 95 % | max | R² of a linear fit |", "|---|---|---|---|---|---|---|"]
    if "redrawn" in result:     # the campaign's own runs (analyse() alone does not know them)
        at = lines.index("![Peak pose error over the samples, and what drives it](figures/dynamic_budget.png)")
        lines[at:at] = [
            f"Every sample is a body that can exist: {len(result['redrawn'])} of the {result['samples']} samples "
            "first drew principal moments that break a triangle inequality (Ixx + Iyy < Izz, which no rigid body "
            "has) and were drawn again, every input of the sample anew (rejection: the draws follow the "
            "distributions as written, conditioned on an admissible body; a run is refused before it starts when "
            "its payload is none).", ""]
    for metric, label in METRICS.items():
        m = result["metrics"][metric]
        lines.append(f"| {label} | {fmt(m['mean'])} | {fmt(m['sd'])} | {fmt(m['p50'])} | {fmt(m['p95'])} | "
                     f"{fmt(m['max'])} | {m['r2']:.2f} |")
    lines += ["", "Share of each group's variance: SRC² (standardised regression coefficients squared, summed over "
              "the group's inputs) with its 95 % bootstrap interval; what the fit leaves (1 - R²) is the gusts and the "
              "sensor noise, which each sample draws anew (its own seeds), and whatever is not linear:", "",
              "| group | " + " | ".join(METRICS[m] for m in METRICS) + " | by chance, m / (N - 1) |",
              "|---|" + "---|" * (len(METRICS) + 1)]
    for group, prefix in GROUPS.items():
        cells = [result["metrics"][m]["groups"][group] for m in METRICS]
        chance = sum(c.startswith(prefix) for c in result["inputs"]) / (result["samples"] - 1)
        lines.append(f"| {group} | " + " | ".join(f"{g['src2']:.2f} ({g['low']:.2f}-{g['high']:.2f})" for g in cells)
                     + f" | {chance:.3f} |")
    lines.append("| gusts, sensor noise and the rest (1 - R²) | " + " | ".join(
        f"{1 - result['metrics'][m]['r2']:.2f}" for m in METRICS) + " | |")
    lines += ["", "The last column is what a group of m inputs would reach by chance (each input's SRC² averages "
              "1 / (N - 1) when it does nothing): a share near it is not told apart from nothing at this N."]
    lines += ["", *_against_short(result["metrics"]["pose error peak"])]
    top = max(result["metrics"]["pose error peak"]["src"].items(), key=lambda kv: abs(kv[1]))
    lines += ["", f"The input that moves the peak error most is {top[0]} (SRC {top[1]:+.2f}: a standard deviation of "
              f"it moves the peak by {abs(top[1]):.2f} of the peak's standard deviation). Why a regression: the "
              "samples are plain Monte Carlo, and SRC reads the runs already made; Sobol indices "
              "(plant.hexapod.tolerance, SALib) would need a Saltelli design of N (D + 2) runs for these "
              f"D = {len(result['inputs'])} inputs, and with R² this low a first-order index would mostly measure "
              "the noise. SRC² is exact for a linear response of independent inputs (these are drawn "
              "independently) and R² says how much of the spread that covers.", ""]
    return "\n".join(lines)


def _against_short(m):
    """What changed against the earlier page's short slew in the ideal loop without wind."""
    noise, mass, groups = 1 - m["r2"], m["groups"]["payload mass"]["src2"], m["groups"]
    lead = max(groups, key=lambda g: groups[g]["src2"])
    return [f"Against the earlier page's short slew in the ideal loop without wind (1.8 s of motion at full "
            f"acceleration, the same draws of the model errors), the peak's 95 % point is {fmt(m['p95'])} µm "
            f"against {SHORT_IDEAL['p95']:g} (mean {fmt(m['mean'])} against {SHORT_IDEAL['mean']:g}, sd "
            f"{fmt(m['sd'])} against {SHORT_IDEAL['sd']:g}). The model errors explain less of the spread: the "
            f"payload mass's share of the variance is {mass:.2f} against {SHORT_IDEAL['payload mass']:.2f}, R² "
            f"{m['r2']:.2f} against {SHORT_IDEAL['r2']:.2f}, so the gusts and the sensor noise, drawn per sample and "
            f"left to the rest, carry {noise:.2f} of it" + (" and dominate" if noise > 0.5 else "")
            + f"; of the model errors, {lead} leads ({groups[lead]['src2']:.2f}). The disturbance observer estimates "
            "from the load cells whatever force the model misses, the payload's wrong weight and inertia as well "
            "as the wind's, while a sensor's error (an encoder's scale) is tracked as if it were true: that reads "
            "the shares, it is not a run that separates them. Peaks are counted from 1 s, over the whole run, and "
            "sit where the slew's acceleration changes: in the scene's own run (its seeds) 5.35 µm at "
            "t = 1.99 s, in "
            "its first 2 s, and 5.26 µm at t = 52.4 s as the slew stops; samples 0-3 peak in those first 2 s "
            "(the [ci] campaign, cut "
            "at 3 s, gives their peaks to the last digit)."]


def write(result, store=STORE, page_path=PAGE, figure=FIGURE):
    atomic.write_text(store, json.dumps(result, indent=1, default=float) + "\n")
    chart(result, figure)
    atomic.write_text(page_path, page(result))


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--ci", action="store_true")
    parser.add_argument("--jobs", type=int)
    parser.add_argument("--dask")
    parser.add_argument("--out", default="out")
    parser.add_argument("--docs", action="store_true", help="write docs/dynamic_budget.json, the page and chart")
    parser.add_argument("--from-store", action="store_true", help="the page and chart from docs/dynamic_budget.json")
    args = parser.parse_args(argv)
    if args.from_store:
        result = json.loads(STORE.read_text(encoding="utf-8"))
    else:
        result = analyse(run(args.out, args.ci, args.jobs, args.dask))
        result["redrawn"] = redrawn(args.ci)
    if args.docs or args.from_store:
        write(result)
    for metric, label in METRICS.items():
        m = result["metrics"][metric]
        print(f"{label}: mean {fmt(m['mean'])}, sd {fmt(m['sd'])}, 95 % {fmt(m['p95'])}; R² {m['r2']:.2f}; "
              + ", ".join(f"{g} {v['src2']:.2f}" for g, v in m["groups"].items()), file=sys.stderr)


if __name__ == "__main__":
    main()
