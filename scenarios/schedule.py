"""An observing schedule (a TOML file) as the table of az/el samples the telescope replays.

Why astropy: it is the library made for apparent positions (precession, nutation,
aberration, the IERS Earth orientation); it runs offline on the tables bundled with it
(``iers.conf.auto_download = False``). The site is the telescope model's
(plant/telescope/model.py TelescopeParams.tianma(): latitude, longitude; height 0 m, as the
kit has none). Refraction is left out (pressure 0), as the kit's sidereal profile does.

A schedule file::

    start = "2024-03-01T12:00:00"   # UTC: the night's t = 0, the antenna on the first source
    elevation_limit = "15 deg"     # optional; the lowest elevation a scan may reach
    keyhole = "80 deg"             # optional; the highest (near the zenith the azimuth rate diverges)
    [[scans]]
    source = "3C 279"
    ra = "12h56m11.17s"            # ICRS (or "194.0465 deg"); or body = "jupiter" instead of ra/dec
    dec = "-5d47m21.5s"
    duration = "10 min"
    start = "2024-03-01T12:30:00"  # optional: wait for it; without, the scan starts when the slew arrives

([requirements] and [wind] tables may follow: studies/night.py reads them, this module not.)

Between scans the antenna slews at the axis limits (the kit's trapezoidal slew, which
arrives where the source is at the arrival time), choosing the azimuth turn within the
cable wrap (plant/telescope/replay.py AZIMUTH_LIMITS) nearest the last one whose scan stays
inside the wrap; during a scan it tracks. A scan that cannot be observed (below the
elevation limit, above the keyhole, beyond the drives' rates or accelerations, beyond the
wrap, a start before the slew arrives, a handover from or to a slew the drives cannot
make, past a day from the first scan, an unknown body) is refused with the reason,
before anything is written (docs/bad-input.md lists each message).
"""
import math
import pathlib
import re
from dataclasses import dataclass
from datetime import datetime, timedelta, timezone

import numpy as np
from astropy.utils import iers

iers.conf.auto_download = False   # offline: the bundled IERS tables, never a download
iers.conf.auto_max_age = None     # and their predictions however old (UT1 drifts from them by ms a month: mas)
import astropy.units as u  # noqa: E402
from astropy.coordinates import AltAz, Angle, EarthLocation, SkyCoord, get_body  # noqa: E402
from astropy.time import Time  # noqa: E402
from scipy.interpolate import CubicSpline  # noqa: E402

from fmu_src import atomic  # noqa: E402
from plant.errors import InvalidInputError  # noqa: E402
from plant.telescope import model as telescope  # noqa: E402
from plant.telescope import replay  # noqa: E402
from scenarios.spec.parsing import parse_quantity  # noqa: E402
from scenarios.spec.text import ScenarioError, read_text, read_toml  # noqa: E402

SAMPLE_INTERVAL = 0.05    # s: the table's rows, 20 Hz as a telescope logs
ASTROPY_STEP = 5.0        # s: astropy positions this far apart, cubic-interpolated between (error < 1e-8 rad
#                           below the keyhole: (5/384) step^4 |x''''|; the tests measure it against astropy)
ELEVATION_LIMIT = math.radians(15.0)   # default lowest elevation of a scan (assumed observing practice)
KEYHOLE = math.radians(80.0)           # default highest elevation of a scan (assumed)
BODIES = ("sun", "moon", "mercury", "venus", "mars", "jupiter", "saturn", "uranus", "neptune")   # astropy's get_body
STUDY_KEYS = ("requirements", "wind")   # tables a night file holds for studies/night.py, not read here
HANDOVER_WINDOW = 10.0    # s either side of a slew's start and end checked as the replay checks a table
SLEW_ITERATIONS = 4       # slew target = the source at arrival: fixed-point iterations (converge to < 1e-9 s)
MAX_SPAN = 24 * 3600.0    # s: the longest schedule, first scan's start to last scan's end (a day at 20 Hz is
#                           the longest table the replay takes: plant/telescope/replay.py MAX_ROWS)


@dataclass(frozen=True)
class Scan:
    """One scheduled scan: name, and its slew start, track start and end [s from the night's start]."""

    source: str
    slew_start: float
    start: float
    end: float


@dataclass(frozen=True)
class Night:
    """A schedule computed: the UTC start, the scans, and the table (times [s], astronomical
    azimuth unwrapped and elevation [rad]) at SAMPLE_INTERVAL."""

    utc_start: datetime
    scans: tuple
    time: np.ndarray
    azimuth: np.ndarray
    elevation: np.ndarray

    def write(self, path):
        """The table as CSV (deg), the scans as '#' lines above it; written whole or not at all."""
        path = pathlib.Path(path)
        lines = [f"# schedule from {self.utc_start.isoformat()} UTC (t = 0); astronomical azimuth, unwrapped"]
        lines += [f"# scan {i + 1}: {s.source}: slew from {s.slew_start:.3f} s, track {s.start:.3f} s to "
                  f"{s.end:.3f} s" for i, s in enumerate(self.scans)]
        lines.append("time [s],azimuth [deg],elevation [deg]")
        lines += [f"{t:.3f},{a:.9f},{e:.9f}" for t, a, e in zip(self.time, np.degrees(self.azimuth),
                                                                   np.degrees(self.elevation))]
        with atomic.replacing(path) as f:
            f.write(("\n".join(lines) + "\n").encode())
        return path


def site(params):
    """The telescope model's site as an astropy EarthLocation (height 0 m: the kit has none)."""
    return EarthLocation(lat=params.latitude * u.rad, lon=params.longitude * u.rad, height=0.0 * u.m)


def altaz(params, target, utc_start, t):
    """(astronomical azimuth in [0, 2 pi), elevation) [rad] of ``target`` (a SkyCoord, or a body's
    name) at t [s] after utc_start, from astropy (no refraction)."""
    times = Time(utc_start) + np.atleast_1d(t) * u.s
    frame = AltAz(obstime=times, location=site(params), pressure=0 * u.hPa)
    first, end = _iers_range()
    if times.mjd.max() > end:   # astropy would go on with the last value, up to 0.9 s of UT1: 13 arcsec
        raise InvalidInputError(f"{times[times.mjd.argmax()].isot[:19]} UTC is past the end of the IERS table "
                                f"bundled with astropy ({Time(end, format='mjd').isot[:10]}): the Earth's "
                                "orientation is not known offline that far ahead")
    if times.mjd.min() < first:
        raise InvalidInputError(f"{times[times.mjd.argmin()].isot[:19]} UTC is before the start of the IERS table "
                                f"bundled with astropy ({Time(first, format='mjd').isot[:10]}): the Earth's "
                                "orientation is not known offline that far back")
    coord = get_body(target, times, site(params)) if isinstance(target, str) else target
    position = coord.transform_to(frame)
    return np.asarray(position.az.rad, dtype=float), np.asarray(position.alt.rad, dtype=float)


def _iers_range():
    """(first, last) MJD of the bundled IERS table: the times whose Earth orientation is known offline."""
    mjd = iers.IERS_Auto.open()["MJD"]
    return mjd[0].value, mjd[-1].value


def _utc(source, key, text):
    """A UTC datetime from text ("2024-03-01T12:00:00", "...Z", an offset) or a TOML date-time."""
    try:
        value = datetime.fromisoformat(text.replace("Z", "+00:00")) if isinstance(text, str) else None
    except ValueError:
        value = None
    if isinstance(text, datetime):
        value = text
    if value is None:
        raise ScenarioError(source, key, f"{text!r} is not a UTC time such as \"2024-03-01T12:00:00\"")
    return value.replace(tzinfo=timezone.utc) if value.tzinfo is None else value.astimezone(timezone.utc)


def _target(source, key, scan):
    """A SkyCoord (ICRS) or a solar-system body's name, checked."""
    if "body" in scan:
        body = scan["body"]
        if "ra" in scan or "dec" in scan:
            raise ScenarioError(source, key, "give either body or ra and dec, not both")
        if str(body).lower() not in BODIES:   # astropy also knows "earth" and its barycentre: not in the sky
            raise ScenarioError(source, key, f"body {body!r} is not a solar-system body the telescope can point at "
                                f"({', '.join(BODIES)})")
        return str(body).lower()
    if "ra" not in scan or "dec" not in scan:
        raise ScenarioError(source, key, "a scan needs ra and dec (ICRS) or body")
    angles = []
    for name in ("ra", "dec"):
        try:
            angles.append(Angle(scan[name]))
        except (ValueError, TypeError, u.UnitsError):
            raise ScenarioError(source, f"{key}.{name}", f"{scan[name]!r} is not an angle such as \"12h56m11.17s\" "
                                "or \"194.05 deg\"") from None
    if not 0 <= angles[0].deg < 360:
        raise ScenarioError(source, f"{key}.ra", f"{scan['ra']!r} is outside [0h, 24h) (0 to 360 deg)")
    if abs(angles[1].deg) > 90:
        raise ScenarioError(source, f"{key}.dec", f"{scan['dec']!r} is outside [-90, 90] deg")
    return SkyCoord(ra=angles[0], dec=angles[1], frame="icrs")


def _turn(azimuth, near):
    """azimuth + k 2 pi nearest ``near``."""
    return azimuth + 2 * math.pi * round((near - azimuth) / (2 * math.pi))


def _track(params, target, utc_start, t0, t1):
    """Unwrapped azimuth and elevation splines of target over [t0, t1] (astropy every ASTROPY_STEP)."""
    nodes = np.linspace(t0, t1, max(4, int(math.ceil((t1 - t0) / ASTROPY_STEP)) + 1))
    az, el = altaz(params, target, utc_start, nodes)
    return CubicSpline(nodes, np.unwrap(az)), CubicSpline(nodes, el)


def _refuse(source, key, name, why):
    raise ScenarioError(source, key, f"{name} cannot be observed: {why}")


def _slew_in(params, target, utc_start, t, pointing, turn, at=None):
    """(slew start, arrival, aim) of the slew from ``pointing`` (free from t) to where the
    source is when it arrives: as soon as it can, or arriving ``at``; the aim's azimuth on
    the turn nearest the pointing plus ``turn``."""
    arrive = t if at is None else at
    for _ in range(SLEW_ITERATIONS):
        az, el = (float(v[0]) for v in altaz(params, target, utc_start, arrive))
        aim = (_turn(az, pointing[0]) + turn, min(max(el, 0.0), math.pi / 2))   # the track's check refuses el < 0
        duration = telescope.slew_duration(params, pointing, aim)
        if at is None:
            arrive = t + duration
    return arrive - duration, arrive, aim


def _scan_track(params, target, utc_start, t0, duration, near, low, high, refuse):
    """(azimuth spline, elevation spline, azimuth shift) of a scan from t0, the shift the
    turn nearest ``near`` (else another) whose track stays inside the cable wrap; ``refuse``
    (why) for a track outside the elevations, the wrap or the drive's azimuth rate."""
    az_spline, el_spline = _track(params, target, utc_start, t0, t0 + duration)
    check = np.linspace(t0, t0 + duration, max(3, int(duration / ASTROPY_STEP) + 1))
    az, el = az_spline(check), el_spline(check)
    bad = np.flatnonzero((el < low) | (el > high))
    if bad.size:
        when = (Time(utc_start) + check[bad[0]] * u.s).isot[:19]
        never = ""
        if not isinstance(target, str):   # a fixed source culminates at 90 deg - |latitude - dec| (to arcmin)
            top = 90.0 - abs(math.degrees(params.latitude) - target.dec.deg)
            never = (f"; at the site's latitude {math.degrees(params.latitude):.2f} deg it culminates at {top:.2f} "
                     "deg: it is never above the elevation limit" if top < math.degrees(low) else "")
        limits = f"[{math.degrees(low):g}, {math.degrees(high):g}] deg (elevation_limit, keyhole)"
        if bad[0] > 0:   # it set or entered the keyhole during the scan
            refuse(f"its elevation leaves {limits} at {when} UTC, {(check[bad[0]] - t0) / 60:.1f} min into the "
                   f"scan of {duration / 60:.1f} min")
        refuse(f"its elevation is {math.degrees(el[bad[0]]):.2f} deg at {when} UTC, outside {limits}{never}")
    for axis, spline, limits in (("azimuth", az_spline, (params.az_rate_max, params.az_acc_max)),
                                 ("elevation", el_spline, (params.el_rate_max, params.el_acc_max))):
        for order, (what, unit), limit in zip((1, 2), (("rate", "deg/s"), ("acceleration", "deg/s2")), limits):
            worst = np.abs(spline(check, order)).max()
            if worst > limit:
                refuse(f"its {axis} {what} reaches {math.degrees(worst):.3g} {unit}, beyond the drive's "
                       f"{math.degrees(limit):.3g} {unit} (the keyhole near the zenith)")
    wrap_low, wrap_high = replay.AZIMUTH_LIMITS
    nearest = _turn(az[0], near) - az[0]
    for turn in (0.0, 2 * math.pi, -2 * math.pi):
        if wrap_low <= az.min() + nearest + turn and az.max() + nearest + turn <= wrap_high:
            return az_spline, el_spline, nearest + turn, turn
    refuse(f"its track crosses the cable wrap's limits [{math.degrees(wrap_low):g}, {math.degrees(wrap_high):g}] "
           "deg on every turn")


def plan(path, params=None):
    """The Night of a schedule file for ``params`` (TelescopeParams, default Tianma's)."""
    params = params or telescope.TelescopeParams.tianma()
    path = pathlib.Path(path)
    source = str(path)
    data = read_toml(read_text(path, what="schedule"), source)
    unknown = set(data) - {"start", "elevation_limit", "keyhole", "scans", "name", "description", *STUDY_KEYS}
    if unknown:
        raise ScenarioError(source, sorted(unknown)[0], "unknown key (start, elevation_limit, keyhole, scans, name, "
                            f"description; {', '.join(STUDY_KEYS)} for studies/night.py)")
    if "start" not in data:
        raise ScenarioError(source, "start", "missing: a schedule needs its UTC start, such as \"2024-03-01T12:00:00\"")
    utc_start = _utc(source, "start", data["start"])
    first, end = (Time(mjd, format="mjd").to_datetime(timezone=timezone.utc) for mjd in _iers_range())
    if not first <= utc_start <= end:
        raise ScenarioError(source, "start", f"{utc_start.isoformat()[:19]} UTC is outside the IERS table bundled "
                            f"with astropy ({first.isoformat()[:10]} to {end.isoformat()[:10]}): the Earth's "
                            "orientation is not known offline then")
    low = parse_quantity(source, "elevation_limit", data.get("elevation_limit", ELEVATION_LIMIT), "rad")
    high = parse_quantity(source, "keyhole", data.get("keyhole", KEYHOLE), "rad")
    if not replay.ELEVATION_LIMITS[0] <= low < high <= replay.ELEVATION_LIMITS[1]:
        raise ScenarioError(source, "elevation_limit", f"elevation_limit {math.degrees(low):g} deg and keyhole "
                            f"{math.degrees(high):g} deg must rise within the axis range "
                            f"[{math.degrees(replay.ELEVATION_LIMITS[0]):g}, "
                            f"{math.degrees(replay.ELEVATION_LIMITS[1]):g}] deg")
    scans = data.get("scans")
    if not isinstance(scans, list) or not scans:
        raise ScenarioError(source, "scans", "a schedule needs at least one [[scans]] table")
    pieces, done, t, pointing = [], [], 0.0, None
    for i, scan in enumerate(scans):
        key = f"scans[{i}]"
        if not isinstance(scan, dict):
            raise ScenarioError(source, key, "expected a table")
        extra = set(scan) - {"source", "ra", "dec", "body", "duration", "start"}
        if extra:
            raise ScenarioError(source, f"{key}.{sorted(extra)[0]}", "unknown key (source, ra, dec, body, duration, "
                                "start)")
        name = str(scan.get("source", scan.get("body", f"scan {i + 1}")))
        target = _target(source, key, scan)
        if "duration" not in scan:
            raise ScenarioError(source, f"{key}.duration", "a scan needs its duration")
        duration = parse_quantity(source, f"{key}.duration", scan["duration"], "s")
        if not duration > 0:
            raise ScenarioError(source, f"{key}.duration", f"{scan['duration']!r} must be > 0")
        at = (_utc(source, f"{key}.start", scan["start"]) - utc_start).total_seconds() if "start" in scan else None
        if at is not None and at < t:
            _refuse(source, key, name, f"its start {scan['start']} is before " + (
                f"the last scan ends ({t:.1f} s after the schedule's start)" if done else "the schedule's start"))
        first_start = done[0].start if done else (at or 0.0)
        ends = (t if at is None else at) + duration
        if ends - first_start > MAX_SPAN:
            _refuse(source, key, name, f"it would end {(ends - first_start) / 3600:.4g} h after the first scan's "
                    f"start, beyond the {MAX_SPAN / 3600:g} h a schedule may span (the longest table the "
                    "replay takes: a day at 20 Hz)")

        def refuse(why, key=key, name=name):
            _refuse(source, key, name, why)
        try:
            t, pointing = _plan_scan(params, scan, target, name, duration, at, utc_start, low, high, t, pointing,
                                     pieces, done, refuse)
        except InvalidInputError as exc:
            raise ScenarioError(source, key, f"{name}: {exc}") from None
        if t - done[0].start > MAX_SPAN:   # the slew before it counted
            refuse(f"it would end {(t - done[0].start) / 3600:.4g} h after the first scan's start, beyond the "
                   f"{MAX_SPAN / 3600:g} h a schedule may span (the longest table the replay takes: a day at 20 Hz)")
    night = _sample(params, utc_start, pieces, done)
    _check_handovers(night, params, source)
    return night


def _check_handovers(night, params, source):
    """ScenarioError for a scan whose slew hands over to its track (or takes over from the
    last one) with a rate step the replay's smoothed acceleration cannot pass: the slews
    start and end at rest, a track moves; near the zenith (a keyhole above ~88.5 deg) its
    azimuth rate is tenths of a deg/s. Each handover is checked as the replay checks the
    table (plant/telescope/replay.py), on the 20 s around it."""
    for i, scan in enumerate(night.scans[1:], start=1):
        for what, at in (("leaves the last scan", night.scans[i - 1].end), ("starts its track", scan.start)):
            rows = np.flatnonzero(np.abs(night.time - at) <= HANDOVER_WINDOW)
            table = replay.Table(night.time[rows], night.azimuth[rows], night.elevation[rows])
            try:
                replay.replay_table(table, params)
            except InvalidInputError as exc:
                k = int(np.searchsorted(night.time, at))
                step = [abs(np.diff(a[k - 2:k + 2])).max() / SAMPLE_INTERVAL for a in (night.azimuth, night.elevation)]
                _refuse(source, f"scans[{i}]", scan.source, f"its slew {what} at rest while the track moves at "
                        f"{math.degrees(step[0]):.3g} deg/s in azimuth, {math.degrees(step[1]):.3g} deg/s in "
                        f"elevation: a step the drives cannot make ({_problem(exc)}); lower the keyhole")


def _problem(exc):
    """The first problem of a replay refusal without its rows (they are an excerpt's)."""
    return re.sub(r"^rows? [\d-]+: ", "", str(exc).split(" problem(s): ", 1)[-1].split("; ")[0])


def _plan_scan(params, scan, target, name, duration, at, utc_start, low, high, t, pointing, pieces, done, refuse):
    """One scan's slew (from the second on) and track appended to pieces and done; returns
    the time it ends and the pointing there."""
    if pointing is None:   # the night starts on the first source, on the turn nearest the wrap's middle
        arrive = at or 0.0
        az_spline, el_spline, shift, _ = _scan_track(params, target, utc_start, arrive, duration,
                                                     sum(replay.AZIMUTH_LIMITS) / 2, low, high, refuse)
        slew_start = arrive
    else:
        arrive = _slew_in(params, target, utc_start, t, pointing, 0.0, at)[1]
        turn = _scan_track(params, target, utc_start, arrive, duration, pointing[0], low, high, refuse)[3]
        slew_start, arrive, aim = _slew_in(params, target, utc_start, t, pointing, turn, at)
        if slew_start < t - 1e-6:
            refuse(f"its start {scan['start']} is before the slew from the last scan can arrive "
                   f"({t + arrive - slew_start:.1f} s after the schedule's start)")
        az_spline, el_spline, shift, _ = _scan_track(params, target, utc_start, arrive, duration, aim[0], low,
                                                     high, refuse)
        pieces.append(("slew", slew_start, arrive, pointing, (float(az_spline(arrive)) + shift,
                                                              float(el_spline(arrive)))))
    pieces.append(("track", arrive, arrive + duration, (az_spline, el_spline, shift)))
    done.append(Scan(name, slew_start, arrive, arrive + duration))
    t = arrive + duration
    return t, (float(az_spline(t)) + shift, float(el_spline(t)))


def _sample(params, utc_start, pieces, scans):
    """The table at SAMPLE_INTERVAL from the first scan's start (the night's t = 0 from here
    on) to the last's end: slews (the kit's trapezoids), tracks, and holds between them."""
    offset = scans[0].start
    t = np.arange(offset, scans[-1].end + SAMPLE_INTERVAL / 2, SAMPLE_INTERVAL)
    az, el = np.full(t.size, np.nan), np.full(t.size, np.nan)
    for kind, t0, t1, *what in pieces:
        inside = (t >= t0) & (t <= t1)
        if not inside.any():
            continue
        if kind == "slew":
            axes = telescope.slew(params, what[0], what[1], t[inside] - t0)
            az[inside], el[inside] = axes.azimuth, axes.E
        else:
            az_spline, el_spline, shift = what[0]
            az[inside], el[inside] = az_spline(t[inside]) + shift, el_spline(t[inside])
    for k in np.flatnonzero(np.isnan(az)):   # holds (before a timed scan's slew): the last pointing
        az[k], el[k] = az[k - 1], el[k - 1]
    shifted = tuple(Scan(s.source, s.slew_start - offset, s.start - offset, s.end - offset) for s in scans)
    return Night(utc_start + timedelta(seconds=offset), shifted, t - offset, az, el)
