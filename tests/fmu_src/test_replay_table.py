"""Prepared replay tables (fmu_src/replay_table.py): the bytes hold the Replay scipy made,
exactly; the cache prepares a log once per setting; the command writes the file."""
import numpy as np
import pytest

from fmu_src import replay_table
from plant.errors import InvalidInputError
from plant.telescope import model as tm
from plant.telescope import replay

P = tm.TelescopeParams.tianma()
DEG = np.pi / 180


@pytest.fixture
def log(tmp_path):
    t = np.arange(0.0, 6.0, 0.05)
    axes = tm.slew(P, (0.0, 30 * DEG), (20 * DEG, 45 * DEG), t - 1.0)
    path = tmp_path / "log.csv"
    np.savetxt(path, np.column_stack([t, np.degrees(axes.azimuth), np.degrees(axes.E)]), delimiter=",",
               header="time [s],azimuth [deg],elevation [deg]", comments="", fmt="%.17g")
    return path


def test_prepared_table_holds_the_replay_exactly(log, tmp_path):
    """Knots and coefficients read back bit for bit; the size is the layout's: 24 bytes of
    header, 8 per knot, 64 per interval (120 knots: 8600 bytes)."""
    made = replay.load(log, P, smoothing_time=0.4)
    path = replay_table.write(log, tmp_path / "t.mbreplay", P, 0.4)
    assert path.stat().st_size == 24 + 8 * 120 + 64 * 119
    back = replay.read_prepared(path, 0.4)
    np.testing.assert_array_equal(back.breakpoints, made.breakpoints)
    np.testing.assert_array_equal(back.coefficients, made.coefficients)
    assert back.smoothing_time == 0.4
    with pytest.raises(InvalidInputError, match="smoothed over 0.4 s, replay_smoothing is 0.25 s"):
        replay.load(path, P)


def test_cache_prepares_once_per_setting(log, tmp_path):
    """The same log and settings: the same file, not rewritten; another smoothing time: another
    file, made from the log even when given the first prepared file (a sweep of h)."""
    first = replay_table.prepared(log, P, 0.25, cache=tmp_path / "cache")
    stamp = first.stat().st_mtime_ns
    assert replay_table.prepared(log, P, 0.25, cache=tmp_path / "cache") == first
    assert first.stat().st_mtime_ns == stamp
    other = replay_table.prepared(first, P, 0.5, cache=tmp_path / "cache")
    assert other != first and replay.read_prepared(other).smoothing_time == 0.5
    assert replay_table.prepared(other, P, 0.5) == other   # a prepared table of that h is itself


def test_command_writes_the_table(log, tmp_path, capsys):
    replay_table.main([str(log), "-o", str(tmp_path / "out.mbreplay"), "--smoothing", "0.3"])
    assert capsys.readouterr().out.strip() == str(tmp_path / "out.mbreplay")
    assert replay.read_prepared(tmp_path / "out.mbreplay").smoothing_time == 0.3
    with pytest.raises(SystemExit):
        replay_table.main([str(tmp_path / "missing.csv")])


def test_an_instance_is_given_the_prepared_table_of_its_settings(log, tmp_path):
    """for_fmu: profile replay with a log -> the prepared table of the instance's
    replay_smoothing and drives' limits; another profile, or no table: the values as given."""
    replay_index = tm.PROFILE_KINDS.index("replay")
    given = {"profile": replay_index, "replay_table": str(log), "replay_smoothing": 0.5, "az_acc_max": 0.01}
    values = replay_table.for_fmu(given)
    assert set(values) == set(given) and values["az_acc_max"] == 0.01
    assert replay.read_prepared(values["replay_table"]).smoothing_time == 0.5
    assert values["replay_table"] == str(replay_table.prepared(log, replay_table.params_of(given), 0.5))
    for unchanged in ({"profile": 0, "replay_table": str(log)}, {"profile": replay_index, "replay_table": ""}):
        assert replay_table.for_fmu(unchanged) == unchanged
