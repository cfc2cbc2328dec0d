"""BaseSensor (plant/c/base_sensor.c through fmu_src/base_sensor_fmu.py and the native
FMU): encoder quantisation error statistics (uniform, variance q^2/12), the differentiating
filter's frequency response against its design (python-control), the IMU's noise density
(Welch) and bias, the base-motion formula of the telescope kernel, same seed -> identical
bytes, native == python bit for bit."""
import control
import numpy as np
import pytest
from scipy import signal, stats

from fmu_src import base_sensor_fmu
from plant.telescope import model as telescope
from tests.fmu_helpers import opened, outputs, reals, step

H = 1e-3


def _sensor(source=0, seed=1, truth=None, **settings):
    slave = base_sensor_fmu.BaseSensor(instance_name="sensor")
    slave.source, slave.seed = source, seed
    slave.settings.update(settings)
    if truth is not None:
        slave.truth[:] = truth(0.0)
    slave.initialize()
    return slave


def _run(slave, truth, n, h=H):
    """Outputs (n + 1, 18) with the inputs set to truth(t) before each step's end."""
    rows = [slave.now.copy()]
    for k in range(n):
        slave.truth[:] = truth((k + 1) * h)
        slave.step(k * h, h)
        rows.append(slave.now.copy())
    return np.array(rows)


def _axes_truth(az, el, az_rate=lambda t: 0.0, el_rate=lambda t: 0.0):
    """Inputs with only the axis angles (and rates) moving."""
    def truth(t):
        row = np.zeros(22)
        row[:4] = az(t), el(t), az_rate(t), el_rate(t)
        return row
    return truth


def test_encoder_quantisation_error_is_uniform_with_variance_q2_over_12():
    q = 0.1 * np.pi / 648000                                    # 0.1 arcsec
    n = 20000
    az = lambda t: 0.3 + 123.4567 * q * t / H * np.sqrt(2) / 7  # sweeps ~7000 quanta
    rows = _run(_sensor(truth=_axes_truth(az, lambda t: 0.6), encoder_resolution=q), _axes_truth(az, lambda t: 0.6), n)
    t = H * np.arange(n + 1)
    error = (np.pi - rows[:, 5]) - np.array([az(x) for x in t])  # yaw = A = 180 deg - Az
    assert np.abs(error).max() <= q / 2 * (1 + 1e-6)
    assert error.var() == pytest.approx(q ** 2 / 12, rel=0.03)
    assert abs(error.mean()) < 0.02 * q
    assert stats.kstest(error / q, stats.uniform(loc=-0.5, scale=1).cdf).pvalue > 1e-3


@pytest.mark.parametrize("cutoff", [0.0, 5.0])
@pytest.mark.parametrize("frequency", [0.5, 5.0, 50.0])
def test_differentiating_filter_frequency_response_is_its_design(cutoff, frequency):
    """Az = a sin(2 pi f t), no quantisation: the rate and acceleration estimates of A
    against H(z) and H(z)^2, H(z) = (1 - z^-1)/h a/(1 - (1 - a) z^-1), by python-control."""
    amplitude, omega = 1e-3, 2 * np.pi * frequency
    az = lambda t: 0.2 + amplitude * np.sin(omega * t)
    truth = _axes_truth(az, lambda t: 0.7, lambda t: amplitude * omega * np.cos(omega * t))
    n = 12000
    rows = _run(_sensor(truth=truth, encoder_resolution=0.0, rate_cutoff=cutoff), truth, n)
    t = H * np.arange(n + 1)
    keep = t >= 2.0                                              # the filter's start transient has decayed
    basis = np.column_stack([np.sin(omega * t[keep]), np.cos(omega * t[keep])])
    alpha = 1 - np.exp(-2 * np.pi * cutoff * H) if cutoff > 0 else 1.0
    design = control.tf([alpha / H, -alpha / H], [1, -(1 - alpha)], H)
    for column, system in ((11, design), (17, design * design)):   # yaw rate = A', yaw acc = A''
        (s, c), *_ = np.linalg.lstsq(basis, rows[keep, column], rcond=None)
        measured = (s + 1j * c) / -amplitude                     # A = 180 deg - Az: input phasor -a
        expected = complex(np.asarray(control.frequency_response(system, [omega]).complex).ravel()[0])
        assert abs(measured - expected) < 1e-7 * abs(expected)


def test_encoder_estimate_is_the_kernels_base_motion():
    """A constant-acceleration slew, plain differences: the backward differences of
    A = A0 + alpha t^2 / 2 are exact (alpha (t - h/2), alpha), so the estimate is
    mb_tel_base_motion of those axes with the sensor's lever arm."""
    alpha, beta = 2e-3, -1e-3
    az = lambda t: 1.0 - alpha * t * t / 2                      # A = 180 deg - Az accelerates at +alpha
    el = lambda t: 0.5 + beta * t * t / 2
    truth = _axes_truth(az, el, lambda t: -alpha * t, lambda t: beta * t)
    rows = _run(_sensor(truth=truth, encoder_resolution=0.0, rate_cutoff=0.0, lever_arm=17.0), truth, 300)
    t = H * np.arange(301)[2:]
    axes = telescope.AxisMotion(t, np.pi - az(t), alpha * (t - H / 2), np.full_like(t, alpha),
                                el(t), beta * (t - H / 2), np.full_like(t, beta))
    params = telescope.TelescopeParams.tianma().__class__(**{**telescope.TelescopeParams.tianma().__dict__,
                                                             "lever_arm": 17.0})
    expected = np.hstack(telescope.base_motion(params, axes))
    # the differences carry the angles' rounding: eps |A| / h (rates), 4 eps |A| / h^2 (accelerations), times L
    eps = np.finfo(float).eps * np.pi
    np.testing.assert_allclose(rows[2:, :12], expected[:, :12], rtol=0, atol=2 * 17.0 * eps / H)
    np.testing.assert_allclose(rows[2:, 12:], expected[:, 12:], rtol=0, atol=8 * 17.0 * eps / H ** 2)


def _imu_truth(t):
    row = np.zeros(22)
    row[:2] = np.pi, np.pi / 2    # at the zenith, yaw 0: {B} = {W}
    return row


@pytest.mark.parametrize("density, bias", [(np.radians(0.01) / 60, 0.0), (1e-4, 2e-5)])
def test_imu_gyro_and_accelerometer_noise_density_by_welch(density, bias):
    n = 2 ** 16
    slave = _sensor(1, seed=7, truth=_imu_truth, gyro_noise_density=density, gyro_bias=bias,
                    accel_noise_density=3 * density, accel_bias=-bias)
    rows = _run(slave, _imu_truth, n)[1:]
    for column, level, offset in ((9, density, bias), (12, 3 * density, -bias), (14, 3 * density, -bias)):
        x = rows[:, column]                                      # roll rate = w_x; x, z acceleration
        f, psd = signal.welch(x - x.mean(), fs=1 / H, nperseg=1024, return_onesided=False)
        assert np.sqrt(psd.mean()) == pytest.approx(level, rel=0.02)   # two-sided density
        assert x.mean() == pytest.approx(offset, abs=5 * level / np.sqrt(n * H))


def test_same_seed_identical_bytes_other_seed_differs():
    def run(seed):
        return _run(_sensor(1, seed=seed, truth=_imu_truth), _imu_truth, 500).tobytes()
    assert run(3) == run(3)
    assert run(3) != run(4)


@pytest.fixture(scope="module")
def native_base_sensor(native_fmus):
    return native_fmus["base_sensor_fmu"]


@pytest.mark.parametrize("source", [0, 1])
def test_native_equals_python_bit_for_bit(fmus, native_base_sensor, source):
    base = telescope.TelescopeParams.tianma()
    t = 1e-3 * np.arange(1, 2001)
    command = telescope.slew(base, (0.0, np.radians(30)), (np.radians(20), np.radians(45)), t)
    pose, rate, acc = telescope.base_motion(base, command)
    runs = []
    for path in (fmus["base_sensor_fmu"], native_base_sensor):
        inst, status = opened(path, source=source, seed=11)
        assert status == 0, inst.log
        names = outputs(inst.md)
        rows = []
        for k in range(t.size):
            values = np.r_[command.azimuth[k], command.E[k], -command.A_dot[k], command.E_dot[k], pose[k], rate[k],
                           acc[k]]
            for name, v in zip([f"axis[{i}]" for i in (1, 2)] + [f"axis_rate[{i}]" for i in (1, 2)]
                               + [f"true_base_{q}[{i}]" for q in ("pose", "rate", "acc") for i in range(1, 7)],
                               values):
                inst.set(name, float(v))
            assert step(inst, k * 1e-3, 1e-3) == 0
            rows.append(reals(inst, names))
        runs.append(np.array(rows))
    np.testing.assert_array_equal(runs[0], runs[1])
    assert np.abs(runs[0]).max() > 0


def test_non_finite_input_discards_with_the_same_words(fmus, native_base_sensor):
    from tests.fmu_helpers import _stepping_failure
    text = _stepping_failure(fmus, {"base_sensor_fmu": native_base_sensor}, "base_sensor_fmu", {},
                             {"true_base_rate[2]": np.nan, "axis[1]": np.inf})
    assert text == "InvalidInputError at t=0 s: inputs must be finite: axis, true_base_rate"
