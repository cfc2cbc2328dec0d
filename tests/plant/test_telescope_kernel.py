"""The C telescope kernel (plant/c/telescope.c) against the numpy implementation it
replaced: plant/telescope/model.py, plant/trajectory.py and fmu_src/telescope_fmu.py at git
revision 73017ff. Many parameter sets, every profile, times on and off the profiles'
phase boundaries; the 40-column FMU rows against the old FMU's _evaluate; invalid input
raises the old messages.

The old modules' inputs and outputs are stored in tests/golden/telescope_c_numba.npz
(fewer times per profile than the comparison against the live old modules had, to keep
the file small); regenerate with tests/golden/make_numba_golden.py (needs the git history).

Agreement is measured per output column relative to that column's largest magnitude:
the C keeps numpy's operand order, so what is left are ulp-level differences from the
libm (numpy computes x**3 with its own SIMD pow)."""
from datetime import datetime, timedelta, timezone
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from fmu_src import telescope_fmu
from plant.errors import InvalidInputError
from plant.hexapod.model import HOME_POSE, S_BAND_POSE
from plant.telescope import model as telescope
from plant.trajectory import quintic

GOLDEN = Path(__file__).resolve().parents[1] / "golden" / "telescope_c_numba.npz"
RTOL = 1e-14      # of each column's largest magnitude
DEG = np.pi / 180
EARTH_RATE = 7.2921159e-5   # rad/s (plant/c/telescope.c)
FIELDS = ("latitude", "longitude", "lever_arm", "az_rate_max", "az_acc_max", "el_rate_max", "el_acc_max",
          "b_y", "c_y", "b_z", "c_z")   # then home: the columns of the stored parameter rows
J2000_ISH = datetime(2000, 1, 1, tzinfo=timezone.utc)   # the stored transits and starts count from here
with np.load(GOLDEN) as _golden:
    FMU_CASES, INVALID_CASES = list(_golden["fmu_cases"]), list(_golden["invalid_cases"])


@pytest.fixture(scope="module")
def old():
    """The arrays of GOLDEN: inputs, and what the modules of 73017ff returned for them."""
    with np.load(GOLDEN) as golden:
        return dict(golden)


def ragged(old, name, k):
    """Entry k of a list of arrays stored concatenated (with ``name``_offsets)."""
    offsets = old[f"{name}_offsets"]
    return old[name][offsets[k]:offsets[k + 1]]


def params(row):
    """TelescopeParams of a stored row (FIELDS, then home)."""
    return telescope.TelescopeParams(**dict(zip(FIELDS, row[:len(FIELDS)])), home=tuple(row[len(FIELDS):]))


def settings(old, prefix):
    """(profile, settings) of a stored FMU case."""
    return int(old[f"{prefix}_profile"]), {str(k): float(v) for k, v in zip(old[f"{prefix}_names"],
                                                                          old[f"{prefix}_values"])}


def assert_same(new, old, what, floor=0.0):
    """new == old to RTOL of each column's largest |old| (exactly where a column is 0), or
    of ``floor`` (per column) if larger: an azimuth carries the rounding of 180 deg - Az."""
    new, old = np.asarray(new, dtype=float), np.asarray(old, dtype=float)
    assert new.shape == old.shape, what
    columns_new, columns_old = new.reshape(new.shape[0], -1), old.reshape(old.shape[0], -1)
    scale = np.maximum(np.max(np.abs(columns_old), axis=0), floor)
    error = np.abs(columns_new - columns_old)
    assert np.all(error <= RTOL * scale), (
        f"{what}: worst {np.max(error / np.where(scale > 0, scale, 1.0)):.3g} of the column scale")


AXES = ("A", "A_dot", "A_ddot", "E", "E_dot", "E_ddot")


def old_axes(rows, astronomical_az):
    """The old module's axes from their stored (n, 7) rows [t, A, A', A'', E, E', E''];
    slew and sidereal axes with their azimuth read as astronomical Az (its inputs and its
    atan2 were Az): the current A = 180 deg - Az, rates negated."""
    t, A, A_dot, A_ddot, E, E_dot, E_ddot = rows.T
    if astronomical_az:
        A, A_dot, A_ddot = np.pi - A, -A_dot, -A_ddot
    return SimpleNamespace(t=t, A=A, A_dot=A_dot, A_ddot=A_ddot, E=E, E_dot=E_dot, E_ddot=E_ddot)


def compare_motion(new_params, new_axes, old, profile, k):
    """The profiles' axes, then what the C makes of the same (old) axes against what the old
    module made of them: an ulp of E near the zenith is 4e-14 of a column like 90 deg - E,
    and base accelerations that nearly cancel magnify it further, so the stages are held
    to RTOL one by one. Case k of ``profile`` (slew, sidereal, paper) in the stored arrays.
    A track's rates and accelerations are sums of terms of the Earth's rate and its square:
    where they nearly cancel (E'' away from the meridian: 1e-10 rad/s2) they still carry the
    rounding of those terms, which another libm rounds differently, so those are their floors."""
    axes = old_axes(ragged(old, f"{profile}_axes", k), profile != "paper")
    floors = {"A": np.pi}
    if profile == "sidereal":
        floors.update(A_dot=EARTH_RATE, E_dot=EARTH_RATE, A_ddot=EARTH_RATE ** 2, E_ddot=EARTH_RATE ** 2)
    for name in ("t",) + AXES:
        assert_same(getattr(new_axes, name), getattr(axes, name), name, floors.get(name, 0.0))
    for what, new_f in (("base_motion", telescope.base_motion), ("base_twist", telescope.base_twist),
                        ("reference_pose", telescope.reference_pose)):
        stored = ragged(old, f"{profile}_{what}", k)
        for j, n in enumerate(new_f(new_params, axes)):
            assert_same(n, stored[:, j], f"{what}[{j}]")


def test_slew_equals_numpy(old):
    """Parameter sets away from the defaults; no, triangular and long moves, to elevations
    on and off 0 and 90 deg; times on both axes' phase boundaries and a grid around the move."""
    compared = 0
    for k, (row, ends, duration, message) in enumerate(zip(old["slew_params"], old["slew_ends"],
                                                           old["slew_duration"], old["slew_message"])):
        new_p, start, target, t = params(row), tuple(ends[:2]), tuple(ends[2:]), ragged(old, "slew_t", k)
        assert telescope.slew_duration(new_p, start, target) == pytest.approx(duration, rel=RTOL, abs=0)
        if message:
            with pytest.raises(InvalidInputError) as raised:
                telescope.slew(new_p, start, target, t)
            assert str(raised.value) == message
            continue
        compare_motion(new_p, telescope.slew(new_p, start, target, t), old, "slew", compared)
        compared += 1
    assert compared == len(old["slew_axes_offsets"]) - 1


def test_sidereal_track_and_lst_equal_numpy(old):
    """Keyhole transits just south or north of the zenith, circumpolar sources over a whole
    day, and any others, over random spans: where the old track raised, the same message."""
    compared = failed = 0
    for k, (row, transit_s, lst, (ra, dec), start_s, message) in enumerate(zip(
            old["sidereal_params"], old["sidereal_transit_s"], old["sidereal_lst"], old["sidereal_source"],
            old["sidereal_start_s"], old["sidereal_message"])):
        new_p = params(row)
        transit = J2000_ISH + timedelta(seconds=int(transit_s))
        assert_same([telescope.local_sidereal_time(new_p, transit)], [lst], "LST")
        start, t = J2000_ISH + timedelta(seconds=int(start_s)), ragged(old, "sidereal_t", k)
        if message:
            with pytest.raises(InvalidInputError) as raised:
                telescope.sidereal_track(new_p, ra, dec, start, t)
            assert str(raised.value) == message
            failed += 1
            continue
        compare_motion(new_p, telescope.sidereal_track(new_p, ra, dec, start, t), old, "sidereal", compared)
        compared += 1
    assert compared >= 50 and failed >= 1, (compared, failed)   # both branches exercised


def test_paper_manoeuvre_and_quintic_equal_numpy(old):
    new_p = params(old["paper_params"][0])
    for k, (T, (start, stop)) in enumerate(zip(old["paper_duration"], old["paper_quintic_ends"])):
        t = ragged(old, "paper_t", k)
        compare_motion(new_p, telescope.paper_manoeuvre(t, T), old, "paper", k)
        stored = ragged(old, "paper_quintic", k)
        for j, n in enumerate(quintic(start, stop, T, t)):
            assert_same(n, stored[:, j], f"quintic[{j}]")
    grid = np.linspace(-1, 7, 24).reshape(2, 3, 4)       # any shape of t, scalar ends
    for n, o in zip(quintic(0.5, 2.0, 6.0, grid), old["paper_quintic_grid"]):
        assert n.shape == o.shape == (2, 3, 4, 1)
        assert_same(n.reshape(-1), o.reshape(-1), "quintic of a 3-D t")


def initialised(profile, settings):
    """The current Telescope with these settings, initialised."""
    slave = telescope_fmu.Telescope(instance_name="new")
    slave.profile = profile
    slave.settings.update(settings)
    slave.initialize()
    return slave


@pytest.mark.parametrize("case", range(len(FMU_CASES)), ids=FMU_CASES)
def test_fmu_rows_equal_the_old_fmu(old, case):
    """The rows after initialisation and of blocks of times, against the old FMU's stored
    rows (every fmu_stride-th of a block): its axis columns (slew, sidereal: the old A was
    the astronomical Az already; paper: given as yaw = A, output as Az = 180 deg - A), and
    the rest as the old FMU made them from the C's axes (see compare_motion)."""
    new = initialised(*settings(old, f"fmu_{case}"))
    blocks, stride = old["fmu_blocks"], int(old["fmu_stride"])
    assert_same(new.now[None, :40], ragged(old, f"fmu_{case}_rows", 0), "outputs after initialisation",
                np.r_[np.zeros(36), np.pi, 0, 0, 0])
    for b, (t0, h, n) in enumerate(blocks[1:], start=1):
        times = t0 + h * np.arange(int(n))
        rows = new._evaluate(times)
        assert rows.shape == (n, 40)
        np.testing.assert_array_equal(rows, telescope.telescope_outputs(new.params, new.motion, times))
        rows, stored = rows[::stride], ragged(old, f"fmu_{case}_rows", b)
        assert_same(rows[:, 36:], stored[:, 36:], f"{FMU_CASES[case]} axes from t = {t0}", np.array([np.pi, 0, 0, 0]))
        assert_same(rows[:, :36], stored[:, :36], f"{FMU_CASES[case]} rows from t = {t0}")


@pytest.mark.parametrize("case", range(len(INVALID_CASES)), ids=INVALID_CASES)
def test_fmu_invalid_settings_raise_the_old_messages(old, case):
    """Elevation and declination out of range, a source through the zenith, one that never
    rises and one that sets while the block is evaluated, a zero duration."""
    profile, values = settings(old, f"invalid_{case}")
    slave = telescope_fmu.Telescope(instance_name="new")
    slave.profile = profile
    slave.settings.update(values)
    with pytest.raises(InvalidInputError) as raised:
        slave.initialize()
        for k in range(3):
            slave._publish(k * 40.0, 40.0)
    assert str(raised.value) == old[f"invalid_{case}_message"]


@pytest.mark.parametrize("name", ["start_azimuth", "utc_start", "paper_duration", "start_delay"])
def test_fmu_non_finite_setting_is_named(name):
    profile = {"start_azimuth": 0, "utc_start": 1, "paper_duration": 2, "start_delay": 1}[name]
    slave = telescope_fmu.Telescope(instance_name="nan")
    slave.profile = profile
    slave.settings[name] = np.nan
    with pytest.raises(InvalidInputError, match=f"{name} must be finite"):
        slave.initialize()


def test_non_finite_time_is_named():
    profile = telescope.motion_profile("paper", reference=(HOME_POSE, S_BAND_POSE))
    with pytest.raises(InvalidInputError, match=r"t must be finite, got .*nan.* at index 2"):
        telescope.telescope_outputs(telescope.TelescopeParams.tianma(), profile, [0.0, 1.0, np.nan])
