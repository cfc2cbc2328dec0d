"""scenarios/schedule.py: a schedule file becomes the table the telescope replays. Truths:
astropy's AltAz called here apart (not through the module), the kit's own sidereal
profile and slew durations, and the refusals of scans that cannot be observed."""
from datetime import datetime, timezone

import numpy as np
import pytest
from astropy.utils import iers

iers.conf.auto_download = False
import astropy.units as u  # noqa: E402
from astropy.coordinates import TETE, AltAz, EarthLocation, SkyCoord  # noqa: E402
from astropy.time import Time  # noqa: E402

from plant.telescope import model as tm  # noqa: E402
from plant.telescope import replay  # noqa: E402
from scenarios import schedule  # noqa: E402
from scenarios.spec import ScenarioError  # noqa: E402

P = tm.TelescopeParams.tianma()
ARCSEC = np.pi / 180 / 3600
OJ287 = ('source = "OJ 287"\nra = "08h54m48.8749s"\ndec = "20d06m30.641s"\n', 133.7036454, 20.1085114)
C4_39 = ('source = "4C 39.25"\nra = "09h27m03.0139s"\ndec = "39d02m20.852s"\n', 141.7625579, 39.0391256)


def write(tmp_path, start, *scans, head=""):
    text = f'start = "{start}"\n{head}' + "".join(f"[[scans]]\n{s}" for s in scans)
    path = tmp_path / "night.toml"
    path.write_text(text)
    return path


def astropy_altaz(ra_deg, dec_deg, utc, t):
    """Azimuth, elevation [rad] by astropy directly: ICRS -> AltAz, no refraction."""
    site = EarthLocation(lat=P.latitude * u.rad, lon=P.longitude * u.rad, height=0 * u.m)
    times = Time(utc) + t * u.s
    c = SkyCoord(ra=ra_deg * u.deg, dec=dec_deg * u.deg, frame="icrs").transform_to(
        AltAz(obstime=times, location=site, pressure=0 * u.hPa))
    return c.az.rad, c.alt.rad


@pytest.fixture(scope="module")
def night(tmp_path_factory):
    folder = tmp_path_factory.mktemp("night")
    path = write(folder, "2024-03-01T11:30:00", OJ287[0] + 'duration = "4 min"\n', C4_39[0] + 'duration = "3 min"\n')
    plan = schedule.plan(path)
    return plan, plan.write(folder / "night.csv")


def test_scans_are_where_astropy_puts_the_sources(night):
    """Within 1 arcsec of astropy computed apart, in the table and in its replay (the CSV's
    rounding and the spline's smoothing included), on the sky (azimuth times cos E)."""
    plan, csv = night
    replayed = replay.load(csv, P)
    for scan, (_, ra, dec) in zip(plan.scans, (OJ287, C4_39)):
        t = np.linspace(scan.start + 1.0, scan.end - 1.0, 97)
        rows = np.searchsorted(plan.time, t)
        t = plan.time[rows]
        az, el = astropy_altaz(ra, dec, plan.utc_start, t)
        got = tm.replay_track(P, replayed, t)
        for azimuth, elevation in ((plan.azimuth[rows], plan.elevation[rows]), (got.azimuth, got.E)):
            d_az = (azimuth - az + np.pi) % (2 * np.pi) - np.pi
            assert np.abs(d_az * np.cos(el)).max() < 1 * ARCSEC
            assert np.abs(elevation - el).max() < 1 * ARCSEC


def test_a_scan_agrees_with_the_kits_sidereal_profile(night):
    """The kit's sidereal profile at the source's apparent (TETE) place: within its own
    documented agreement with astropy (<= 0.0013 deg of hour angle: 4.7 arcsec)."""
    plan, _ = night
    scan = plan.scans[1]
    t = plan.time[(plan.time >= scan.start) & (plan.time <= scan.end)]
    utc = plan.utc_start.replace(tzinfo=None)
    apparent = SkyCoord(ra=C4_39[1] * u.deg, dec=C4_39[2] * u.deg, frame="icrs").transform_to(
        TETE(obstime=Time(plan.utc_start) + scan.start * u.s))
    track = tm.sidereal_track(P, apparent.ra.rad, apparent.dec.rad, utc, t)
    rows = (plan.time >= scan.start) & (plan.time <= scan.end)
    d_az = (plan.azimuth[rows] - track.azimuth + np.pi) % (2 * np.pi) - np.pi
    assert np.abs(d_az * np.cos(track.E)).max() < 5 * ARCSEC
    assert np.abs(plan.elevation[rows] - track.E).max() < 5 * ARCSEC


def test_slews_at_the_axis_limits_arrive_on_the_source(night):
    """The slew between the scans lasts the kit's slew_duration to where the source is at
    the arrival, and the table is continuous there; the whole table passes replay's checks."""
    plan, csv = night
    first, second = plan.scans
    end = np.searchsorted(plan.time, first.end)
    start = np.searchsorted(plan.time, second.start)
    az, el = astropy_altaz(C4_39[1], C4_39[2], plan.utc_start, np.array([second.start]))
    aim = (plan.azimuth[end] + ((az[0] - plan.azimuth[end] + np.pi) % (2 * np.pi) - np.pi), el[0])
    duration = tm.slew_duration(P, (plan.azimuth[end], plan.elevation[end]), aim)
    assert second.slew_start == first.end
    assert second.start - second.slew_start == pytest.approx(duration, abs=1e-6)
    steps = np.abs(np.diff(plan.azimuth[start - 3:start + 3]))
    assert steps.max() < 0.06 * P.az_rate_max       # no jump: a 20 Hz step moves < 0.05 s x the max rate
    assert 60.0 < duration < 120.0
    replay.load(csv, P)


def test_a_track_across_north_is_unwrapped(tmp_path):
    """A circumpolar source crossing north (Polaris' neighbour at dec 80 deg) stays one
    continuous azimuth inside the cable wrap."""
    path = write(tmp_path, "2024-03-01T12:00:00", 'source = "near pole"\nra = "19h15m00s"\ndec = "80d"\n'
                 'duration = "60 min"\n')
    plan = schedule.plan(path)
    assert np.abs(np.diff(plan.azimuth)).max() < 1e-3
    assert np.ptp(np.mod(plan.azimuth, 2 * np.pi)) > np.pi     # it did cross north: wrapped values would jump


@pytest.mark.parametrize("scans, head, match", [
    ((OJ287[0] + 'duration = "5 min"\nstart = "2024-03-01T23:00:00"\n',), "",
     r"scans\[0\]: OJ 287 cannot be observed: its elevation is -\d+\.\d+ deg at 2024-03-01T23:00:00 UTC, outside "
     r"\[15, 80\] deg"),
    ((OJ287[0] + 'duration = "5 min"\n',), 'keyhole = "40 deg"\n',
     r"OJ 287 cannot be observed: its elevation is 5\d\.\d+ deg .*outside \[15, 40\] deg"),
    ((OJ287[0] + 'duration = "5 min"\n', C4_39[0] + 'duration = "5 min"\nstart = "2024-03-01T11:35:30"\n'), "",
     r"scans\[1\]: 4C 39.25 cannot be observed: its start 2024-03-01T11:35:30 is before the slew from the last "
     r"scan can arrive"),
    (('body = "vulcan"\nduration = "5 min"\n',), "", "body 'vulcan' is not a solar-system body"),
    (('source = "x"\nra = "12h"\nduration = "5 min"\n',), "", r"scans\[0\]: a scan needs ra and dec"),
    (('source = "x"\nra = "12h"\ndec = "95 deg"\nduration = "5 min"\n',), "", r"scans\[0\]\.dec: '95 deg' is "
     r"outside \[-90, 90\] deg"),
])
def test_what_cannot_be_observed_is_refused_with_the_reason(tmp_path, scans, head, match):
    with pytest.raises(ScenarioError, match=match):
        schedule.plan(write(tmp_path, "2024-03-01T11:30:00", *scans, head=head))


def test_a_solar_system_body(tmp_path):
    """Jupiter by name: where astropy's get_body puts it (computed apart, to 1 arcsec)."""
    from astropy.coordinates import get_body
    plan = schedule.plan(write(tmp_path, "2024-03-01T11:00:00", 'body = "jupiter"\nduration = "2 min"\n'))
    t = plan.time[::400]
    site = EarthLocation(lat=P.latitude * u.rad, lon=P.longitude * u.rad, height=0 * u.m)
    times = Time(datetime(2024, 3, 1, 11, tzinfo=timezone.utc)) + t * u.s
    c = get_body("jupiter", times, site).transform_to(AltAz(obstime=times, location=site, pressure=0 * u.hPa))
    assert np.abs(plan.elevation[::400] - c.alt.rad).max() < 1 * ARCSEC


def test_times_beyond_the_bundled_iers_table_are_refused(tmp_path):
    """Offline, UT1 is known as far as the bundled table predicts (its predictions used
    however old); past its end the schedule is refused, not computed on a guess."""
    end = Time(iers.IERS_Auto.open()["MJD"][-1].value, format="mjd")
    late = (end + 30 * u.day).isot[:19]
    with pytest.raises(ScenarioError, match=r"OJ 287: .* UTC is past the end of the IERS table bundled with astropy"):
        schedule.plan(write(tmp_path, late, OJ287[0] + 'duration = "2 min"\n'))
    soon = (end - 200 * u.day).isot[:10]      # in the table's predictions: planned
    path = tmp_path / "soon.toml"             # a circumpolar source (21..41 deg at Tianma), a TOML date-time
    path.write_text(f'start = {soon}T12:00:00Z\n[[scans]]\nsource = "near pole"\nra = "19h15m00s"\ndec = "80d"\n'
                    'duration = "1 min"\n')
    plan = schedule.plan(path)
    assert plan.utc_start == datetime.fromisoformat(f"{soon}T12:00:00+00:00")
    assert 21.0 < np.degrees(plan.elevation).min() < np.degrees(plan.elevation).max() < 41.1
