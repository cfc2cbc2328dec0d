"""The wind-rejection study (issue 29): its scheme table makes runnable scenes, its docs
regenerate from the stored results, and the observer's estimate against the Wind FMU's
true force in co-simulation (the truth of item 6)."""
import json
import re

import numpy as np
import pytest
from scipy import signal

from plant.hexapod.model import StewartParams, dynamics_terms
from scenarios.runs import runner
from studies import wind_rejection as study


def test_a_scheme_is_a_table_of_scenario_changes():
    """The observer scheme adds its load cell, wiring and parameters to the realistic loop
    and nothing else: the PID scheme's scenario plus exactly those."""
    plain = study.scheme_scenario("telescope_slew", "pid", 10.0)
    wired = study.scheme_scenario("telescope_slew", "observer", 10.0)
    assert set(wired["fmus"]) - set(plain["fmus"]) == {"load_cell"}
    added = [c for c in wired["connections"] if c not in plain["connections"]]
    assert added == study.SCHEMES["observer"]["connections"]
    assert wired["fmus"]["controller"]["parameters"]["observer_bandwidth"] == f"{study.OBSERVER_BANDWIDTH:g} Hz"
    assert wired["fmus"]["controller"]["parameters"]["observer_model"] == "leg_space"
    assert "wind" not in study.scheme_scenario("telescope_slew", "pid", 0.0)["fmus"]   # calm: no wind FMU


def test_the_docs_regenerate_from_the_store(tmp_path, monkeypatch):
    """--from-store writes the page from docs/wind_rejection.json, every number from it."""
    monkeypatch.setattr(study, "REPORT", tmp_path / "wind-rejection.md")
    stored = json.loads(study.STORE.read_text())
    study.report(stored, charts=False)
    text = (tmp_path / "wind-rejection.md").read_text()
    assert "## The goals" in text
    peak = stored["runs"]["telescope_slew/observer/10"]["peak"]
    assert f"({study.OBSERVER_BANDWIDTH:g} Hz) {study.fmt(peak)} µm" in text


@pytest.mark.slow
def test_the_observer_estimates_the_true_wind_force_through_q(tmp_path):
    """The shipped observer slew in 10 m/s wind at 8 Hz, 12 s recorded every step: the Wind FMU's
    wrench on the platform mapped to leg space (F = J^-T W at the pose, J the plant's own
    twist Jacobian: M du + h - W = J^T F) is the truth. The estimate is that force through
    Q (2nd-order Butterworth at 8 Hz, filtered here with scipy) to < 1.5 N RMS per leg,
    against 13-98 N RMS of wind force: what is left is the load cells' noise and the
    friction. Unfiltered, the estimate is within 10 % RMS of the true force, and its error
    within the band is Q's own: |1 - Q(f)| of the force at 0.5-2 Hz (the heaviest-loaded leg)."""
    text = runner.resolve("telescope_slew_observer").read_text()
    shipped = f"{study.OBSERVER_BANDWIDTH:g} Hz"   # run at 8 Hz: Q's lag then dominates the load cells' noise
    text = text.replace(f'values = ["0 Hz", "{shipped}"]', 'values = ["8 Hz"]').replace(
        'stop_time = "60 s"', 'stop_time = "12 s"')
    text = re.sub(r"\n\[requirements\].*?(?=\n\[|\Z)", "", text, flags=re.S)   # they name the shipped run
    text = text.replace('interval = "10 ms"', 'interval = "1 ms"')
    text = re.sub(r"variables = \[.*\]",
                  'variables = ["plant.pose", "wind.platform_wrench", "controller.disturbance_estimate"]', text)
    path = tmp_path / "truth.toml"
    path.write_text(text)
    _, (run,), _ = runner.run_scenario(path, tmp_path / "out", progress=False, charts="none")
    r = run.records
    column = lambda name: np.array([r[f"{name}[{i}]"] for i in range(1, 7)]).T
    pose, wrench, estimate = column("plant.pose"), column("wind.platform_wrench"), column(
        "controller.disturbance_estimate")
    params = StewartParams.paper()
    truth = np.array([np.linalg.solve(dynamics_terms(params, q, np.zeros(6), twist_speeds=True).jacobian.T, w)
                      for q, w in zip(pose, wrench)])
    keep = r.time >= 2.0
    t, truth, estimate = r.time[keep] - 2.0, truth[keep], estimate[keep]
    w = 2 * np.pi * 8.0
    q = signal.lti([w * w], [1, np.sqrt(2) * w, w * w])
    through_q = np.array([signal.lsim(q, f - f[0], t)[1] + f[0] for f in truth.T]).T
    settled = t >= 2.0
    residual = (estimate - through_q)[settled].std(axis=0)
    assert np.all(residual < 1.5) and np.all(truth.std(axis=0) > 10)
    assert np.all((estimate - truth).std(axis=0) < 0.1 * truth.std(axis=0))   # unfiltered: within 10 %
    f, s_ff = signal.welch(truth[:, 2] - truth[:, 2].mean(), 1000.0, nperseg=4096)
    _, s_ee = signal.welch((estimate - truth)[:, 2], 1000.0, nperseg=4096)
    jw = 2j * np.pi * f
    lag = np.abs(1 - w * w / (jw * jw + np.sqrt(2) * w * jw + w * w))
    band = (f >= 0.5) & (f <= 2.0)
    assert np.sqrt(s_ee[band] / s_ff[band]) == pytest.approx(lag[band], rel=0.25)


@pytest.mark.parametrize("name", ["telescope_slew_observer", "keyhole_tracking_observer"])
def test_the_shipped_observer_holds_10_um_in_gusts_it_was_not_tuned_on(tmp_path, name):
    """The shipped scenes at their [ci] length (1.5 s from the operating point, counted from
    0.5 s) in gust seeds outside the study's (26-28; tuned on TUNING_SEEDS, tabled GUST_SEEDS) at
    turbulence intensity 0.3: the observer's peak pose error stays under 10 µm, and without
    the observer the same gusts give more than twice it (the check bites)."""
    peaks = {}
    for seed in (26, 27, 28):
        assert seed not in study.TUNING_SEEDS + study.GUST_SEEDS
        text = runner.resolve(name).read_text()
        text = text.replace("turbulence_intensity = 0.15, spectrum = \"kaimal\", seed = 1",
                            f"turbulence_intensity = 0.3, spectrum = \"kaimal\", seed = {seed}")
        text = re.sub(r'sweep = \{ parameter = "controller.observer_bandwidth", values = \["[0-9.]+ Hz"\] \}',
                      'sweep = { parameter = "controller.observer_bandwidth", values = ["0 Hz", '
                      f'"{study.OBSERVER_BANDWIDTH:g} Hz"] }}', text)
        assert f"seed = {seed}" in text and '"0 Hz", ' in text
        path = tmp_path / f"{name}-{seed}.toml"
        path.write_text(text)
        _, runs, _ = runner.run_scenario(path, tmp_path / "out", ci=True, progress=False, charts="none")
        peaks[seed] = {run.label: run.metrics["pose error"]["peak"] for run in runs}
    for seed, by in peaks.items():
        assert by[f"{study.OBSERVER_BANDWIDTH:g} Hz"] < study.GOAL, peaks
        assert by["0 Hz"] > 2 * by[f"{study.OBSERVER_BANDWIDTH:g} Hz"], peaks
