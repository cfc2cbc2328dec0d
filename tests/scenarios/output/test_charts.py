"""The charts the main job and the 3T study write: files appear, and the figures they
report agree with the models they are drawn from."""
import json
import pathlib
import re

import numpy as np
import pytest

from plant.hexapod.model import HOME_POSE, StewartParams, inverse_dynamics
from plant.mechanism3t import model as m3t
from scenarios.output import charts as style
from studies import mechanism3t_charts, paper_forces


def test_paper_leg_force_chart(tmp_path):
    path = paper_forces.main(tmp_path)
    assert path.exists() and path.stat().st_size > 10_000
    t, fixed, moving = paper_forces.paper_leg_forces(n=61)
    _, _, printed = paper_forces.paper_leg_forces(n=61, reading="eq43")
    top, axes = paper_forces.plot_paper_forces(t, fixed, {"model": moving, "eq43": printed}, tmp_path / "f.png")
    np.testing.assert_allclose(np.array([line.get_ydata() for line in top.get_lines()[:6]]).T, -fixed / 1e3)
    low, high = top.get_ylim()        # the fixed-base panel on its own scale: its 0.3 kN spread fills it
    assert low > 4.5 and high < 5.5 and np.ptp(-fixed / 1e3) > 0.5 * (high - low)
    assert len({ax.get_ylim() for ax in axes.flat}) == 1          # one force scale for the other panels
    for col, forces in enumerate((moving, printed)):
        for ax, data in zip(axes[:, col], (forces, forces - fixed)):
            lines = ax.get_lines()[:6]
            np.testing.assert_allclose(np.array([line.get_ydata() for line in lines]).T, -data / 1e3)
    styles = [(line.get_color(), line.get_linestyle(), line.get_linewidth()) for line in top.get_lines()[:6]]
    assert len(set(styles)) == 6                                   # every leg told apart, pairs included
    for first, second in ((0, 1), (2, 5), (3, 4)):                 # a pair: the thin line drawn over the wide one
        assert styles[first][0] == styles[second][0] and styles[first][2] > 2 * styles[second][2]
    figure = top.figure
    assert len(figure.legends) == 1 and all(ax.get_legend() is None for ax in [top, *axes.flat])
    t, fixed, moving = paper_forces.paper_leg_forces(n=61)
    static = inverse_dynamics(StewartParams.paper(), HOME_POSE, np.zeros(6), np.zeros(6))
    np.testing.assert_allclose(fixed[0], static, rtol=1e-12)   # starts at rest at home
    np.testing.assert_allclose(moving[0], static, rtol=1e-12)  # the base starts at identity
    assert np.all(-fixed > 0)                                  # legs in tension with the base fixed
    assert np.all(-moving[-1][[2, 5]] < 0)                     # legs 3 and 6 end in compression


def test_mechanism3t_charts(tmp_path):
    result = mechanism3t_charts.write_charts(tmp_path)
    assert all(pathlib.Path(p).exists() for p in result["charts"].values())
    history = m3t.paper_example()
    assert result["peak_force_N"] == pytest.approx(np.abs(history.forces).max(), rel=1e-12)
    assert 0 < result["workspace_volume_m3"] < result["paper_criterion_volume_m3"]
    ax = mechanism3t_charts.slider_force_chart(history, tmp_path / "forces.png")
    lines = {line.get_label(): line for line in ax.get_lines()}
    for k, name in enumerate(("x_A2", "y_A1", "y_A3")):
        np.testing.assert_array_equal(lines[f"slider {name}"].get_ydata(), history.forces[:, k])
    assert set(lines[f"paper's peak {mechanism3t_charts.PAPER_PEAK_FORCE_N} N"].get_ydata()) == {142.2}


def test_eq43_as_printed_counts_gravity_twice():
    """At rest (t = 0, base at identity) the printed eq. 43 is the static load under 2 g;
    at the end (rest again, base turned) it is our moving-base load plus the fixed-base
    gravity load. Read so, the changes match the paper's text (legs 1-2 up to ~14 kN,
    legs 3-6 ~6 kN); our model's do not (legs 4 and 5 change by < 1 kN)."""
    params = StewartParams.paper()
    t, fixed, printed = paper_forces.paper_leg_forces(n=61, reading="eq43")
    _, _, moving = paper_forces.paper_leg_forces(n=61)
    double = inverse_dynamics(StewartParams.paper(gravity=2 * params.gravity), HOME_POSE, np.zeros(6), np.zeros(6))
    np.testing.assert_allclose(printed[0], double, rtol=1e-10)
    np.testing.assert_allclose(printed[-1], moving[-1] + fixed[-1], rtol=1e-9)
    printed_rise = paper_forces.change_summary(fixed, printed)["rise"]
    assert np.all(np.abs(printed_rise[:2] - 14.0) < 1.0)          # "close to 14 000 N"
    assert np.all((printed_rise[2:] > 4.5) & (printed_rise[2:] < 7.0))   # "6 000 N"
    ours = paper_forces.change_summary(fixed, moving)
    assert np.all(np.maximum(ours["rise"], -ours["fall"])[[3, 4]] < 1.0)
    with pytest.raises(ValueError, match="unknown reading"):
        paper_forces.paper_leg_forces(reading="eq 43")


def _stored_realistic_loop():
    from studies import realistic_loop
    return realistic_loop, json.loads(realistic_loop.STORE.read_text())


def test_budget_chart_values_clear_of_the_marks_and_floored(tmp_path):
    """Every bar ends at its stored value; the value labels stand right of the axes (never
    on a mark line); values under 1 nm are written '< 1 nm'; rows without a fixed-base run
    say so; the ideal loop's value is drawn in each model's colour."""
    rl, s = _stored_realistic_loop()
    for scene in rl.SCENES:
        axes = rl.budget_chart(s, scene, tmp_path / f"{scene}.png")
        rows = rl.budget_rows(s, scene)
        for ax, key in zip(axes, ("peak", "rms")):
            expected = [row[m][key] for _, row in rows for m in ("fixed_base", "moving_base")
                        if m in row and row[m] and row[m][key] >= style.FLOOR]
            np.testing.assert_allclose([b.get_x() + b.get_width() for b in ax.patches], expected)
            labels = [t for t in ax.texts if t.get_transform() != ax.transData and t.get_position()[0] == 1.01]
            under = [row[m][key] for _, row in rows for m in row if row[m] and row[m][key] < style.FLOOR]
            assert sum(t.get_text() == "< 1 nm" for t in labels) == len(under)
            assert not any(re.search(r"\de-\d", t.get_text()) for t in ax.texts)   # no round-off exponents
            only = sum("fixed_base" not in row for _, row in rows)
            assert sum("moving-base model only" in t.get_text() for t in ax.texts) == only > 0
            ideal = {line.get_color() for line in ax.get_lines() if line.get_linestyle() != "-"
                     and list(line.get_xdata())[0] not in style.MARKS_UM.values()}
            assert {style.RUN_COLOURS["fixed_base"], style.RUN_COLOURS["moving_base"]} <= ideal


def test_wind_sweep_readable_log_axis_and_legend(tmp_path):
    rl, s = _stored_realistic_loop()
    ax = rl.sweep_chart(s, tmp_path / "sweep.png")
    ax.figure.canvas.draw()
    low, high = ax.get_ylim()
    labelled = [t for t in ax.get_yticks() if low <= t <= high]
    assert len(labelled) >= 4                                     # not only 10 and 100
    handles = ax.figure.legends[0].legend_handles
    looks = {(h.get_color(), h.get_marker(), str(h.get_linestyle()), h.get_markerfacecolor()) for h in handles}
    assert len(looks) == len(handles) == 4
    gains = {(h.get_marker(), h.get_markerfacecolor() == "white") for h in handles}
    assert len(gains) == 2                                        # the gains differ by marker and fill too


def test_work_precision_chart_floor_front_labels_and_ratios(tmp_path, monkeypatch):
    """Synthetic results with known costs and errors: the position axis stops at 1 nm and
    a run under it is drawn there as a triangle; only the front's points carry a step
    label; ratios are written as 'Nx' with 3 digits; no legend sits on the data."""
    from studies import work_precision as wp
    configs = [wp.Config(h, max_step=h) for h in (0.5e-3, 2e-3, 4e-3)] + [wp.DEFAULT]
    configs += [wp.Config(1e-3, integrator="euler", max_step=1e-3), wp.Config(1e-3, fidelity="massless_legs")]
    costs = [8.0, 2.0, 1.0, 4.0, 3.0, 0.5]
    pose = [2e-4, 0.05, 0.3, 7.0, 0.2, 40.0]            # the default far off the front, one run under 1 nm
    results = [{"config": c, "failure": None, "unstable": None, "cpu_time": w, "times": [w],
                "error": {"pose_rms_um": e, "force_rms_N": 10 * e + 1}} for c, w, e in zip(configs, costs, pose)]
    axes = []
    monkeypatch.setattr(style, "save", lambda fig, path: axes.extend(fig.axes))
    assert wp.chart("synthetic", results, tmp_path / "wp.png") == tmp_path / "wp.png"
    position = axes[0]
    assert position.get_ylim()[0] == style.FLOOR
    offsets = np.concatenate([c.get_offsets() for c in position.collections])
    assert [costs[0], style.FLOOR] in offsets.tolist() and pose[0] not in offsets[:, 1]
    front = wp.pareto_front(*wp.measures(results, "pose_rms_um"))
    labels = sorted(t.get_text() for t in position.texts)
    assert labels == sorted(f"{results[i]['config'].step * 1e3:g} ms" + ("" if results[i]["config"].fidelity == "full"
                                                               else f", {results[i]['config'].fidelity}")
                            for i in np.flatnonzero(front))
    v = wp.verdict(results)
    assert f"cost {style.ratio(v['cost_ratio'], 1)}" in position.get_title()
    assert not re.search(r"x\d+\.\d\d\b", position.get_title())          # no 'x5955.92'
    assert all(ax.get_legend() is None for ax in axes) and len(position.figure.legends) == 1


def _sky_rows(azimuths, elevations, peak):
    return [{"mode": mode, "peak": peak(a, e, mode), "rms": peak(a, e, mode) / 5, "flags": "", "values": {
        "base.start_azimuth": f"{a} deg", "base.target_azimuth": f"{a + 10} deg",
        "base.start_elevation": f"{e} deg", "base.target_elevation": f"{e + 5} deg"}}
        for a in azimuths for e in elevations for mode in ("fixed_base", "moving_base")]


def test_sky_map_ticks_every_cell_and_keeps_its_legend_off_the_cells(tmp_path, monkeypatch):
    from studies import sky_coverage as sc
    azimuths, elevations = (0, 60, 120, 180, 240, 300), (10, 30, 50, 70)
    rows = _sky_rows(azimuths, elevations, lambda a, e, mode: (50 + a / 10 if mode == "fixed_base" else 5e-4))
    axes = []
    monkeypatch.setattr(sc, "save", lambda fig, path: axes.extend(fig.axes[:4]))
    sc.map_chart(rows, tmp_path / "map.png")
    for ax in axes:
        np.testing.assert_allclose(ax.get_xticks(), azimuths)
        np.testing.assert_allclose(ax.get_yticks(), elevations)
        assert ax.get_legend() is None
        cells = [t.get_text() for t in ax.texts]
        assert len(cells) == len(azimuths) * len(elevations)
        assert not any(re.search(r"\de-\d", c) for c in cells)
    assert [t.get_text() for t in axes[2].get_xticklabels()] == [f"{a:g}" for a in azimuths]
    assert "<1 nm" in [t.get_text() for t in axes[1].texts]           # moving-base peaks under the floor
    assert len(axes[0].figure.legends) == 1


def test_slew_size_chart_ticks_at_the_sizes_run(tmp_path, monkeypatch):
    from studies import sky_coverage as sc
    sizes = (0.5, 1, 2, 5, 10, 20)
    rows = [{"mode": mode, "peak": 3.0 * d, "rms": 0.5 * d, "flags": "", "values": {
        "base.start_azimuth": "0 deg", "base.target_azimuth": f"{d} deg"}} for d in sizes
        for mode in ("fixed_base", "moving_base")]
    axes = []
    monkeypatch.setattr(sc, "save", lambda fig, path: axes.append(fig.axes[0]))
    sc.size_chart(rows, tmp_path / "sizes.png")
    np.testing.assert_allclose(axes[0].get_xticks(), sizes)
    assert [t.get_text() for t in axes[0].get_xticklabels()] == [f"{d:g}" for d in sizes]


@pytest.mark.parametrize("low, high, subs", [(1e-9, 1e5, {1.0}), (0.01, 50.0, {1.0, 2.0, 5.0})])
def test_plain_log_axes_label_wide_and_narrow_ranges(low, high, subs):
    """A log axis over 14 decades keeps labelled decades (matplotlib's LogLocator with
    subs 1-2-5 dropped every tick there); over 3.7 decades it labels 1, 2 and 5."""
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots()
    ax.set_yscale("log")
    ax.set_ylim(low, high)
    style.plain_log_axis(ax.yaxis)
    fig.canvas.draw()
    ticks = [t for t in ax.yaxis.get_majorticklocs() if low <= t <= high]
    labels = [t.get_text() for t in ax.yaxis.get_majorticklabels() if t.get_text()]
    plt.close(fig)
    assert 5 <= len(ticks) <= 15 and len(labels) >= 5
    assert {round(t / 10 ** np.floor(np.log10(t)), 6) for t in ticks} == subs
