"""studies/dynamic_budget.py's analysis against a response whose variance shares are known:
y = 2 a + b + e with a, b, e independent of unit variance gives a's group 4/6 of the
variance, b's 1/6, R^2 = 5/6, and nothing to the inputs that do not enter."""
import csv

import numpy as np
import pytest

from studies import dynamic_budget


def test_shares_of_a_known_linear_response(tmp_path):
    rng = np.random.default_rng(1)
    n = 2000
    inputs = ["plant.payload_mass_error [kg]", "plant.payload_inertia_error[1] [kg.m2]", "encoders.scale_error[1]",
              "encoders.scale_error[2]", "imu.imu_alignment[1] [rad]"]
    x = np.c_[rng.normal(0, 40, n), rng.uniform(-550, 550, (n, 1)), rng.uniform(-1e-4, 1e-4, (n, 2)),
              rng.uniform(-1e-3, 1e-3, n)]
    z = (x - x.mean(0)) / x.std(0)
    y = 2 * z[:, 0] + z[:, 4] + rng.normal(0, 1, n)
    path = tmp_path / "summary.csv"
    with open(path, "w", newline="") as file:
        writer = csv.writer(file)
        writer.writerow(["label", *inputs, "status", "pose error peak", "pose error rms"])
        writer.writerows([f"sample {k}", *x[k], "ok", 7 + y[k], 3 + 0.1 * y[k]] for k in range(n))
    result = dynamic_budget.analyse(path)
    m = result["metrics"]["pose error peak"]
    groups = m["groups"]
    assert m["r2"] == pytest.approx(5 / 6, abs=0.02)
    assert groups["payload mass"]["src2"] == pytest.approx(4 / 6, abs=0.03)
    assert groups["IMU alignment"]["src2"] == pytest.approx(1 / 6, abs=0.02)
    assert groups["encoder scale"]["src2"] < 0.005 and groups["payload inertia"]["src2"] < 0.005
    mass = groups["payload mass"]
    assert mass["low"] < mass["src2"] < mass["high"] and mass["high"] - mass["low"] < 0.1
    assert m["sd"] == pytest.approx(np.sqrt(6), rel=0.05)
    page = dynamic_budget.page(result)
    assert "| payload mass | 0.6" in page and f"{n} samples" in page


def test_percentiles_are_read_on_the_percent_scale(tmp_path):
    """y = 1..200 exactly: the median is 100.5 and p95 (linear interpolation at rank 1 + 199 x
    0.95 = 190.05) is 190.05; np.percentile(y, 0.95) would give 2.8905."""
    path = tmp_path / "summary.csv"
    rng = np.random.default_rng(2)
    with open(path, "w", newline="") as file:
        writer = csv.writer(file)
        writer.writerow(["label", "plant.payload_mass_error [kg]", "status", "pose error peak", "pose error rms"])
        writer.writerows([f"sample {k}", rng.normal(), "ok", k + 1, 1 + (k % 7)] for k in range(200))
    m = dynamic_budget.analyse(path)["metrics"]["pose error peak"]
    assert m["p50"] == pytest.approx(100.5, abs=1e-12) and m["p95"] == pytest.approx(190.05, abs=1e-12)
    assert m["max"] == 200 and m["mean"] == pytest.approx(100.5)


def test_the_scene_is_the_shipped_realistic_slew_in_wind_with_the_observer():
    """The campaign's scene runs the slew, plant, controller, wind and load cells of
    scenarios/files/telescope_slew_observer.toml's observer run (issue 41), parameter for
    parameter, with an IMU and encoders in place of the ideal base input and leg sensor, and
    each sample draws the gusts (wind.seed) beside the sensors' noise."""
    import tomllib

    from scenarios.runs import campaign as campaigns
    scene = tomllib.loads((campaigns.SHIPPED / "scenes" / "dynamic_budget.toml").read_text())
    shipped = tomllib.loads((campaigns.SHIPPED.parent / "files" / "telescope_slew_observer.toml").read_text())
    params = lambda table, inst: table["fmus"][inst]["parameters"]   # noqa: E731
    for inst in ("controller", "wind", "load_cell"):
        assert params(scene, inst) == params(shipped, inst), inst
    assert params(scene, "plant") == params(shipped, "plant")   # 0.1 nm substeps both
    assert params(shipped, "controller")["observer_bandwidth"] == "32 Hz" and "32 Hz" in shipped["sweep"]["values"]
    assert {k: v for k, v in params(scene, "base").items() if k != "start_delay"} == \
        {k: v for k, v in params(shipped, "base").items() if k != "start_delay"}
    assert params(scene, "encoders") == params(shipped, "leg_sensor")
    assert (scene["step"], scene["master"], scene["extrapolation"]) == \
        (shipped["step"], shipped["master"], shipped["extrapolation"])
    sample = campaigns.load("dynamic_budget").sample
    assert sample.samples == 256
    assert {key for key, *_ in sample.seeds} == {"imu.seed", "encoders.seed", "load_cell.seed", "wind.seed"}
