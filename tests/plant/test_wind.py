"""The wind on the subreflector (plant/c/wind.c, fmu_src/wind_fmu.py, its native twin):
the gust's spectrum against the Kaimal and Davenport formulas by Welch, the area-averaged
gust's against them times the plate's admittance, the mean drag against
0.5 rho Cd A (U^2 + sigma_A^2), the wrench's direction and moment against an
independent rotation, and determinism: same seed, same bytes; native equal to python."""
import numpy as np
import pytest
from fmpy import simulate_fmu
from scipy import integrate, signal

from fmu_src.wind_fmu import DEFAULTS, gust_model, gusts
from plant._kernel import ffi, lib
from plant.rotations import rpy_matrix

U, TI = DEFAULTS["mean_speed"], DEFAULTS["turbulence_intensity"]
BAND = (1 / 600, 50.0)   # Hz, the band the generator covers (plant/c/wind.h)


def variance_below(spectrum, f, length):
    """The integral over (0, f) of the target one-sided spectrum, written from its formula:
    Kaimal S = s2 (4 L/U) / (1 + 6 f L/U)^(5/3); Davenport S = s2 (2/3)(L/U) n / (1 + n^2)^(4/3)."""
    s2, n = (TI * U) ** 2, f * length / U
    return s2 * (1 - (1 + 6 * n) ** (-2 / 3)) if spectrum == "kaimal" else s2 * (1 - (1 + n * n) ** (-1 / 3))


def spectrum_density(spectrum, f, length):
    """The target one-sided spectrum S(f) (the derivative of variance_below)."""
    s2, n = (TI * U) ** 2, f * length / U
    if spectrum == "kaimal":
        return s2 * 4 * length / U / (1 + 6 * n) ** (5 / 3)
    return s2 * 2 / 3 * length / U * n / (1 + n * n) ** (4 / 3)


def admittance(f):
    """Vickery's aerodynamic admittance of a plate of area A, squared: 1 / (1 + (2 f sqrt(A) / U)^(4/3))^2."""
    return 1 / (1 + (2 * f * np.sqrt(DEFAULTS["drag_area"]) / U) ** (4 / 3)) ** 2


def band_power(x, fs, edges):
    f, psd = signal.welch(x, fs=fs, nperseg=2 ** 16)
    return np.array([psd[(f >= a) & (f < b)].sum() * (f[1] - f[0]) for a, b in zip(edges[:-1], edges[1:])])


@pytest.fixture(scope="module")
def native_wind(native_fmus):
    return native_fmus["wind_fmu"]


@pytest.mark.parametrize("spectrum, index, length", [("kaimal", 0, 8.1 * 0.7 * 60.0), ("davenport", 1, 1200.0)])
def test_gust_spectrum_is_the_target_by_welch(spectrum, index, length):
    """Welch's estimate of a 4000 s record at 100 Hz, integrated over octave bands from
    0.02 to 41 Hz: each band holds the target's variance within 15 % (the random frequency
    inside each of the generator's bins moves power across a band edge), all of them
    within 5 % (the lowest bands hold most of it, so their edges still count); the standard length scales are the
    ones the kernel chose."""
    model = gust_model(DEFAULTS, index, seed=11)
    assert model.scale == pytest.approx(length, rel=1e-12)
    fs = 100.0
    edges = 0.02 * 2.0 ** np.arange(12)
    measured = band_power(gusts(model, np.arange(0.0, 4000.0, 1 / fs)), fs, edges)
    target = np.diff(variance_below(spectrum, edges, length))
    assert np.all(np.abs(measured / target - 1) < 0.15), measured / target
    assert measured.sum() / target.sum() == pytest.approx(1, abs=0.05)
    full = variance_below(spectrum, np.array(BAND), length)
    assert model.band_variance == pytest.approx(full[1] - full[0], rel=1e-12)
    assert model.band_variance > 0.75 * (TI * U) ** 2   # the band holds most of sigma_u^2


def test_area_gust_spectrum_is_the_target_times_the_admittance():
    """The gust the drag sees (u_A, averaged over the 33 m2 plate): Welch's band powers
    against the integral of chi^2 S over each octave (numerical quadrature of the
    formulas), within 15 % each; above 1 Hz it carries under half the point gust's power."""
    length = 8.1 * 0.7 * 60.0
    model = gust_model(DEFAULTS, 0, seed=11)
    fs, edges = 100.0, 0.02 * 2.0 ** np.arange(12)
    t = np.arange(0.0, 4000.0, 1 / fs)
    measured = band_power(gusts(model, t, area=True), fs, edges)
    target = np.array([integrate.quad(lambda f: admittance(f) * spectrum_density("kaimal", f, length), a, b)[0]
                       for a, b in zip(edges[:-1], edges[1:])])
    assert np.all(np.abs(measured / target - 1) < 0.15), measured / target
    point = band_power(gusts(model, t), fs, edges)
    assert np.all(measured[edges[:-1] >= 1.0] < 0.5 * point[edges[:-1] >= 1.0])


def test_mean_drag_is_half_rho_cd_a_times_mean_square_speed():
    """Over 20 seeds of a 1 h record, the mean along-wind force is 0.5 rho Cd A (U^2 +
    sigma_A^2) (sigma_A^2 the variance of the area-averaged gust: the integral of chi^2 S
    over the generator's band, by quadrature) within four standard errors of the
    seed-to-seed spread; the sigma_A^2 term (1.7 % here) is many standard errors away, so
    the test sees it."""
    q = 0.5 * DEFAULTS["air_density"] * DEFAULTS["drag_coefficient"] * DEFAULTS["drag_area"]
    length = 8.1 * 0.7 * 60.0
    sigma2 = sum(integrate.quad(lambda f: admittance(f) * spectrum_density("kaimal", f, length), a, b)[0]
                 for a, b in zip(np.geomspace(*BAND, 9)[:-1], np.geomspace(*BAND, 9)[1:]))
    pose, wrench, gust = ffi.new("double[6]"), ffi.new("double[6]"), ffi.new("double *")
    means = []
    for seed in range(20):
        model = gust_model(DEFAULTS, 0, seed)
        forces = []
        for t in np.arange(0.0, 3600.0, 0.37):
            assert lib.mb_wind_wrench(model, t, pose, wrench, gust) == 0
            forces.append(-wrench[1])   # the wind from the north (direction 0) pushes towards -y = south
        means.append(np.mean(forces))
    mean, error = np.mean(means), np.std(means, ddof=1) / np.sqrt(len(means))
    expected = q * (U ** 2 + sigma2)
    assert abs(mean - expected) < 4 * error
    assert abs(mean - q * U ** 2) > 10 * error


def test_wrench_direction_rotation_and_moment():
    """The force along the wind (coming from azimuth `direction`, {W} = east, north, up),
    turned into {B} by R_WB^T (plant.rotations, independent of the kernel's rotation),
    its size the drag of the area-averaged gust; the moment (0, 0, arm) x F."""
    settings = dict(DEFAULTS, direction=np.radians(250.0), moment_arm=-2.5)
    model = gust_model(settings, 0, seed=4)
    base = np.array([3.0, -1.0, 20.0, 0.4, -0.7, 2.1])
    pose, wrench, gust = ffi.new("double[6]", list(base)), ffi.new("double[6]"), ffi.new("double *")
    assert lib.mb_wind_wrench(model, 12.3, pose, wrench, gust) == 0
    speed = U + gusts(model, [12.3], area=True)[0]
    size = 0.5 * DEFAULTS["air_density"] * DEFAULTS["drag_coefficient"] * DEFAULTS["drag_area"] * speed ** 2
    heading = -np.array([np.sin(settings["direction"]), np.cos(settings["direction"]), 0.0])
    force = rpy_matrix(base[3:]).T @ (size * heading)
    got = np.array(list(wrench))
    np.testing.assert_allclose(got[:3], force, rtol=1e-13, atol=1e-10)
    np.testing.assert_allclose(got[3:], np.cross([0.0, 0.0, -2.5], force), rtol=1e-13, atol=1e-10)
    assert gust[0] == gusts(model, [12.3])[0]


def test_calm_air_gives_no_wrench():
    model = gust_model(dict(DEFAULTS, mean_speed=0.0), 0, seed=1)
    assert model.band_variance == 0 and np.all(gusts(model, np.linspace(0, 100, 50)) == 0)


def _stepped_against_direct(model, start, h, n):
    """Sample n steps of h from start with mb_wind_sample_stepped (the FMUs' times: start + k h
    + h) and with mb_wind_sample: the largest |difference| of (u, U + u_a, U + u_A), and the
    samples evaluated exactly (anchors, z.steps 0), each checked equal to the direct sum bit for bit."""
    z = ffi.new("mb_wind_phasors *")
    lib.mb_wind_phasors_reset(z)
    pose = ffi.new("double[6]")
    w1, w2, s1, s2 = ffi.new("double[6]"), ffi.new("double[6]"), ffi.new("double[3]"), ffi.new("double[3]")
    worst, exact = np.zeros(3), []
    for k in range(n):
        t = start + k * h + h
        assert lib.mb_wind_sample_stepped(model, z, t, h if k else 0.0, pose, w1, s1) == 0
        assert lib.mb_wind_sample(model, t, pose, w2, s2) == 0
        worst = np.maximum(worst, [abs(s1[i] - s2[i]) for i in range(3)])
        if z.steps == 0:
            assert list(s1) == list(s2) and list(w1) == list(w2)
            exact.append(k)
    return worst, exact


@pytest.mark.parametrize("start", [0.0, 36000.0])   # a run's start, and 10 h on: the coarsest times of a night
def test_stepped_phasors_stay_within_their_bound_of_the_direct_sum(start):
    """The FMUs' stepped gust (phasors turned per step, plant/c/wind.h Stepping) against the
    direct sum of cosines at every sample of 60 s at 1 ms (58 anchors): within the bound the
    header states, 1e-12 of the sum of the amplitudes, plus the rounding of the direct sum's
    own angles (an ulp of omega_k t + phi_k each: 7e-14 of the sum at 1 min, 4e-11 at 10 h;
    measured 6e-14 and 6e-12); evaluated exactly at the first two samples (no step known
    yet) and every MB_WIND_ANCHOR_STEPS (1024) samples on, bit for bit the direct sum there."""
    model = gust_model(dict(DEFAULTS, turbulence_intensity=0.3), 0, seed=3)
    a, omega, phase = (np.array(list(getattr(model, n))) for n in ("amplitude", "omega", "phase"))
    bound = 1e-12 * a.sum() + (a * np.spacing(omega * (start + 60.0) + phase)).sum()   # m/s
    worst, exact = _stepped_against_direct(model, start, 1e-3, 60_000)
    assert np.all(worst <= bound), worst / a.sum()
    assert worst[0] > 1e-17 * a.sum()   # the turns were taken (a direct sum throughout differs by 0)
    assert exact == [0] + list(range(1, 60_000, 1024))   # the first (h 0), the first step, every 1024


def test_stepped_phasors_anchor_at_a_new_step_and_when_time_jumps():
    """A new step h (1 ms, then 2 ms, then 1 ms) or a t not one h on from the last sample
    evaluates the phasors exactly: those samples equal the direct sum bit for bit, and the
    next one turns by the new step."""
    model = gust_model(DEFAULTS, 1, seed=8)
    z = ffi.new("mb_wind_phasors *")
    lib.mb_wind_phasors_reset(z)
    pose, w1, w2 = ffi.new("double[6]"), ffi.new("double[6]"), ffi.new("double[6]")
    s1, s2 = ffi.new("double[3]"), ffi.new("double[3]")
    anchors = []
    samples = [(0.0, 0.0), (0.001, 1e-3), (0.002, 1e-3), (0.004, 2e-3), (0.006, 2e-3), (0.003, 2e-3),
               (0.005, 2e-3), (0.006, 1e-3), (0.007, 1e-3)]
    for t, h in samples:
        lib.mb_wind_sample_stepped(model, z, t, h, pose, w1, s1)
        lib.mb_wind_sample(model, t, pose, w2, s2)
        np.testing.assert_allclose(list(s1), list(s2), rtol=0, atol=1e-13)
        anchors.append(z.steps == 0)
        if z.steps == 0:
            assert list(s1) == list(s2)
    # 0: first; 1 ms: first step; 4 ms (2 ms): new step; 3 ms: back in time; 6 ms (1 ms): new step
    assert anchors == [True, True, False, True, False, True, False, True, False]
    assert z.step == 1e-3 and z.steps == 1


def test_a_nonfinite_base_pose_leaves_the_phasors_as_they_were():
    model = gust_model(DEFAULTS, 0, seed=2)
    z = ffi.new("mb_wind_phasors *")
    lib.mb_wind_phasors_reset(z)
    pose, wrench, speeds = ffi.new("double[6]"), ffi.new("double[6]"), ffi.new("double[3]")
    for t in (0.0, 0.001, 0.002):
        lib.mb_wind_sample_stepped(model, z, t, 1e-3 if t else 0.0, pose, wrench, speeds)
    before = bytes(ffi.buffer(z))
    pose[3] = float("nan")
    assert lib.mb_wind_sample_stepped(model, z, 0.003, 1e-3, pose, wrench, speeds) == lib.MB_WIND_NONFINITE
    assert bytes(ffi.buffer(z)) == before


def _run(path, seed, **extra):
    values = {"seed": seed, "base_pose[4]": 0.3, "base_pose[6]": 1.0, **extra}
    return simulate_fmu(str(path), stop_time=3.0, step_size=1e-3, output_interval=1e-3, start_values=values)


def test_same_seed_same_bytes_other_seed_other_gust(fmus):
    a, b, c = (_run(fmus["wind_fmu"], seed) for seed in (5, 5, 6))
    assert a.tobytes() == b.tobytes()
    assert not np.array_equal(a["gust"], c["gust"])
    assert np.std(a["gust"]) > 0.1   # the record moves (a few s of a 1.4 m/s RMS gust)


@pytest.mark.parametrize("spectrum", [0, 1])
def test_native_equals_python_bit_for_bit(fmus, native_wind, spectrum):
    python, compiled = (_run(p, 9, spectrum=spectrum, mean_speed=14.0) for p in (fmus["wind_fmu"], native_wind))
    assert python.dtype.names == compiled.dtype.names
    assert python.tobytes() == compiled.tobytes()


def test_nan_base_pose_discards_in_both(fmus, native_wind):
    """A NaN base pose mid-run: fmi2Discard, and the same log line from both."""
    from tests.fmu_helpers import DISCARD, failure_lines, opened, step
    lines = []
    for path in (fmus["wind_fmu"], native_wind):
        inst, status = opened(path)
        assert status == 0
        inst.set("base_pose[5]", float("nan"))
        assert step(inst, 0.0, 1e-3) == DISCARD
        lines.append(failure_lines(inst)[-1])
    assert lines[0] == lines[1] == "[DISCARD] InvalidInputError at t=0 s: base pose input contains NaN or inf"


def test_a_gust_that_turns_the_air_around_pushes_the_other_way():
    """At turbulence intensity 1 (the FMU's upper bound) the area-averaged air speed U + u
    turns negative for a sizeable share of the time; the drag then takes the sign of the
    air speed: 0.5 rho Cd A (U + u)|U + u|, not (U + u)^2 (at 0.15, U + u < 0 is a
    6.7-sigma event and no test saw the difference)."""
    settings = dict(DEFAULTS, turbulence_intensity=1.0, direction=0.0, moment_arm=0.0)
    model = gust_model(settings, 0, seed=3)
    times = np.arange(0.0, 600.0, 0.5)
    speed = U + gusts(model, times, area=True)
    q = 0.5 * DEFAULTS["air_density"] * DEFAULTS["drag_coefficient"] * DEFAULTS["drag_area"]
    pose, wrench, gust = ffi.new("double[6]"), ffi.new("double[6]"), ffi.new("double *")
    along = []
    for t in times:
        assert lib.mb_wind_wrench(model, t, pose, wrench, gust) == 0
        along.append(-wrench[1])       # from the north (direction 0): towards -y
    along = np.array(along)
    backwards = speed < 0
    assert 0.05 < backwards.mean() < 0.5          # the air turns around often enough to be seen
    np.testing.assert_allclose(along, q * speed * np.abs(speed), rtol=1e-12, atol=1e-9)
    assert np.all(along[backwards] < 0) and np.all(along[~backwards] >= 0)
