"""What ``movingbase regress`` writes for people and CI servers: a JUnit XML file (one
test suite per scenario file, one test case per run) and a Markdown report with a chart
per failure: the baseline, its tube, the new curve and where it leaves the tube.

It reads the comparison's outcome (scenarios.runs.regress.Regression) by its fields."""
import math
import pathlib
import re
from xml.etree import ElementTree

import numpy as np

from fmu_src import atomic
from scenarios.output.charts import MARK_COLOUR, save

CHARTS_PER_RUN = 4    # the first failures of a run drawn (first outside its tube first); the rest listed


def write_junit(outcome, path):
    """The JUnit XML of ``outcome`` at ``path`` (written whole): a failure per regressed
    run, its findings as the message and text; an error per scenario that could not run."""
    suites = ElementTree.Element("testsuites", name="movingbase regress")
    for scene in outcome.scenes:
        suite = ElementTree.SubElement(suites, "testsuite", name=scene.name, time=f"{scene.wall_time:.3f}")
        failures = errors = 0
        if scene.error:
            case = ElementTree.SubElement(suite, "testcase", classname=scene.name, name="(scenario)")
            ElementTree.SubElement(case, "error", message=scene.error[:500]).text = scene.error
            errors += 1
        for run in scene.runs:
            case = ElementTree.SubElement(suite, "testcase", classname=scene.name, name=run.label)
            if run.findings:
                failures += 1
                failure = ElementTree.SubElement(case, "failure", message=run.findings[0].text[:500],
                                                 type="regression")
                failure.text = "\n".join(f.text for f in run.findings) + "".join(
                    f"\nchanged since the baseline: {note}" for note in scene.notes)
        suite.set("tests", str(len(scene.runs) + bool(scene.error)))
        suite.set("failures", str(failures))
        suite.set("errors", str(errors))
    ElementTree.indent(suites)
    path = pathlib.Path(path)
    atomic.write_text(path, ElementTree.tostring(suites, encoding="unicode", xml_declaration=True) + "\n")
    return path


def write_report(outcome, folder):
    """folder/regress.md: every scenario's verdict, every finding, and a chart per failing
    signal or metric (the first CHARTS_PER_RUN of each run); its path."""
    folder = pathlib.Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    _remove_earlier(folder)
    lines = [f"# Regression against {outcome.baseline}", "",
             f"**{'passed' if outcome.exit_code == 0 else 'REGRESSION' if outcome.exit_code == 1 else 'COULD NOT RUN'}"
             f"**: {sum(s.verdict == 'pass' for s in outcome.scenes)} of {len(outcome.scenes)} scenario files passed.",
             "", "| scenario | run | verdict | first finding |", "|---|---|---|---|"]
    for scene in outcome.scenes:
        if scene.error:
            lines.append(f"| {scene.name} | | could not run | {_cell(scene.error)} |")
        for run in scene.runs:
            lines.append(f"| {scene.name} | {run.label} | {'REGRESSION' if run.findings else 'pass'} | "
                         f"{_cell(run.findings[0].text) if run.findings else ''} |")
    for scene in outcome.scenes:
        bad = [r for r in scene.runs if r.findings]
        if not bad:
            continue
        lines += ["", f"## {scene.name}", ""]
        lines += [f"- changed since the baseline: {note}" for note in scene.notes]
        for run in bad:
            lines += ["", f"### {scene.name}, run {run.label}", ""]
            lines += [f"- {f.text}" for f in run.findings]
            drawn = set()
            for finding in run.findings:
                name = finding.curve
                if name not in run.curves or name in drawn or len(drawn) == CHARTS_PER_RUN:
                    continue
                png = f"{_file(scene.name)}_{_file(run.label)}_{_file(name)}.png"
                save(tube_chart(scene.name, run.label, name, finding, *run.curves[name]), folder / png)
                lines += ["", f"![{name}: baseline, tube and new run]({png})"]
                drawn.add(name)
    path = folder / "regress.md"
    atomic.write_text(path, "\n".join(lines) + "\n")
    return path


def _remove_earlier(folder):
    """Remove the charts an earlier report in ``folder`` drew: a chart of a failure that is
    gone is not this report's."""
    earlier = folder / "regress.md"
    if earlier.is_file():
        for png in re.findall(r"\]\(([^)/]+\.png)\)", earlier.read_text(encoding="utf-8")):
            (folder / png).unlink(missing_ok=True)


def _cell(text):
    return text.replace("|", "\\|").replace("\n", " ")


def _file(text):
    return "".join(c if c.isalnum() or c in "-_" else "_" for c in text).strip("_")


def tube_chart(scene, label, name, finding, t, y, low, high, t_new, y_new, unit):
    """Two panels against time: above, the baseline, its tube and the new curve; below,
    the new curve less the baseline with the tube's edges likewise (a tube of 1e-5 µm
    around 100 µm is seen only there); the points outside the tube in red, the first one
    marked. Returns the figure."""
    from scenarios.output.report import _figure
    fig, axes = _figure(2, 1, (9, 6), left=1.2, right=0.3, top=0.6, bottom=0.6, gap=0.35, sharex=True)
    top, bottom = axes[0, 0], axes[1, 0]
    at = np.interp(t, t_new, y_new) if len(t_new) else np.full(len(t), np.nan)
    out = (at > high) | (at < low)
    top.fill_between(t, low, high, color="0.75", alpha=0.6, lw=0, label="tube")
    top.plot(t, y, color="0.2", lw=1.0, label="baseline")
    top.plot(t_new, y_new, color="#1f77b4", lw=1.0, ls="--", label="new run")
    top.plot(t[out], at[out], "o", ms=3, color=MARK_COLOUR, label="outside the tube")
    bottom.fill_between(t, low - y, high - y, color="0.75", alpha=0.6, lw=0,
                        label=f"tube (up to +-{float(np.nanmax(high - y)):.2g} {unit}: may be too thin to see)")
    bottom.plot(t, at - y, color="#1f77b4", lw=1.0)
    bottom.plot(t[out], (at - y)[out], "o", ms=3, color=MARK_COLOUR)
    bottom.axhline(0.0, color="0.2", lw=0.8)
    if math.isfinite(finding.first):
        for ax in (top, bottom):
            ax.axvline(finding.first, color=MARK_COLOUR, lw=0.8, ls=":")
        bottom.text(0.01, 0.03, f"first outside: t = {finding.first:.4g} s (dotted)", transform=bottom.transAxes,
                    color=MARK_COLOUR, fontsize=8)
    top.set_ylabel(f"{name}\n[{unit or '-'}]")
    bottom.set_ylabel(f"new - baseline\n[{unit or '-'}]")
    bottom.set_xlabel("time [s]")
    for ax in (top, bottom):
        ax.grid(True, lw=0.4, color="0.85")
    top.legend(loc="best", fontsize=7.5, frameon=False)
    bottom.legend(loc="best", fontsize=7.5, frameon=False)
    fig.suptitle(f"{scene}, run {label}: {finding.text}"[:230], fontsize=9, color="#b00020", wrap=True)
    return fig
