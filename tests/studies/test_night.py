"""studies/night.py's pieces that need no loop run: the shipped demonstration night plans,
its synthetic encoder log is what its header says and the table checks treat it as
documented, and a scan's metrics are read against the night's requirements."""
import numpy as np
import pytest

from plant.telescope import model as tm
from plant.telescope import replay
from scenarios import schedule
from studies import night

P = tm.TelescopeParams.tianma()


@pytest.fixture(scope="module")
def planned():
    return schedule.plan(night.NIGHT, P)


def test_the_demonstration_night_plans(planned):
    """Twelve scans of ten minutes over ten hours, each inside [15, 80] deg of elevation."""
    assert len(planned.scans) == 12 and planned.time[-1] == pytest.approx(36000.0)
    for scan in planned.scans:
        assert scan.end - scan.start == pytest.approx(600.0)
        rows = (planned.time >= scan.start) & (planned.time <= scan.end)
        assert 15.0 <= np.degrees(planned.elevation[rows]).min() and np.degrees(planned.elevation[rows]).max() <= 80.0


def test_the_shipped_encoder_log_is_noisy_with_a_bridged_dropout(planned, tmp_path):
    """Regenerated, it is the shipped file; the spline bridges its 0.6 s dropout and
    smooths its 2 arcsec noise to the documented 0.297 sigma / sqrt(r h^5) of acceleration;
    with a 3 s dropout it is refused, naming the rows."""
    path = night.synthetic_log(planned, tmp_path / "log.csv")
    ours, shipped = replay.read_table(path), replay.read_table(night.ENCODER_LOG)
    assert np.array_equal(ours.time, shipped.time)      # the rows kept: the dropout is where it was
    for a, b in ((ours.azimuth, shipped.azimuth), (ours.elevation, shipped.elevation)):
        assert np.abs(a - b).max() <= np.radians(1.01e-7)   # the file's last digit (1e-7 deg) may round apart
    loaded, refused = night.log_checks(path, P)
    t = replay.read_table(path).time
    assert np.diff(t).max() == pytest.approx(0.65, abs=1e-9)
    assert "a gap of 3.05 s" in refused and "rows " in refused
    clean = replay.replay_table(replay.Table(*(a for a in _clean(planned))), P)
    times = np.arange(5.0, t[-1] - 5.0, 0.01)
    error = tm.replay_track(P, loaded, times).E_ddot - tm.replay_track(P, clean, times).E_ddot
    expected = 0.297 * np.radians(2.0 / 3600) / np.sqrt(20.0 * replay.SMOOTHING_TIME ** 5)
    assert 0.7 * expected < error.std() < 1.3 * expected


def _clean(planned):
    scan = planned.scans[1]
    t0 = scan.slew_start - 30.0
    rows = (planned.time >= t0) & (planned.time <= scan.start + 90.0)
    return planned.time[rows] - t0, planned.azimuth[rows], planned.elevation[rows]


def test_breaches_read_the_requirements():
    metrics = {"pointing": {"peak": 3.0, **{k: 0.5 for k in night.BANDS}}, "pose error": {"peak": 50.0}}
    requirements = {"pointing_peak_arcsec": 2.7, "pose_error_peak_um": 100.0, "efficiency_loss_43GHz_percent": 0.4}
    assert night.breaches(metrics, requirements) == [("pointing_peak_arcsec", 3.0, 2.7),
                                                    ("efficiency_loss_43GHz_percent", 0.5, 0.4)]
    assert night.wind_at({"hours": [0, 3, 4], "speed": [4, 4, 12]}, 3.5) == 8.0
