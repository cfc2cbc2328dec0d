"""The anemometer on the subreflector (plant/c/wind.c, mb_wind_anemometer) and the drag model
a wind feedforward shares with the Wind FMU (mb_wind_drag, mb_wind_feedforward): the
anemometer's coherence with the drag gust, estimated by scipy.signal.coherence over an
ensemble of seeds, against Davenport's gamma(f)^2; its lag's gain and phase against the
analytic first-order response; Taylor's lead of an upstream mast; its speed's drag against
the true wrench where the admittance is 1; the feedforward's leg forces against J^-T w in
numpy; and the Wind kernel's older outputs against arrays made before the anemometer, within
rounding (tests/golden/make_wind_golden.py, run on the tree before it)."""
import pathlib

import numpy as np
import pytest
from scipy import signal

from fmu_src.wind_fmu import DEFAULTS, anemometer_speeds, gust_model, gusts
from plant._kernel import ffi, lib
from plant.hexapod.model import StewartParams, jacobian
from plant.rotations import rpy_matrix
from tests.rounding_helpers import Nudged

U = DEFAULTS["mean_speed"]
GOLDEN = pathlib.Path(__file__).resolve().parent.parent / "golden" / "wind_kernel.npz"
FS, RECORD, SEEDS = 8.0, 64.0, 256   # Hz, s per seed, seeds: the ensemble (many short records: many phases per bin)
BANDS = np.array([0.06, 0.12, 0.25, 0.5, 1.0, 2.0])   # Hz


def settings(**over):
    return {**DEFAULTS, **over}


def ensemble(over, area=True):
    """(drag gust u_A or point gust u, anemometer gust u_a) of SEEDS seeds, one after the other."""
    t = np.arange(0.0, RECORD, 1 / FS)
    xs, ys = [], []
    for seed in range(SEEDS):
        m = gust_model(settings(**over), 0, seed)
        xs.append(gusts(m, t, area=area))
        ys.append(anemometer_speeds(m, t) - U)
    return np.concatenate(xs), np.concatenate(ys)


def band_means(f, values):
    return np.array([values[(f >= a) & (f < b)].mean() for a, b in zip(BANDS[:-1], BANDS[1:])])


def welch(fn, *xy):
    """Welch over the ensemble: one Hann segment per seed, so the averages are over seeds."""
    n = int(RECORD * FS)
    return fn(*xy, fs=FS, nperseg=n, noverlap=0)


@pytest.mark.parametrize("distance, decay", [(3.25, 8.0), (6.5, 10.0)])
def test_coherence_with_the_drag_gust_is_davenports(distance, decay):
    x, y = ensemble({"anemometer_distance": distance, "coherence_decay": decay, "anemometer_time_constant": 0.0})
    f, coh = welch(signal.coherence, x, y)
    gamma2 = np.exp(-decay * f * distance / U) ** 2
    measured, expected = band_means(f, coh), band_means(f, gamma2)
    assert np.abs(measured - expected).max() < 0.06, (measured, expected)
    assert expected[0] > 0.3 and expected[-1] < 0.01   # the bands span coherent to incoherent


def test_lag_is_the_first_order_response():
    tau = 0.25
    m = gust_model(settings(anemometer_distance=0.0, anemometer_time_constant=tau), 0, 1)
    t = np.arange(0.0, 600.0, 0.01)   # 100 Hz: no component (<= 50 Hz) aliases
    x, y = gusts(m, t), anemometer_speeds(m, t) - U
    f, sxy = signal.csd(x, y, fs=100.0, nperseg=4096)
    _, sxx = signal.welch(x, fs=100.0, nperseg=4096)
    h = band_means(f, sxy / sxx)   # the estimate H = S_xy / S_xx, x the gust at the disc's centre
    truth = band_means(f, 1 / (1 + 2j * np.pi * f * tau))   # gain 1 / sqrt(1 + (w tau)^2), phase -atan(w tau)
    assert np.allclose(np.abs(h), np.abs(truth), rtol=0.02), (np.abs(h), np.abs(truth))
    assert np.allclose(np.angle(h), np.angle(truth), atol=0.02), (np.angle(h), np.angle(truth))


def test_upstream_mast_leads_by_taylors_delay():
    upstream = 5.0
    x, y = ensemble({"anemometer_distance": 0.0, "anemometer_upstream": upstream, "anemometer_time_constant": 0.0},
                    area=False)
    f, sxy = welch(signal.csd, x, y)
    low = (f > 0.03) & (f < 0.3)   # coherence above ~0.4: the cross phase is well defined
    lead = np.unwrap(np.angle(sxy[low]))
    slope = np.polyfit(2 * np.pi * f[low], lead, 1)[0]   # s
    assert slope == pytest.approx(upstream / U, rel=0.05)


def test_anemometer_at_the_centre_without_lag_reads_the_point_gust():
    m = gust_model(settings(anemometer_distance=0.0, anemometer_time_constant=0.0), 0, 3)
    t = np.linspace(0.0, 600.0, 3001)
    # the phases differ by 2 pi (atan2's range): rounding of w t + phase at |w t| ~ 1e4 rad
    assert np.allclose(anemometer_speeds(m, t), U + gusts(m, t), rtol=0, atol=1e-10)


def drag_wrench(drag, arm, direction, speed, base_pose):
    """The quasi-steady drag wrench in {B}, written out in numpy."""
    force_w = -drag * speed * abs(speed) * np.array([np.sin(direction), np.cos(direction), 0.0])
    force_b = rpy_matrix(np.asarray(base_pose[3:])).T @ force_w
    return np.concatenate([force_b, np.cross([0.0, 0.0, arm], force_b)])


def test_predicted_drag_is_the_wind_wrench_where_the_admittance_is_one():
    """With a drag area of 1 cm2 the plate's admittance is 1 within 1e-3 up to 50 Hz: the drag
    of the speed an anemometer at the centre reads without lag is then the Wind's wrench.
    (With the 6.5 m disc it differs by the admittance: the point gust's drag has more
    high-frequency force than the disc feels, chi = 0.5 at 0.87 Hz.)"""
    s = settings(drag_area=1e-4, anemometer_distance=0.0, anemometer_time_constant=0.0, direction=0.7)
    m = gust_model(s, 0, 5)
    drag = 0.5 * s["air_density"] * s["drag_coefficient"] * s["drag_area"]
    base = np.array([0.0, 0.0, 0.0, 0.02, -0.5, 1.1])
    pose = ffi.new("double[6]", list(base))
    truth, got, gust = ffi.new("double[6]"), ffi.new("double[6]"), ffi.new("double *")
    for t in np.linspace(0.0, 100.0, 201):
        lib.mb_wind_wrench(m, t, pose, truth, gust)
        speed = anemometer_speeds(m, [t])[0]
        lib.mb_wind_drag(drag, s["moment_arm"], s["direction"], speed, pose, got)
        assert np.allclose(list(got), list(truth), rtol=2e-3, atol=1e-9 * abs(truth[0]) + 1e-12)
        assert np.allclose(list(got), drag_wrench(drag, s["moment_arm"], s["direction"], speed, base), rtol=1e-12)


def test_feedforward_forces_are_minus_j_inverse_transpose_w():
    params = StewartParams.paper()
    rng = np.random.default_rng(2)
    wrench, forces = ffi.new("double[6]"), ffi.new("double[6]")
    for _ in range(5):
        pose = params.home_pose + rng.normal(0.0, [0.01, 0.01, 0.01, 0.01, 0.01, 0.01])
        base = np.array([0.0, 0.0, 0.0, *rng.normal(0.0, 0.5, 3)])
        speed, gain, direction = rng.uniform(-5, 20), rng.uniform(0.5, 1.5), rng.uniform(-3, 3)
        det = lib.mb_wind_feedforward(*params.kernel.params, ffi.new("double[6]", list(pose)),
                                      ffi.new("double[6]", list(base)), 24.0, 1.3, direction, speed, gain,
                                      wrench, forces)
        w = drag_wrench(24.0, 1.3, direction, speed, base)
        J = jacobian(params, pose)
        assert np.allclose(list(wrench), w, rtol=1e-12)
        assert np.allclose(list(forces), -np.linalg.solve(J.T, gain * w), rtol=1e-9)
        assert J.T @ np.array(list(forces)) == pytest.approx(-gain * w, abs=1e-9 * np.abs(w).max())
        assert det == pytest.approx(np.linalg.det(J), rel=1e-9)


def _wrenches(m, times, pose):
    """mb_wind_wrench at each time: (status 0, the wrenches, their gusts)."""
    w, u = np.empty((times.size, 6)), np.empty((times.size, 1))
    pose = ffi.from_buffer("double[]", np.ascontiguousarray(pose))
    for i, t in enumerate(times):
        lib.mb_wind_wrench(m, t, pose, ffi.from_buffer("double[]", w[i]), ffi.from_buffer("double[]", u[i]))
    return 0, w, u[:, 0]


def test_older_outputs_are_those_before_the_anemometer():
    """The gust, area gust and wrench against the arrays written before the anemometer, on
    another machine: within what rounding explains (tests/rounding_helpers.py: sums of sines
    of arguments up to ~1e3 rad move by ulps of the argument), so a changed draw, spectrum or
    drag law fails while another libm passes. The FMUs' one-pass sample (the anemometer from the
    same angles) against mb_wind_wrench of this run: bit for bit."""
    g = np.load(GOLDEN)
    times, pose = g["times"], g["base_pose"]
    for spectrum in (0, 1):
        for seed in (0, 7):
            key = f"s{spectrum}_seed{seed}"
            m = gust_model(DEFAULTS, spectrum, seed)
            for name, call, args in (("gust", lambda t: (0, gusts(m, t)), (times,)),
                                     ("area", lambda t: (0, gusts(m, t, area=True)), (times,)),
                                     ("wrench", lambda t, p: _wrenches(m, t, p)[:2], (times, pose))):
                found, want = Nudged(call, *args), g[f"{key}_{name}"]
                np.testing.assert_allclose(found.outputs[0], want, rtol=0, err_msg=f"{key} {name}",
                                           atol=found.tolerance(0, 1e-13 * np.abs(want).max()))
            wrenches, pose_c = _wrenches(m, times, pose)[1], ffi.from_buffer("double[]", pose)
            w, speeds = np.empty(6), np.empty(3)
            for t, row, gust, area in zip(times, wrenches, gusts(m, times), gusts(m, times, area=True)):
                lib.mb_wind_sample(m, t, pose_c, ffi.from_buffer("double[]", w), ffi.from_buffer("double[]", speeds))
                assert np.array_equal(w, row) and speeds[0] == gust and speeds[2] == DEFAULTS["mean_speed"] + area
