"""The leg sensor (plant/c/sensors.h, LegSensor FMU) against independent truths: the
quantisation error of a signal sweeping many steps is uniform with variance q^2/12; the
noise has the RMS asked for and is Gaussian; the rate estimator's measured frequency
response is its design, the discrete transfer function a (1 - z^-1) / (h (1 - (1 - a)
z^-1)) z^-delay (python-control); same seed, same bytes; native == python bit for bit,
and a saved FMU state replays the same noise."""
import math

import control
import numpy as np
import pytest
from scipy import stats

from plant._kernel import ffi, lib
from plant.hexapod.model import StewartParams
from tests.fmu_helpers import open_fmu

H = 1e-3


def run_kernel(values, resolution=0.0, noise=0.0, cutoff=0.0, delay=0, seed=1, h=H):
    """(measured, rate) per sample of values (n, 6); sample 0 starts the sensor."""
    s = ffi.new("mb_sensor *")
    values = np.ascontiguousarray(values, dtype=float)
    measured, rate = np.empty_like(values), np.empty_like(values)
    P = lambda a: ffi.from_buffer("double[]", a)
    lib.mb_sensor_start(s, seed, 6, resolution, noise, P(values[0]), P(measured[0]), P(rate[0]))
    for k in range(1, len(values)):
        lib.mb_sensor_sample(s, 6, resolution, noise, cutoff, delay, h, P(values[k]), P(measured[k]), P(rate[k]))
    return measured, rate


def test_quantisation_error_is_uniform_with_variance_q2_over_12():
    q = 1e-7
    n = 20000
    ramp = 3.0 + q * 1234.5678 * np.linspace(0.0, 1.0, n)   # ~1235 steps, crossed at irregular phases
    values = ramp[:, None] + q * np.array([0.0, 0.13, 0.29, 0.41, 0.67, 0.83])
    measured, _ = run_kernel(values, resolution=q)
    error = (measured - values).ravel()
    assert np.abs(error).max() <= q / 2 * (1 + 1e-6)
    np.testing.assert_allclose(error.var(), q ** 2 / 12, rtol=0.02)
    assert abs(error.mean()) < 0.01 * q
    assert stats.kstest(error / q, stats.uniform(-0.5, 1.0).cdf).pvalue > 1e-3
    assert np.allclose(measured / q, np.round(measured / q), rtol=0, atol=1e-6)   # on the grid


def test_noise_has_its_rms_and_is_gaussian():
    sigma = 2e-7
    values = np.tile(np.linspace(3.0, 3.1, 6), (10001, 1))
    measured, _ = run_kernel(values, noise=sigma, seed=42)
    error = (measured - values).ravel()
    np.testing.assert_allclose(error.std(), sigma, rtol=0.02)
    assert abs(error.mean()) < 4 * sigma / math.sqrt(error.size)
    assert stats.kstest(error / sigma, "norm").pvalue > 1e-3
    lag1 = np.corrcoef(error[:-6], error[6:])[0, 1]   # white: sample k independent of k + 1
    assert abs(lag1) < 0.03


@pytest.mark.parametrize("cutoff, delay", [(0.0, 0), (50.0, 0), (50.0, 2), (200.0, 1)])
def test_rate_estimator_frequency_response_is_its_design(cutoff, delay):
    a = 1.0 - math.exp(-2 * math.pi * cutoff * H) if cutoff > 0 else 1.0
    design = control.tf([a, -a], [H, -(1 - a) * H], H) * control.tf([1], [1] + [0] * delay, H)
    for f in (1.0, 10.0, 40.0, 150.0):
        w = 2 * math.pi * f
        n = int(round(20 / f / H)) + 400
        t = H * np.arange(n)
        amplitude = 1e-4
        values = 3.0 + amplitude * np.sin(w * t)[:, None] * np.ones(6)
        _, rate = run_kernel(values, cutoff=cutoff, delay=delay)
        tail = slice(n // 2, n)
        basis = np.c_[np.sin(w * t[tail]), np.cos(w * t[tail])]
        (s, c), *_ = np.linalg.lstsq(basis, rate[tail, 0], rcond=None)
        measured = complex(s, c) / amplitude
        expected = complex(design(np.exp(1j * w * H)))
        assert abs(measured - expected) < 1e-6 * abs(expected) + 1e-9, (f, measured, expected)
        if f <= 10.0:   # the design: a differentiator rolled off at the cutoff, near jw / (1 + jw/wc)
            ideal = 1j * w / (1 + 1j * f / cutoff) if cutoff else 1j * w
            assert abs(abs(measured) / abs(ideal) - 1) < 0.03


def test_delay_shifts_the_outputs_by_whole_samples():
    values = 3.0 + 1e-5 * np.sin(np.arange(300) * 0.07)[:, None] * np.arange(1, 7)
    m0, r0 = run_kernel(values, resolution=1e-8, noise=1e-8, cutoff=80.0, delay=0, seed=5)
    m2, r2 = run_kernel(values, resolution=1e-8, noise=1e-8, cutoff=80.0, delay=2, seed=5)
    assert m2[3:].tobytes() == m0[1:-2].tobytes() and r2[3:].tobytes() == r0[1:-2].tobytes()
    np.testing.assert_array_equal(m2[1], m0[0])   # before the line fills: the first sample


def test_same_seed_same_bytes_other_seed_other_noise():
    values = np.full((200, 6), 3.05)
    a = run_kernel(values, noise=1e-7, seed=9)
    b = run_kernel(values, noise=1e-7, seed=9)
    c = run_kernel(values, noise=1e-7, seed=10)
    assert a[0].tobytes() == b[0].tobytes() and a[1].tobytes() == b[1].tobytes()
    assert np.abs(a[0] - c[0]).max() > 0


SETTINGS = dict(resolution=1e-7, noise=5e-8, rate_cutoff=120.0, delay_steps=1, seed=11)


def _fmu_run(path, steps=80, save_at=40):
    sensor = open_fmu(path, **SETTINGS)
    rows, saved = [], None
    for k in range(steps):
        for i in range(6):
            sensor.set(f"leg_length[{i + 1}]", 3.1 + 1e-5 * math.sin(0.05 * k + i))
        sensor.do_step(k * H, H)
        rows.append([sensor.get_real(f"{v}[{i + 1}]") for v in ("measured_length", "estimated_rate")
                     for i in range(6)])
        if k == save_at - 1:
            saved = sensor.fmu.getFMUState()
    sensor.fmu.setFMUState(saved)
    replay = []
    for k in range(save_at, steps):
        for i in range(6):
            sensor.set(f"leg_length[{i + 1}]", 3.1 + 1e-5 * math.sin(0.05 * k + i))
        sensor.do_step(k * H, H)
        replay.append([sensor.get_real(f"{v}[{i + 1}]") for v in ("measured_length", "estimated_rate")
                       for i in range(6)])
    sensor.fmu.freeFMUState(saved)
    return np.array(rows), np.array(replay)


def test_native_sensor_equals_python_bit_for_bit_and_replays(fmus, native_fmus):
    native = native_fmus["leg_sensor_fmu"]
    python_rows, python_replay = _fmu_run(fmus["leg_sensor_fmu"])
    native_rows, native_replay = _fmu_run(native)
    assert python_rows.tobytes() == native_rows.tobytes()
    assert python_replay.tobytes() == python_rows[40:].tobytes()
    assert native_replay.tobytes() == native_rows[40:].tobytes()
    # the FMU is the kernel: sample 0 at initialization (the start lengths), then one per step
    values = 3.1 + 1e-5 * np.sin(0.05 * np.arange(80)[:, None] + np.arange(6))
    measured, rate = run_kernel(np.r_[StewartParams.paper().home_lengths[None], values], SETTINGS["resolution"],
                                SETTINGS["noise"], SETTINGS["rate_cutoff"], SETTINGS["delay_steps"],
                                SETTINGS["seed"])
    assert python_rows.tobytes() == np.c_[measured[1:], rate[1:]].tobytes()
