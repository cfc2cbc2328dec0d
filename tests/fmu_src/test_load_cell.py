"""The load cell's kernel (plant/c/sensors.c mb_load_cell) against closed forms: its
first-order low-pass, its noise, its quantisation and its delay."""
import numpy as np
import pytest

from plant._kernel import ffi, lib


def _run(values, h=1e-3, resolution=0.0, noise=0.0, bandwidth=0.0, delay=0, seed=1):
    """Measured outputs (k, 6) of the samples of ``values`` (k, 6) after the first."""
    cell = ffi.new("mb_load_cell *")
    out = np.zeros(6)
    buf = lambda a: ffi.from_buffer("double[]", a)
    first = np.ascontiguousarray(values[0], dtype=float)
    lib.mb_load_cell_start(cell, seed, 6, resolution, noise, buf(first), buf(out))
    rows = []
    for v in values[1:]:
        v = np.ascontiguousarray(v, dtype=float)
        lib.mb_load_cell_sample(cell, 6, resolution, noise, bandwidth, delay, h, buf(v), buf(out))
        rows.append(out.copy())
    return np.array(rows)


def test_a_step_follows_the_first_order_low_pass():
    """From rest at 0, a held step F: sample k reads F (1 - exp(-2 pi f_c k h)), the low-pass
    matched at its pole; delay_steps reads it that many samples later."""
    n, f_c, h = 200, 50.0, 1e-3
    values = np.vstack([np.zeros(6), np.tile(np.arange(1.0, 7.0) * 1e3, (n, 1))])
    k = np.arange(1, n + 1)[:, None]
    expected = np.arange(1.0, 7.0) * 1e3 * (1 - np.exp(-2 * np.pi * f_c * k * h))
    assert _run(values, h, bandwidth=f_c) == pytest.approx(expected, rel=1e-12)
    late = _run(values, h, bandwidth=f_c, delay=2)
    assert np.array_equal(late[2:], _run(values, h, bandwidth=f_c)[:-2]) and np.all(late[:2] == 0)


def test_noise_rms_and_quantisation():
    """White noise of the given RMS (4000 samples: within 5 %); with a resolution every
    reading is a whole number of steps."""
    values = np.full((4001, 6), 5000.0)
    noisy = _run(values, noise=5.0)
    assert noisy.std() == pytest.approx(5.0, rel=0.05) and abs(noisy.mean() - 5000.0) < 0.5
    stepped = _run(values, noise=5.0, resolution=0.5)
    assert np.array_equal(stepped, np.round(stepped / 0.5) * 0.5)
    assert np.array_equal(_run(values, noise=5.0, seed=3), _run(values, noise=5.0, seed=3))
