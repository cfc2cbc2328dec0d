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


@pytest.mark.parametrize("k", [0, 1])
def test_a_scan_agrees_with_the_kits_sidereal_profile(night, k):
    """The kit's sidereal profile at the source's apparent (TETE) place: within its own
    documented agreement with astropy (<= 0.0013 deg of hour angle: 4.7 arcsec; measured
    3.9 arcsec in elevation), and the schedule's difference from it is the profile's own
    difference from astropy computed apart, to 0.01 arcsec: a slip of the schedule's
    positions by a tenth of an arcsec fails it."""
    plan, _ = night
    scan, (_, ra, dec) = plan.scans[k], (OJ287, C4_39)[k]
    rows = (plan.time >= scan.start) & (plan.time <= scan.end)
    t = plan.time[rows]
    utc = plan.utc_start.replace(tzinfo=None)
    apparent = SkyCoord(ra=ra * u.deg, dec=dec * u.deg, frame="icrs").transform_to(
        TETE(obstime=Time(plan.utc_start) + scan.start * u.s))
    track = tm.sidereal_track(P, apparent.ra.rad, apparent.dec.rad, utc, t)
    az, el = astropy_altaz(ra, dec, plan.utc_start, t)
    ours = ((plan.azimuth[rows] - track.azimuth + np.pi) % (2 * np.pi) - np.pi, plan.elevation[rows] - track.E)
    theirs = ((az - track.azimuth + np.pi) % (2 * np.pi) - np.pi, el - track.E)
    assert np.abs(ours[0] * np.cos(track.E)).max() < 4.7 * ARCSEC
    assert 1.0 * ARCSEC < np.abs(ours[1]).max() < 4.7 * ARCSEC
    for a, b, scale in zip(ours, theirs, (np.cos(track.E), 1.0)):
        assert np.abs((a - b) * scale).max() < 0.01 * ARCSEC


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
    (('body = "vulcan"\nduration = "5 min"\n',), "", r"scans\[0\]: body 'vulcan' is not a solar-system body the "
     r"telescope can point at \(sun, moon, mercury, venus, mars, jupiter, saturn, uranus, neptune\)$"),
    (('body = "earth"\nduration = "5 min"\n',), "", r"scans\[0\]: body 'earth' is not a solar-system body the "
     r"telescope can point at"),
    (('source = "x"\nra = "12h"\nduration = "5 min"\n',), "", r"scans\[0\]: a scan needs ra and dec"),
    (('source = "x"\nra = "12h"\ndec = "95 deg"\nduration = "5 min"\n',), "", r"scans\[0\]\.dec: '95 deg' is "
     r"outside \[-90, 90\] deg"),
    (('source = "x"\nra = "25h"\ndec = "20 deg"\nduration = "5 min"\n',), "", r"scans\[0\]\.ra: '25h' is "
     r"outside \[0h, 24h\) \(0 to 360 deg\)"),
    (('source = "x"\nra = 133.7\ndec = "20 deg"\nduration = "5 min"\n',), "", r"scans\[0\]\.ra: 133\.7 is not an "
     r"angle such as"),
    (('body = "jupiter"\nra = "12h"\ndec = "20 deg"\nduration = "5 min"\n',), "", r"scans\[0\]: give either body or "
     r"ra and dec, not both"),
    # below the elevation limit all night: where it culminates says so
    (('source = "south"\nra = "08h54m"\ndec = "-70d"\nduration = "5 min"\n',), "",
     r"scans\[0\]: south cannot be observed: its elevation is -15\.\d+ deg at 2024-03-01T11:30:00 UTC, outside "
     r"\[15, 80\] deg \(elevation_limit, keyhole\); at the site's latitude 31\.09 deg it culminates at -11\.09 deg: "
     r"it is never above the elevation limit$"),
    # sets during the scan: a scan longer than its night
    ((OJ287[0] + 'duration = "9 h"\n',), "",
     r"OJ 287 cannot be observed: its elevation leaves \[15, 80\] deg \(elevation_limit, keyhole\) at "
     r"2024-03-01T19:47:5\d UTC, 497\.\d min into the scan of 540\.0 min$"),
    # longer than a schedule may be (a day at 20 Hz: the replay's MAX_ROWS)
    (('source = "near pole"\nra = "19h15m00s"\ndec = "80d"\nduration = "25 h"\n',), "",
     r"scans\[0\]: near pole cannot be observed: it would end 25 h after the first scan's start, beyond the 24 h "
     r"a schedule may span"),
    (('source = "near pole"\nra = "19h15m00s"\ndec = "80d"\nduration = "1e12 s"\n',), "",
     r"it would end 2\.778e\+08 h after the first scan's start"),
    (('source = "near pole"\nra = "19h15m00s"\ndec = "80d"\nduration = "10 h"\n',
      'source = "near pole"\nra = "19h15m00s"\ndec = "80d"\nduration = "10 h"\nstart = "2024-03-02T09:00:00"\n'), "",
     r"scans\[1\]: near pole cannot be observed: it would end 31\.5 h after the first scan's start"),
    # bad times
    ((OJ287[0] + 'duration = "5 min"\nstart = "2024-02-30T12:00:00"\n',), "",
     r"scans\[0\]\.start: '2024-02-30T12:00:00' is not a UTC time such as"),
    ((OJ287[0] + 'duration = "5 min"\nstart = 2024-03-01\n',), "",
     r"scans\[0\]\.start: datetime\.date\(2024, 3, 1\) is not a UTC time such as"),
    ((OJ287[0] + 'duration = "5 min"\nstart = "2024-03-01T11:00:00"\n',), "",
     r"scans\[0\]: OJ 287 cannot be observed: its start 2024-03-01T11:00:00 is before the schedule's start"),
    ((OJ287[0] + 'duration = "nan s"\n',), "", r"scans\[0\]\.duration: 'nan s' is not a finite number"),
    ((OJ287[0] + 'duration = "-5 min"\n',), "", r"scans\[0\]\.duration: '-5 min' must be > 0"),
    ((OJ287[0],), "", r"scans\[0\]\.duration: a scan needs its duration"),
])
def test_what_cannot_be_observed_is_refused_with_the_reason(tmp_path, scans, head, match):
    with pytest.raises(ScenarioError, match=r"night\.toml: " + ("" if match.startswith("scans") else ".*") + match):
        schedule.plan(write(tmp_path, "2024-03-01T11:30:00", *scans, head=head))


ZENITH = 'source = "zenith"\nra = "222.3231 deg"\ndec = "30.89 deg"\nduration = "15 min"\n'   # keyhole_tracking's


@pytest.mark.parametrize("head, match", [
    ("", r"zenith cannot be observed: its elevation is 88\.\d\d deg at 2025-12-31T23:55:00 UTC, outside \[15, 80\] "
         r"deg \(elevation_limit, keyhole\)$"),
    ('keyhole = "90 deg"\n', r"zenith cannot be observed: its azimuth rate reaches 0\.6\d deg/s, beyond the drive's "
                           r"0\.5 deg/s \(the keyhole near the zenith\)$"),
])
def test_a_pass_through_the_keyhole_is_refused(tmp_path, head, match):
    """keyhole_tracking's source over its transit 0.31 deg from the zenith (00:03:10 UTC):
    above the keyhole elevation; with the keyhole at 90 deg, an azimuth rate of 0.66 deg/s
    the drive cannot follow."""
    with pytest.raises(ScenarioError, match=match):
        schedule.plan(write(tmp_path, "2025-12-31T23:55:00", ZENITH, head=head))


def test_a_handover_the_drives_cannot_make_is_refused(tmp_path):
    """A slew starts and ends at rest; a track 1.6 deg from the zenith (keyhole raised to
    90 deg) moves at 0.12 deg/s in azimuth: the step, smoothed, passes the drive's
    acceleration (the replay would refuse the table at its row); the schedule names the
    scan and the step. The same schedule with the source 30 deg lower is planned and replays."""
    near = 'source = "z"\nra = "222.3231 deg"\ndec = "{dec} deg"\nduration = "5 min"\n'
    then = 'source = "b"\nra = "200.3231 deg"\ndec = "40 deg"\nduration = "2 min"\n'
    with pytest.raises(ScenarioError, match=r"scans\[1\]: b cannot be observed: its slew leaves the last scan at rest "
                                            r"while the track moves at 0\.123 deg/s in azimuth, 0\.00625 deg/s in "
                                            r"elevation: a step the drives cannot make \(the smoothed azimuth "
                                            r"acceleration up to 0\.27\d* deg/s2 passes the drive's 0\.25 deg/s2 "
                                            r"\(\+8% allowed\)\); lower the keyhole$"):
        schedule.plan(write(tmp_path, "2025-12-31T23:58:00", near.format(dec=29.5), then, head='keyhole = "90 deg"\n'))
    plan = schedule.plan(write(tmp_path, "2025-12-31T23:58:00", near.format(dec=60), then, head='keyhole = "90 deg"\n'))
    replay.load(plan.write(tmp_path / "night.csv"), P)


@pytest.mark.parametrize("start, match", [
    ("yesterday", r"start: 'yesterday' is not a UTC time such as \"2024-03-01T12:00:00\""),
    ("1950-01-01T12:00:00", r"start: 1950-01-01T12:00:00 UTC is outside the IERS table bundled with astropy "
                            r"\(1973-01-02 to 20\d\d-\d\d-\d\d\): the Earth's orientation is not known offline then"),
])
def test_a_bad_schedule_start_is_refused(tmp_path, start, match):
    with pytest.raises(ScenarioError, match=r"night\.toml: " + match):
        schedule.plan(write(tmp_path, start, OJ287[0] + 'duration = "2 min"\n'))


@pytest.mark.parametrize("text, match", [
    ("", r"night\.toml: start: missing: a schedule needs its UTC start"),
    ('start = "2024-03-01T11:30:00"\n', r"night\.toml: scans: a schedule needs at least one \[\[scans\]\] table"),
    ('start = "2024-03-01T11:30:00"\nscans = []\n', r"night\.toml: scans: a schedule needs at least one"),
    ('start = "2024-03-01T11:30:00"\nkeyhole = "10 deg"\n[[scans]]\nbody = "moon"\nduration = "1 min"\n',
     r"night\.toml: elevation_limit: elevation_limit 15 deg and keyhole 10 deg must rise within the axis range"),
    ('start = "2024-03-01T11:30:00"\nsite = "Effelsberg"\n', r"night\.toml: site: unknown key"),
    ('start = "2024-03-01T11:30:00"\n[[scans]]\nbody = "moon"\ntime = "1 min"\n', r"scans\[0\]\.time: unknown key"),
])
def test_a_bad_schedule_file_is_refused_by_key(tmp_path, text, match):
    path = tmp_path / "night.toml"
    path.write_text(text)
    with pytest.raises(ScenarioError, match=match):
        schedule.plan(path)


def test_a_start_with_an_offset_is_that_utc_time(tmp_path):
    """"2024-03-01T19:30:00+08:00" (Beijing time) is 11:30 UTC: the same table."""
    utc = schedule.plan(write(tmp_path, "2024-03-01T11:30:00", OJ287[0] + 'duration = "1 min"\n'))
    local = schedule.plan(write(tmp_path, "2024-03-01T19:30:00+08:00", OJ287[0] + 'duration = "1 min"\n'))
    assert local.utc_start == utc.utc_start == datetime(2024, 3, 1, 11, 30, tzinfo=timezone.utc)
    np.testing.assert_array_equal(local.azimuth, utc.azimuth)


def test_a_solar_system_body(tmp_path):
    """Jupiter by name: where astropy's get_body puts it (computed apart, to 1 arcsec)."""
    from astropy.coordinates import get_body
    plan = schedule.plan(write(tmp_path, "2024-03-01T11:00:00", 'body = "jupiter"\nduration = "2 min"\n'))
    t = plan.time[::400]
    site = EarthLocation(lat=P.latitude * u.rad, lon=P.longitude * u.rad, height=0 * u.m)
    times = Time(datetime(2024, 3, 1, 11, tzinfo=timezone.utc)) + t * u.s
    c = get_body("jupiter", times, site).transform_to(AltAz(obstime=times, location=site, pressure=0 * u.hPa))
    assert np.abs(plan.elevation[::400] - c.alt.rad).max() < 1 * ARCSEC
    d_az = (plan.azimuth[::400] - c.az.rad + np.pi) % (2 * np.pi) - np.pi
    assert np.abs(d_az * np.cos(c.alt.rad)).max() < 1 * ARCSEC


def test_times_beyond_the_bundled_iers_table_are_refused(tmp_path):
    """Offline, UT1 is known as far as the bundled table predicts (its predictions used
    however old); past its end the schedule is refused, not computed on a guess."""
    end = Time(iers.IERS_Auto.open()["MJD"][-1].value, format="mjd")
    late = (end + 30 * u.day).isot[:19]
    with pytest.raises(ScenarioError, match=rf"night\.toml: start: {late} UTC is outside the IERS table bundled "
                                            r"with astropy \(1973-01-02 to "):
        schedule.plan(write(tmp_path, late, OJ287[0] + 'duration = "2 min"\n'))
    with pytest.raises(ScenarioError, match=r"scans\[0\]: OJ 287: .* UTC is past the end of the IERS table bundled "
                                            r"with astropy"):   # a scan that runs past it
        schedule.plan(write(tmp_path, (end - 1 * u.hour).isot[:19], OJ287[0] + 'duration = "2 h"\n'))
    soon = (end - 200 * u.day).isot[:10]      # in the table's predictions: planned
    path = tmp_path / "soon.toml"             # a circumpolar source (21..41 deg at Tianma), a TOML date-time
    path.write_text(f'start = {soon}T12:00:00Z\n[[scans]]\nsource = "near pole"\nra = "19h15m00s"\ndec = "80d"\n'
                    'duration = "1 min"\n')
    plan = schedule.plan(path)
    assert plan.utc_start == datetime.fromisoformat(f"{soon}T12:00:00+00:00")
    assert 21.0 < np.degrees(plan.elevation).min() < np.degrees(plan.elevation).max() < 41.1
