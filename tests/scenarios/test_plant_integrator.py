"""The realistic plant's integrator on every shipped realistic scene (a plant with screw
friction or a force loop), against a reference 10x finer than the fixed substeps those
scenes took before issue 41 (RK4 at 0.01 ms, 100x finer than the 1 ms the error control
may take; it is converged: 0.005 ms agrees with it to 1e-8 µm on every pose metric).

Each scene runs its [ci] version once (its last sweep value: the design the scene
ships), as shipped (error-controlled substeps, tolerance 0.1 nm) and with the reference's
plant. The pose metrics (position and rotation, RMS and peak) and the leg
error agree within 1 % (or 1 nm, 1 nrad): issue 41's equal accuracy. The error each
scene shows is pinned: the largest relative difference, measured, times 2 (the observer
scenes' loops amplify a last-bit change of the libm a machine brings: x2 keeps rounding
from failing the test, and a slip in the integrator, e.g. the lag's rate without its 2 pi,
moves these by far more).

The observer slew's metrics also move by 0.2-1.5 % when a converged plant's start pose is
nudged by 0.05-3 nm: the leg sensor's 0.1 µm and the load cell's 0.5 N steps turn any error
above ~10 pm into other steps, and the loop into another draw of its quantization noise
(docs/speed.md, fourth pass). So that scene's integrator error is pinned a second time with
both quantizations off, where it is the integrator's own and moves smoothly with it."""
import pathlib

import pytest

from scenarios.runs import metrics, runner, single

REALISTIC = sorted(p.stem for p in runner.SHIPPED.glob("*.toml")
                   if "coulomb_friction" in p.read_text() or "actuator_bandwidth" in p.read_text())
# the largest relative error of the compared metrics, measured on the [ci] runs, x2
# (1.73e-3, 8.64e-4, 2.75e-3, 1.26e-4, 1.62e-3, 1.60e-4 on 2026-12-05, operating-point starts;
# the four observer scenes with the 32 Hz leg-space observer: 2.89e-3, 1.30e-4, 6.10e-3, 2.25e-4;
# the observer slew at 0.1 nm, not 0.03 nm: 4.52e-3, pinned 9.0e-3, 1.2e-2 before)
PINNED = {"keyhole_tracking_observer": 5.8e-3, "telescope_slew_gust_front": 2.6e-4,
          "telescope_slew_observer": 9.0e-3, "telescope_slew_observer_switch_on": 4.5e-4,
          "telescope_slew_realistic": 3.2e-3, "telescope_slew_wind_feedforward": 3.2e-4}
# the observer slew with the sensors' quantization off: 4.05e-3 on 2026-12-05 (at 0.03 nm 2.52e-3, fixed
# RK4 at 0.5 ms 1.3e-4), held to half the 1 %: without the quantization the loop moves smoothly with a
# change of rounding (a 1 nm nudge of the start pose moves it by 2.6e-4), so the gap is not rounding's
UNQUANTIZED = 5e-3
QUANTIZATION_OFF = {"leg_sensor": {"resolution": 0.0}, "load_cell": {"resolution": 0.0}}
COMPARED = {"pose error": ("rms", "peak", "rotation_rms", "rotation_peak"), "leg error": ("rms", "peak")}
REFERENCE = {"tolerance": 0.0, "max_step": 1e-5}


def _metrics(name, tmp_path, plant_values=None, others=None):
    scenario, paths, descriptions, values = runner.prepare(runner.resolve(name), ci=True)
    label, params = list(runner.sweep_runs(scenario, descriptions, values))[-1]
    plant = next(inst for inst, fmu in scenario.fmus.items() if fmu == "hexapod_plant")
    shipped = dict(params[plant])
    params[plant].update(plant_values or {})
    for inst, values_ in (others or {}).items():
        params[inst].update(values_)
    out = pathlib.Path(tmp_path) / ("reference" if plant_values else "shipped")
    out.mkdir(parents=True)
    run = single.run(scenario, paths, params, out, label, [metrics.make(m) for m in scenario.metrics])
    return run.metrics, shipped


def test_every_realistic_scene_is_pinned():
    assert REALISTIC == sorted(PINNED)


def _worst(shipped_metrics, reference):
    """The largest relative difference of the compared metrics; each within 1 % (or 1 nm)."""
    worst = 0.0
    for metric, keys in COMPARED.items():
        for key in keys:
            got, truth = shipped_metrics[metric][key], reference[metric][key]   # µm or µrad
            assert abs(got - truth) <= max(0.01 * abs(truth), 1e-3), (metric, key, got, truth)
            worst = max(worst, abs(got - truth) / abs(truth))
    return worst


@pytest.mark.parametrize("name", REALISTIC)
def test_the_plant_integrator_error_against_a_finer_reference(name, tmp_path):
    shipped_metrics, shipped = _metrics(name, tmp_path)
    assert shipped["tolerance"] == pytest.approx(1e-10)
    assert shipped["max_step"] == pytest.approx(1e-3)
    reference, _ = _metrics(name, tmp_path, REFERENCE)
    worst = _worst(shipped_metrics, reference)
    print(f"{name}: largest relative error {worst:.3g}")
    assert worst <= PINNED[name]
    assert worst > PINNED[name] / 100   # the comparison sees the integrator at all


def test_the_observer_slews_integrator_error_with_the_sensors_quantization_off(tmp_path):
    """The observer slew's own integrator error, without the quantization that makes its
    metrics a draw: within 1 % with a 2x margin (and pinned)."""
    shipped_metrics, _ = _metrics("telescope_slew_observer", tmp_path / "off", others=QUANTIZATION_OFF)
    reference, _ = _metrics("telescope_slew_observer", tmp_path / "off", REFERENCE, QUANTIZATION_OFF)
    worst = _worst(shipped_metrics, reference)
    print(f"telescope_slew_observer, quantization off: largest relative error {worst:.3g}")
    assert worst <= UNQUANTIZED
    assert worst > UNQUANTIZED / 100
