"""The error-budget study (studies/error_budget.py): its table from known records, and its
[ci] runs (~10 s on two workers) against docs/error-budget.md, which they generate."""
import math

import pytest

from studies import error_budget as study
from studies import realistic_loop

POSE = {"rms": 27.2, "peak": 106.0, "rotation_rms": 1.4, "rotation_peak": 5.5, "unit": "µm, µrad"}
POINTING = {"rms": 0.125, "peak": 0.5, "path_rms": 1.5, "path_peak": 5.5, "efficiency_loss_15GHz": 1e-5,
            "efficiency_loss_22GHz": 4.5e-5, "efficiency_loss_31GHz": 9e-5, "efficiency_loss_43GHz": 1.75e-4,
            "unit": "arcsec, µm, %"}


def test_the_table_gives_each_effect_and_feedforward_in_the_telescope_s_units():
    ok = {"status": "ok", "metrics": {realistic_loop.METRIC: POSE, "pointing": POINTING}}
    results = {"ideal": {"exact": {"none": ok, "fixed_base": ok, "moving_base": ok}},
               "wind": {"exact": {"fixed_base": {"status": "failed"}, "moving_base": ok}}}
    lines = study.table((results, {"observer": {**POSE, "pointing": POINTING}})).splitlines()
    assert "efficiency lost at K 22 GHz [%] | efficiency lost at Q 43 GHz [%] |" in lines[0]
    assert lines[2] == ("| ideal loop | none (PID only) | 27.2 / 106 | 0.125 / 0.5 | 1.5 / 5.5 | 4.5e-05 | "
                        "0.000175 |")
    wind = [line for line in lines if "fixed-base" in line and line.startswith("| wind")]
    assert wind == ["| wind (10 m/s, Kaimal gust) | fixed-base model (base motion ignored) | failed | failed | failed "
                    "| failed | failed | failed |"]
    not_run = [line for line in lines if line.startswith("| leg encoders")]
    assert not_run and "failed" in not_run[0]          # a case not in the results is no number either
    assert len(lines) == 2 + 3 + 2 * (len(realistic_loop.EFFECTS) + 1) + len(study.SCHEME_ROWS) + 1
    observer, anemometer = lines[-3:-1]        # the schemes: one given, one not run
    assert observer.endswith("| moving-base model | 27.2 / 106 | 0.125 / 0.5 | 1.5 / 5.5 | 4.5e-05 | 0.000175 |")
    assert "disturbance observer" in observer and anemometer.count("failed") == 6


@pytest.fixture(scope="module")
def ran(tmp_path_factory):
    return study.run(tmp_path_factory.mktemp("budget"), jobs=2, progress=False)


def test_every_budget_run_finishes_and_the_docs_page_is_current(ran):
    effects, schemes = ran
    assert all(record["status"] == "ok" for modes in effects.values() for record in modes["exact"].values())
    assert all(entry is not None for entry in schemes.values())
    page = study.REPORT.read_text()
    assert study.table(ran) in page, "docs/error-budget.md is stale: python -m studies.error_budget"


def test_the_moving_base_model_points_better_and_wind_costs_pointing(ran):
    """The budget's physics: with the moving-base feedforward the beam points better than
    with the base motion ignored; wind alone adds pointing error to the moving-base loop;
    the efficiency loss grows with frequency as (f)^2 for errors this small."""
    effects, schemes = ran
    point = {(loop, mode): effects[loop]["exact"][mode]["metrics"]["pointing"] for loop in effects
             for mode in effects[loop]["exact"]}
    assert point["ideal", "moving_base"]["rms"] < 0.1 * point["ideal", "fixed_base"]["rms"]
    assert point["wind", "moving_base"]["rms"] > 10 * point["ideal", "moving_base"]["rms"]
    worst = point["wind", "fixed_base"]
    assert worst["efficiency_loss_43GHz"] / worst["efficiency_loss_22GHz"] == pytest.approx((43 / 22) ** 2, rel=1e-3)
    assert all(math.isfinite(v) for v in worst.values() if not isinstance(v, str))


def test_the_observer_takes_the_wind_out_of_the_budget(ran):
    """The last rows: the disturbance observer on load cells brings the all-effects, 10 m/s
    wind row's peak pose and pointing error down; the chart is drawn from the same rows."""
    effects, schemes = ran
    everything = effects["realistic"]["exact"]["moving_base"]["metrics"]
    assert schemes["observer"]["peak"] < 0.6 * everything[realistic_loop.METRIC]["peak"]
    assert schemes["observer"]["pointing"]["peak"] < everything["pointing"]["peak"]
    rows = study.chart_rows(ran)
    assert rows[-3][1]["moving_base"] == (schemes["observer"]["peak"], schemes["observer"]["pointing"]["peak"])


def test_the_support_sway_row_is_the_recorded_sway_through_the_optics(ran):
    """The support row: the sway's own pointing through the optics is larger than what the
    hexapod's error costs with the moving-base model in the same wind (the hexapod cannot
    correct its base), and its position peak is the scale of the sway (µm to mm)."""
    effects, schemes = ran
    sway = schemes["support"]
    everything = effects["realistic"]["exact"]["moving_base"]["metrics"]
    assert sway["pointing"]["peak"] > everything["pointing"]["peak"]
    assert 10.0 < sway["peak"] < 5000.0 and sway["rms"] <= sway["peak"]
