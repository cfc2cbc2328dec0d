"""The scene report and its charts, from synthetic runs whose numbers are known: each
chart is written and holds the series it should (figure objects, not pixels), the base
motion panel's acceleration matches the analytic derivative of the recorded rate, and
the report states settings, names the runs and gives each number once."""
import json
import math

import numpy as np
import pytest

from scenarios import spec
from scenarios.cosim.master import Run
from scenarios.cosim.records import Records
from scenarios.output import headline, report
from scenarios.runs.runner import SHIPPED

T0, T1, CUT = 0.0, 8.0, 5.0


def _scenario(name="telescope_slew"):
    return spec.load(SHIPPED / f"{name}.toml", overrides={"stop_time": f"{T1} s"})


def _rate(t):
    """Recorded axis rates [rad/s]: smooth, with a known derivative."""
    return np.stack([1e-3 * np.sin(t), 5e-4 * np.cos(0.5 * t)], -1)


def _acc(t):
    return np.stack([1e-3 * np.cos(t), -2.5e-4 * np.sin(0.5 * t)], -1)


def _runs(tmp_path, scales=(1.0, 1.0 + 1e-4, 1e-2)):
    """Three runs whose error series are one shape times a scale; metrics from the series."""
    t = np.arange(0.0, T1 + 1e-9, 0.01)
    te = t[t >= CUT]
    shape = 1e-6 * (1.5 + np.sin(3 * te)) * 50     # [m] 25-125 µm
    runs = []
    for label, scale in zip(("none", "fixed_base", "moving_base"), scales):
        path = Records.of(t, ["base.axis_rate[1]", "base.axis_rate[2]"], ["rad/s"] * 2,
                          _rate(t)).save(tmp_path / f"{label}.npz")
        leg, pos, rot = 0.4 * shape * scale, shape * scale, 0.05 * shape * scale
        series = {"leg error": (te, leg * 1e6), "pose error": (te, pos * 1e6), "pose error rotation": (te, rot)}
        rms = lambda v: float(np.sqrt(np.mean(v ** 2)))
        metrics = {"leg error": {"rms": rms(leg) * 1e6, "peak": leg.max() * 1e6, "unit": "µm"},
                   "pose error": {"rms": rms(pos) * 1e6, "peak": pos.max() * 1e6, "rotation_rms": rms(rot) * 1e6,
                                  "rotation_peak": rot.max() * 1e6, "unit": "µm, µrad"},
                   "pointing": {"rms": 0.125 * scale, "peak": 0.5 * scale, "path_rms": 1.5 * scale,
                                "path_peak": 5.5 * scale, "efficiency_loss_15GHz": 2e-5, "efficiency_loss_22GHz": 4e-5,
                                "efficiency_loss_31GHz": 9e-5, "efficiency_loss_43GHz": 1.75e-4,
                                "unit": "arcsec, µm, %"},
                   "leg force": {"rms": 11.0, "peak": 16.25, "unit": "kN"},
                   "base effect": {"rms": 11.7, "peak": 17.5432, "gravity_peak": 17.3, "transport_peak": 0.245,
                                   "unit": "kN"}}
        runs.append(Run(label, path, 8000, 0.5, T1, metrics, series))
    return runs


def _metric(scenario, name):
    return next(m for m in scenario.metrics if m.name == name)


def _line(ax, label):
    return next(line for line in ax.get_lines() if line.get_label() == label)


def _texts(ax):
    return " ".join(t.get_text() for t in ax.texts)


def test_pose_chart_holds_position_rotation_and_base_motion(tmp_path):
    scenario, runs = _scenario(), _runs(tmp_path)
    path = tmp_path / "pose.png"
    panels = report._error_chart(scenario, runs, _metric(scenario, "pose error"), path)
    assert path.exists() and path.stat().st_size > 10_000
    assert set(panels) == {"position", "rotation", "axis rate", "axis acceleration"}
    for run in runs:
        t, position = run.series["pose error"]
        np.testing.assert_array_equal(_line(panels["position"], run.label).get_ydata(), position)
        np.testing.assert_allclose(_line(panels["rotation"], run.label).get_ydata(),
                                   run.series["pose error rotation"][1] * 1e6)
    assert "µm" in panels["position"].get_ylabel() and "µrad" in panels["rotation"].get_ylabel()
    # none and fixed_base differ by 1e-4 of the signal: told apart by style and said on the chart
    none, fixed = _line(panels["position"], "none"), _line(panels["position"], "fixed_base")
    assert (none.get_linestyle(), none.get_linewidth()) != (fixed.get_linestyle(), fixed.get_linewidth())
    assert "none and fixed_base coincide" in _texts(panels["position"])
    largest = np.abs(runs[0].series["pose error"][1] - runs[1].series["pose error"][1]).max()
    assert report.length(largest) in _texts(panels["position"])
    peak = max(runs[0].series["pose error"][1].max(), runs[1].series["pose error"][1].max())
    assert f"({100 * largest / peak:.2g} % of the peak)" in _texts(panels["position"])   # 1e-4: 0.01 %
    for name, ax in panels.items():
        assert ax.get_xlim() == (T0, T1)                            # trimmed to the scene
        assert any(list(line.get_xdata()) == [CUT, CUT] for line in ax.get_lines())   # cut-off marked
    assert panels["position"].get_yscale() == "log" and panels["position"].get_ylim()[0] == report.FLOOR


def test_base_motion_panel_is_rate_and_its_derivative(tmp_path):
    scenario, runs = _scenario(), _runs(tmp_path)
    panels = report._error_chart(scenario, runs, _metric(scenario, "leg error"), tmp_path / "leg.png")
    assert set(panels) == {"position", "axis rate", "axis acceleration"}
    assert "leg length error" in panels["position"].get_ylabel()
    marks = [line for line in panels["position"].get_lines() if list(line.get_ydata()) in ([10.0] * 2, [100.0] * 2)]
    assert not marks                                     # the pose marks are no leg-length requirement
    t = _line(panels["axis rate"], "azimuth").get_xdata()
    for k, axis in enumerate(("azimuth", "elevation")):
        np.testing.assert_allclose(_line(panels["axis rate"], axis).get_ydata(), np.degrees(_rate(t)[:, k]))
        acc = _line(panels["axis acceleration"], axis).get_ydata()
        # central differences of a 10 ms record: error ~ h^2/6 * third derivative, ends one-sided
        np.testing.assert_allclose(acc[1:-1], np.degrees(_acc(t)[1:-1, k]), atol=np.degrees(2e-8))


def test_run_under_the_floor_is_said(tmp_path):
    scenario = _scenario()
    runs = _runs(tmp_path, scales=(1.0, 0.5, 1e-6))      # moving_base peaks at 1.25e-4 µm
    panels = report._error_chart(scenario, runs, _metric(scenario, "pose error"), tmp_path / "p.png")
    assert "moving_base: under the floor throughout" in _texts(panels["position"])
    assert "coincide" not in _texts(panels["position"])


def test_no_base_panel_when_the_plant_holds_its_base_fixed(tmp_path):
    scenario = spec.load(SHIPPED / "paper_fixed_base.toml", overrides={"stop_time": f"{T1} s"})
    panels = report._error_chart(scenario, _runs(tmp_path)[:2], _metric(scenario, "pose error"), tmp_path / "f.png")
    assert set(panels) == {"position", "rotation"}


def test_chart_without_a_telescope_has_no_base_panel(tmp_path):
    scenario = spec.load(SHIPPED / "mechanism3t_paper.toml")
    metric = next(m for m in scenario.metrics if m.kind in report.TRACKING)
    t = np.linspace(0.0, 1.0, 50)
    path = Records.of(t, [], [], np.empty((len(t), 0))).save(tmp_path / "run.npz")
    runs = [Run("run", path, 1000, 0.1, 1.0, {}, {metric.name: (t, 1.0 + t)})]
    panels = report._error_chart(scenario, runs, metric, tmp_path / "m.png")
    assert list(panels) == ["position"]
    np.testing.assert_array_equal(_line(panels["position"], "run").get_ydata(), 1.0 + t)


def test_summary_bars_are_the_metrics_on_a_log_scale(tmp_path):
    scenario, runs = _scenario(), _runs(tmp_path)
    tracked = [m for m in scenario.metrics if m.kind in report.TRACKING]
    path = tmp_path / "summary.png"
    panels = report._summary_chart(scenario, runs, tracked, path)
    assert path.exists()
    assert len(panels) == 3      # leg length, platform position, platform rotation
    for title, ax in panels.items():
        name = "leg error" if title.startswith("leg") else "pose error"
        keys = ("rotation_rms", "rotation_peak") if "rotation" in title else ("rms", "peak")
        tops = [p.get_y() + p.get_height() for p in ax.patches]
        expected = [r.metrics[name][keys[0]] for r in runs] + [r.metrics[name][keys[1]] for r in runs]
        np.testing.assert_allclose(tops, expected)
        assert ax.get_yscale() == "log" and ax.get_ylim()[0] == report.FLOOR
        assert ("µrad" if "rotation" in title else "µm") in ax.get_ylabel()
        colours = [p.get_facecolor()[:3] for p in ax.patches[:3]]
        assert colours[1] != colours[2]                  # fixed- and moving-base runs in their colours
    position = panels["pose error: platform position"]
    levels = {line.get_ydata()[0] for line in position.get_lines()}
    assert {10.0, 100.0} <= levels                       # both marks drawn, the peak is 125 µm
    assert not panels["leg error: leg length (6 legs)"].get_lines()   # pose marks: no leg-length requirement
    assert scenario.name in position.figure.get_suptitle()


def test_summary_says_when_marks_are_off_scale(tmp_path):
    scenario = _scenario()
    runs = _runs(tmp_path, scales=(1e-3, 1e-3, 1e-5))     # peaks ~0.1 µm
    tracked = [m for m in scenario.metrics if m.kind in report.TRACKING]
    panels = report._summary_chart(scenario, runs, tracked, tmp_path / "s.png")
    assert "10 µm and 0.1 mm marks: off the scale" in _texts(panels["pose error: platform position"])
    under = panels["pose error: platform rotation"]    # rotation peaks ~1e-4 µrad and 5e-6 µrad
    assert "< 1 nrad" in [t.get_text() for t in under.texts]


def test_report_names_runs_states_settings_and_gives_base_effect_once(tmp_path):
    scenario, runs = _scenario(), _runs(tmp_path)
    text = report.write(scenario, runs, tmp_path).read_text()
    for part in ("master jacobi", "input extrapolation linear", "communication step 1 ms", "integrator rk4",
                 "fidelity full", "from 5 s", "run `fixed_base`", "`fixed_base` = PID + feedforward from the "
                 "fixed-base model (the base motion ignored)", "stepping loop only"):
        assert part in text, part
    assert text.count("17.5") == 1                       # the base effect, once, not per run
    assert ("| pointing (arcsec, µm, %) |" in text and "pointing RMS 0.125 arcsec, peak 0.5 arcsec; path error RMS "
            "1.5 µm, peak 5.5 µm; efficiency lost 15 GHz 2e-05 %, 22 GHz 4e-05 %, 31 GHz 9e-05 %, 43 GHz 0.000175 %"
            in text)
    fixed, moving = runs[1].metrics["pose error"], runs[2].metrics["pose error"]
    assert f"{fixed['rms'] / moving['rms']:.3g}x the RMS" in text
    for name in ("leg_error_vs_time.png", "pose_error_vs_time.png", "summary.png"):
        assert (tmp_path / name).exists() and f"]({name})" in text


@pytest.mark.parametrize("charts, drawn", [("all", {"leg_error_vs_time.png", "pose_error_vs_time.png", "summary.png"}),
                                           ("summary", {"summary.png"}), ("none", set())])
def test_charts_choice_draws_what_is_asked_and_the_report_links_only_those(tmp_path, charts, drawn):
    scenario, runs = _scenario(), _runs(tmp_path)
    text = report.write(scenario, runs, tmp_path, charts).read_text()
    assert {p.name for p in tmp_path.glob("*.png")} == drawn
    assert {part.split(")")[0] for part in text.split("](")[1:] if ".png" in part.split(")")[0]} == drawn
    with pytest.raises(ValueError, match="charts must be one of all, summary, none, got 'some'"):
        report.write(scenario, runs, tmp_path, "some")


def test_a_run_without_charts_imports_no_plotting_design_or_cluster_library(tmp_path):
    """The CLI's own process, one [ci] scenario, --charts none: matplotlib, python-control,
    scipy, dask and pandas are not imported (each costs a run 0.1-1.3 s; issue 21). The
    FMUs are built first, here: building one imports the FMU scripts and what they use."""
    import subprocess
    import sys

    from scenarios.runs.runner import prepare, resolve
    prepare(resolve("telescope_slew"), ci=True)
    code = ("import sys; from movingbase.cli import run_command as main; "
            f"main(['telescope_slew', '--ci', '--quiet', '--charts', 'none', '--out', {str(tmp_path)!r}]); "
            "print(sorted(m for m in ('matplotlib', 'control', 'scipy', 'dask', 'distributed', 'pandas') "
            "if m in sys.modules))")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert (tmp_path / "telescope_slew" / "report.md").exists() and not list(tmp_path.rglob("*.png"))
    assert done.stdout.splitlines()[-1] == "[]", done.stdout

def test_ratio_and_fmt_are_three_digits():
    assert report.ratio(9.2547, 0.0641) == f"{9.2547 / 0.0641:.3g}x" == "144x"
    assert report.ratio(129.0, 0.0767) == "1680x" and report.ratio(1.0, 0.5) == "2x"
    assert report.fmt(math.pi) == "3.14"


def test_readme_headline_is_generated_from_the_stored_metrics():
    """The README's headline section is what scenarios.output.headline writes from
    docs/headline.json, with the report's own sentences: no number typed by hand."""
    store = json.loads(headline.STORE.read_text())
    text = headline.README.read_text()
    section = text[text.index(headline.BEGIN):text.index(headline.END) + len(headline.END)]
    assert section == headline.render(store)
    for scene, runs in store.items():
        assert report.compare(runs, "pose error") in section
        fixed, moving = runs["fixed_base"]["pose error"], runs["moving_base"]["pose error"]
        if moving["peak"] >= report.FLOOR:
            assert report.ratio(fixed["rms"], moving["rms"]) + " the RMS" in section


def test_cli_help_and_unknown_scenario_list_the_shipped_ones(capsys):
    from movingbase.cli import run_command as main
    shipped = sorted(p.stem for p in SHIPPED.glob("*.toml"))
    with pytest.raises(SystemExit) as done:
        main(["--help"])
    assert done.value.code == 0
    out = " ".join(capsys.readouterr().out.split())
    assert all(name in out for name in shipped) and "stepping loop only" in out
    with pytest.raises(SystemExit) as done:
        main(["no_such_scene"])
    message = str(done.value.code)
    assert "'no_such_scene'" in message and all(name in message for name in shipped)


def test_the_command_ends_with_its_status_after_writing_everything(tmp_path):
    """`python -m movingbase` ends without the interpreter's teardown (0.2-0.3 s saved):
    the status is still the command's, every file is written, an error still says why."""
    import subprocess
    import sys
    command = [sys.executable, "-m", "movingbase", "run", "--quiet", "--charts", "summary", "--out", str(tmp_path)]
    done = subprocess.run(command + ["telescope_slew", "--ci"], capture_output=True, text=True)
    assert done.returncode == 0 and "telescope_slew: report" in done.stdout, done.stderr
    folder = tmp_path / "telescope_slew"
    assert set(json.loads((folder / "metrics.json").read_text())) == {"none", "fixed_base", "moving_base"}
    assert (folder / "report.md").read_text().endswith("\n") and (folder / "summary.png").stat().st_size > 10_000
    failed = subprocess.run(command + ["no_such_scene"], capture_output=True, text=True)
    assert failed.returncode == 1 and "no scenario file or shipped scenario named 'no_such_scene'" in failed.stderr


def test_build_command_returns_no_exit_status(monkeypatch):
    """`movingbase build` returned the builder's output folder, which the console script
    passed to sys.exit: the folder printed as an error and status 1 after a good build."""
    import pathlib

    from movingbase import cli
    monkeypatch.setattr(cli, "build_command", lambda argv: pathlib.Path("build/fmu"))
    assert cli.main(["build"]) is None
