"""The C telescope kernel (plant/c/telescope.c) against the numpy implementation it
replaced: plant/telescope/model.py, plant/trajectory.py and fmu_src/telescope_fmu.py at git
revision 73017ff, loaded from git into a temporary package. Many parameter sets, every
profile, times on and off the profiles' phase boundaries; the 40-column FMU rows against
the old FMU's _evaluate; invalid input raises the old messages.

Agreement is measured per output column relative to that column's largest magnitude:
the C keeps numpy's operand order, so what is left are ulp-level differences from the
libm (numpy computes x**3 with its own SIMD pow)."""
import importlib
import subprocess
import sys
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

REVISION = "73017ff"
RTOL = 1e-14      # of each column's largest magnitude
ROOT = Path(__file__).resolve().parents[2]
DEG = np.pi / 180


@pytest.fixture(scope="module")
def old(tmp_path_factory):
    """The modules of REVISION as a package ``old73017ff`` (telescope, trajectory, and the
    FMU module as ``telescope_fmu`` importing them and the slave base of that revision)."""
    folder = tmp_path_factory.mktemp("old") / "old73017ff"
    folder.mkdir()
    (folder / "__init__.py").write_text("")
    for name in ("errors", "rotations", "trajectory", "telescope", "slave", "telescope_fmu"):
        path = ("fmu_src/" if name in ("slave", "telescope_fmu") else "plant/") + name + ".py"
        try:
            text = subprocess.run(["git", "show", f"{REVISION}:{path}"], cwd=ROOT, check=True,
                                  capture_output=True, text=True).stdout
        except (OSError, subprocess.CalledProcessError) as exc:
            pytest.skip(f"git cannot show {REVISION}:{path}: {exc}")
        if name == "telescope_fmu":
            text = (text.replace("from plant import telescope", "from old73017ff import telescope")
                        .replace("from plant.trajectory import", "from old73017ff.trajectory import")
                        .replace("from fmu_src.slave import", "from old73017ff.slave import")
                        .replace("from plant.stewart import", "from plant.hexapod.model import"))
            assert "old73017ff" in text
        (folder / f"{name}.py").write_text(text)
    sys.path.insert(0, str(folder.parent))
    try:
        package = importlib.import_module("old73017ff")
        for name in ("telescope", "trajectory", "telescope_fmu"):
            importlib.import_module(f"old73017ff.{name}")
        yield package
    finally:
        sys.path.remove(str(folder.parent))


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


def random_params(rng):
    """Keyword values of a TelescopeParams: every field away from the defaults."""
    return dict(latitude=rng.uniform(-85, 85) * DEG, longitude=rng.uniform(-180, 180) * DEG,
                  lever_arm=rng.choice([0.0, rng.uniform(0, 40)]),
                  az_rate_max=rng.uniform(0.1, 3) * DEG, az_acc_max=rng.uniform(0.05, 2) * DEG,
                  el_rate_max=rng.uniform(0.1, 3) * DEG, el_acc_max=rng.uniform(0.05, 2) * DEG,
                  b_y=rng.uniform(-0.03, 0.03), c_y=rng.uniform(-0.03, 0.03),
                  b_z=rng.uniform(-0.03, 0.03), c_z=rng.uniform(-0.03, 0.03),
                  home=tuple(rng.uniform(-0.1, 0.1, 6) + [0, 0, -2.68, 0, 0, 0]))


def both(old, values):
    return telescope.TelescopeParams(**values), old.telescope.TelescopeParams(**values)


AXES = ("A", "A_dot", "A_ddot", "E", "E_dot", "E_ddot")


def astronomical(old_axes):
    """The old module's slew/sidereal axes with its azimuth read as astronomical Az (its
    inputs and its atan2 were Az): the current A = 180 deg - Az, rates negated."""
    return SimpleNamespace(t=old_axes.t, A=np.pi - old_axes.A, A_dot=-old_axes.A_dot, A_ddot=-old_axes.A_ddot,
                           E=old_axes.E, E_dot=old_axes.E_dot, E_ddot=old_axes.E_ddot)


def compare_motion(new_params, old_params, new_axes, old_axes, old):
    """The profiles' axes, then what each module makes of the same (old) axes: an ulp of
    E near the zenith is 4e-14 of a column like 90 deg - E, and base accelerations that
    nearly cancel magnify it further, so the stages are held to RTOL one by one."""
    for name in ("t",) + AXES:
        assert_same(getattr(new_axes, name), getattr(old_axes, name), name, np.pi if name == "A" else 0.0)
    for what, new_f, old_f in (("base_motion", telescope.base_motion, old.telescope.base_motion),
                               ("base_twist", telescope.base_twist, old.telescope.base_twist),
                               ("reference_pose", telescope.reference_pose, old.telescope.reference_pose)):
        for k, (n, o) in enumerate(zip(new_f(new_params, old_axes), old_f(old_params, old_axes))):
            assert_same(n, o, f"{what}[{k}]")


def call_both(new_f, old_f, new_args, old_args):
    """Both results, or both InvalidInputErrors with the same message (then None)."""
    try:
        expected = old_f(*old_args)
    except Exception as exc:   # noqa: BLE001 - the old error is the truth for the new one
        assert type(exc).__name__ == "InvalidInputError", exc
        with pytest.raises(InvalidInputError) as raised:
            new_f(*new_args)
        assert str(raised.value) == str(exc)
        return None
    return new_f(*new_args), expected


def test_slew_equals_numpy(old):
    rng = np.random.default_rng(1)
    for _ in range(60):
        new_p, old_p = both(old, random_params(rng))
        start = (rng.uniform(-360, 360) * DEG, rng.uniform(0, 90) * DEG)   # none, triangular, long moves:
        target = (start[0] + rng.choice([0.0, rng.uniform(-0.5, 0.5), rng.uniform(-400, 400)]) * DEG,
                  rng.choice([start[1], rng.uniform(0, 90) * DEG, np.pi / 2, 0.0]))
        duration = old.telescope.slew_duration(old_p, start, target)
        assert telescope.slew_duration(new_p, start, target) == pytest.approx(duration, rel=RTOL, abs=0)
        # phase boundaries of both axes exactly, and a dense grid around the whole move
        corners = []
        for (a0, a1), rate, acc in (((start[0], target[0]), old_p.az_rate_max, old_p.az_acc_max),
                                    ((start[1], target[1]), old_p.el_rate_max, old_p.el_acc_max)):
            *_, d = old.telescope._trapezoid(a1 - a0, rate, acc, np.zeros(1))
            t_acc = min(rate / acc, np.sqrt(abs(a1 - a0) / acc))
            corners += [t_acc, d - t_acc, d]
        t = np.unique(np.r_[np.linspace(-5, 1.2 * duration + 5, 700), corners, 0.0])
        new_axes, old_axes = call_both(telescope.slew, old.telescope.slew,
                                       (new_p, start, target, t), (old_p, start, target, t))
        compare_motion(new_p, old_p, new_axes, astronomical(old_axes), old)


def test_sidereal_track_and_lst_equal_numpy(old):
    rng = np.random.default_rng(2)
    compared = failed = 0
    for k in range(80):
        new_p, old_p = both(old, random_params(rng))
        transit = datetime(2000, 1, 1, tzinfo=timezone.utc) + timedelta(seconds=int(rng.uniform(0, 1e9)))
        assert_same([telescope.local_sidereal_time(new_p, transit)],
                    [old.telescope.local_sidereal_time(old_p, transit)], "LST")
        lat = old_p.latitude
        kind = k % 4
        if kind == 0:     # the keyhole: transits just south or north of the zenith
            dec = lat + rng.choice([-1, 1]) * rng.uniform(2e-6, 0.01)
        elif kind == 1:   # circumpolar over a whole day: both culminations, any unwrapping
            dec = np.sign(lat) * rng.uniform(min(90 - abs(lat) + 1, 89.5), 89.9) * DEG
        else:
            dec = rng.uniform(-89, 89) * DEG
        dec = float(np.clip(dec, -np.pi / 2, np.pi / 2))
        ra = old.telescope.local_sidereal_time(old_p, transit) + rng.uniform(-0.3, 0.3)
        span = 90000.0 if kind == 1 else rng.uniform(60, 8 * 3600)
        start = transit - timedelta(seconds=int(span / 2))
        t = np.unique(np.r_[rng.uniform(0, span, 300), np.linspace(0, span, 1500)])
        result = call_both(telescope.sidereal_track, old.telescope.sidereal_track,
                           (new_p, ra, dec, start, t), (old_p, ra, dec, start, t))
        if result is None:
            failed += 1
            continue
        compare_motion(new_p, old_p, result[0], astronomical(result[1]), old)
        compared += 1
    assert compared >= 50 and failed >= 1, (compared, failed)   # both branches exercised


def test_paper_manoeuvre_and_quintic_equal_numpy(old):
    rng = np.random.default_rng(3)
    new_p, old_p = both(old, random_params(rng))
    for T in (6.0, 0.37, 1234.5, rng.uniform(0.1, 100)):
        t = np.unique(np.r_[np.linspace(-1, T + 1, 999), 0.0, T, T / 2])
        compare_motion(new_p, old_p, telescope.paper_manoeuvre(t, T), old.telescope.paper_manoeuvre(t, T), old)
        start, stop = rng.uniform(-3, 3, 5), rng.uniform(-3, 3, 5)
        for k, (n, o) in enumerate(zip(quintic(start, stop, T, t), old.trajectory.quintic(start, stop, T, t))):
            assert_same(n, o, f"quintic[{k}]")
    grid = np.linspace(-1, 7, 24).reshape(2, 3, 4)       # any shape of t, scalar ends
    for n, o in zip(quintic(0.5, 2.0, 6.0, grid), old.trajectory.quintic(0.5, 2.0, 6.0, grid)):
        assert n.shape == o.shape == (2, 3, 4, 1)
        assert_same(n.reshape(-1), o.reshape(-1), "quintic of a 3-D t")


def fmu_pair(old, profile, **settings):
    """The current and the old Telescope with the same parameters, initialised."""
    pair = []
    for new, module in ((True, telescope_fmu), (False, old.telescope_fmu)):
        slave = (module.Telescope if new else module.TelescopeBase)(instance_name=module.__name__)   # renamed
        slave.profile = profile
        slave.settings.update(settings)
        slave.initialize()
        pair.append(slave)
    return pair


FMU_CASES = {
    "slew": (0, {}),
    "slew delayed, far": (0, dict(start_azimuth=-3.0, target_azimuth=4.0, target_elevation=0.1,
                                  start_delay=7.25, lever_arm=31.0, az_rate_max=0.02)),
    "sidereal keyhole": (1, dict(right_ascension=telescope.near_zenith_source(
        telescope.TelescopeParams.tianma(), datetime.fromtimestamp(1.7e9 + 60, timezone.utc))[0])),
    "sidereal delayed": (1, dict(right_ascension=2.0, declination=0.9, utc_start=1.8e9 + 0.5,
                                 start_delay=100.0, latitude=0.6, longitude=-1.2)),
    "paper": (2, dict(lever_arm=0.0)),
    "paper delayed": (2, dict(lever_arm=3.0, paper_duration=2.5, start_delay=1.5)),
}


def old_rows(new, previous, profile, times):
    """What the old FMU gives at ``times`` with today's conventions: its axis columns
    (slew, sidereal: the old A was the astronomical Az already; paper: given as yaw = A,
    output as Az = 180 deg - A) and the rest from the C's axes (see compare_motion)."""
    axis = previous._evaluate(times)[:, 36:]
    if profile == 2:
        axis[:, 0], axis[:, 2] = np.pi - axis[:, 0], -axis[:, 2]
    c_axes = telescope._axes(new.params, new.motion, times)
    profile_at, previous.profile_at = previous.profile_at, lambda t: c_axes
    rest = previous._evaluate(times)[:, :36]
    previous.profile_at = profile_at
    return rest, axis


@pytest.mark.parametrize("case", FMU_CASES)
def test_fmu_rows_equal_the_old_fmu(old, case):
    profile, settings = FMU_CASES[case]
    new, previous = fmu_pair(old, profile, **settings)
    rest, axis = old_rows(new, previous, profile, np.zeros(1))
    assert_same(new.now[None, :40], np.concatenate([rest, axis], axis=1), "outputs after initialisation",
                np.r_[np.zeros(36), np.pi, 0, 0, 0])
    for t0, h, n in ((0.0, 1e-3, telescope_fmu.BLOCK), (3.7, 0.05, 500), (-2.0, 0.25, 200), (1e4, 1.0, 1)):
        times = t0 + h * np.arange(n)
        rows = new._evaluate(times)
        assert rows.shape == (n, 40)
        np.testing.assert_array_equal(rows, telescope.telescope_outputs(new.params, new.motion, times))
        rest, axis = old_rows(new, previous, profile, times)
        assert_same(rows[:, 36:], axis, f"{case} axes from t = {t0}", np.array([np.pi, 0, 0, 0]))
        assert_same(rows[:, :36], rest, f"{case} rows from t = {t0}")


@pytest.mark.parametrize("profile, settings", [
    (0, dict(target_elevation=1.7)),
    (1, dict(declination=2.0)),
    (1, dict(declination=telescope.TelescopeParams.tianma().latitude)),
    (1, dict(declination=-1.4)),                       # never rises at 31 deg north
    (1, dict(declination=-0.5, start_delay=1e4)),      # sets while the block is evaluated
    (2, dict(paper_duration=0.0)),
], ids=["elevation", "dec", "zenith", "below horizon", "sets later", "duration"])
def test_fmu_invalid_settings_raise_the_old_messages(old, profile, settings):
    messages = []
    for new, module in ((True, telescope_fmu), (False, old.telescope_fmu)):
        slave = (module.Telescope if new else module.TelescopeBase)(instance_name=module.__name__)   # renamed
        slave.profile = profile
        slave.settings.update(settings)
        with pytest.raises(Exception) as raised:
            slave.initialize()
            for k in range(3):
                slave._publish(k * 40.0, 40.0)
        assert type(raised.value).__name__ == "InvalidInputError"
        messages.append(str(raised.value))
    assert messages[0] == messages[1]


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
