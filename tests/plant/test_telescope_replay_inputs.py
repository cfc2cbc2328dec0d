"""Every defect class of a pointing log, as a file read by plant/telescope/replay.py load()
(the path a scenario, the pythonfmu Telescope and ``python -m fmu_src.replay_table`` take):
each refused naming the row or the key and the reason, or handled as docs/bad-input.md
says. The truths for the handled ones: the same motion logged without the defect (a
wrap-aware azimuth in deg, times from 0), replayed; and the analytic slew it was sampled from."""
import dataclasses
import re

import numpy as np
import pytest

from plant.errors import InvalidInputError
from plant.telescope import replay as rp
from plant.telescope.model import TelescopeParams, replay_track, slew, slew_duration

P = TelescopeParams.tianma()
DEG = np.pi / 180
J, H = 0.25 * DEG, rp.SMOOTHING_TIME
HEADER = "time [s],azimuth [deg],elevation [deg]"


def sampled(start=(10 * DEG, 30 * DEG), target=(40 * DEG, 50 * DEG), params=P, hold=5.0):
    """(t, azimuth, elevation) [s, rad] of a slew sampled at 20 Hz from hold s of rest before it to 5 s after."""
    t = np.arange(-hold, slew_duration(params, start, target) + 5.0, 0.05)
    axes = slew(params, start, target, t)
    return t + hold, axes.azimuth, axes.E


def csv_text(t, az, el, header=HEADER, scale=(1.0, 1 / DEG, 1 / DEG)):
    return header + "\n" + "\n".join(f"{float(a * scale[0])!r},{float(b * scale[1])!r},{float(c * scale[2])!r}"
                                     for a, b, c in zip(t, az, el)) + "\n"


def edited_rows(edit):
    """The slew's CSV with ``edit`` (t, az, el arrays, in s and deg) applied."""
    t, az, el = sampled()
    az, el = np.degrees(az), np.degrees(el)
    edit(t, az, el)
    return csv_text(t, az, el, scale=(1.0, 1.0, 1.0))


def with_cell(row, column, cell):
    """The slew's CSV with data row ``row`` (1-based), column ``column`` (0-based) written as ``cell``."""
    lines = edited_rows(lambda t, az, el: None).splitlines()
    cells = lines[row].split(",")
    cells[column] = cell
    lines[row] = ",".join(cells)
    return "\n".join(lines) + "\n"


def noisy(sigma):
    t, az, el = sampled()
    rng = np.random.default_rng(1)
    return csv_text(t, az + sigma * rng.normal(size=t.size), el + sigma * rng.normal(size=t.size))


def fast(**limits):
    """A slew at drives faster than Tianma's (the log's rate or acceleration passes P's)."""
    return csv_text(*sampled(params=dataclasses.replace(P, **limits)))


def swap(t, az, el):
    t[100], t[101] = t[101], t[100]


def npz(path, **arrays):
    np.savez(path, **arrays)
    return path.read_bytes()


T, AZ, EL = sampled()
SI = {"time [s]": T, "azimuth [rad]": AZ, "elevation [rad]": EL}

# (defect class, the file's suffix, its contents (text, or bytes: a callable of the folder),
#  the message's pattern: the row or key and the reason)
REFUSED = [
    ("rows out of order", ".csv", edited_rows(swap),
     r"1 problem\(s\): row 102: time 5 s goes back from row 101's 5\.05 s \(out of order\)$"),
    ("a duplicate time", ".csv", edited_rows(lambda t, az, el: t.__setitem__(200, t[199])),
     r"row 201: time 9\.95 s repeats row 200's \(a duplicate time\)"),
    ("a gap beyond the bound", ".csv", edited_rows(lambda t, az, el: t.__setitem__(slice(500, None), t[500:] + 3.0)),
     r"rows 500-501: a gap of 3\.05 s from 24\.95 s, more than the 1 s the spline may bridge"),
    ("an azimuth beyond the cable wrap", ".csv", edited_rows(lambda t, az, el: az.__setitem__(slice(None), az + 450)),
     r"row 1: azimuth 460 deg \(unwrapped\) is outside the cable wrap \[-90, 450\] deg; row 2: .*and \d+ more"),
    ("an elevation below its limit", ".csv", edited_rows(lambda t, az, el: el.__setitem__(800, 2.0)),
     r"1 problem\(s\): row 801: elevation 2 deg is outside \[5, 90\] deg"),
    ("an elevation beyond the zenith", ".csv", edited_rows(lambda t, az, el: el.__setitem__(10, 90.5)),
     r"row 11: elevation 90\.5 deg is outside \[5, 90\] deg"),
    ("a rate beyond the drive's limit", ".csv", fast(az_rate_max=1.0 * DEG),
     r"rows \d+-\d+: the smoothed azimuth rate up to 1\.0\d* deg/s passes the drive's 0\.5 deg/s \(\+8% allowed\)"),
    ("an acceleration beyond the drive's limit", ".csv", fast(el_acc_max=0.5 * DEG),
     r"2 problem\(s\): rows 101-112: the smoothed elevation acceleration up to 0\.3\d* deg/s2 passes the drive's "
     r"0\.25 deg/s2 \(\+8% allowed\); rows 14\d\d-14\d\d: "),    # the slew's start (row 101: 5 s) and its end
    ("noise beyond what the smoothing keeps within the drives", ".csv", noisy(0.05 * DEG),
     r"rows? \d+(-\d+)?: the smoothed (azimuth|elevation) (rate|acceleration) (up to )?[\d.]+ deg/s2? passes"),
    ("a NaN cell", ".csv", with_cell(8, 2, "nan"), r"1 problem\(s\): row 8: elevation is nan, not a finite number"),
    ("an inf cell", ".csv", with_cell(9, 1, "-inf"), r"row 9: azimuth is -inf, not a finite number"),
    ("an empty cell", ".csv", with_cell(3, 1, ""), r"row 3, column 'azimuth \[deg\]': is empty$"),
    ("a cell that is not a number", ".csv", with_cell(4, 0, "12:00:01"),
     r"row 4, column 'time \[s\]': '12:00:01' is not a number$"),
    ("a short row", ".csv", with_cell(5, 2, "30\n1.0,2.0"), r"row 6 has 2 values, the header 3$"),
    ("a missing unit", ".csv", csv_text(T, AZ, EL, header="time [s],azimuth,elevation [deg]"),
     r"column 'azimuth' needs its unit in brackets, one of deg, rad, arcsec; got 'azimuth'$"),
    ("an unknown unit", ".csv", csv_text(T, AZ, EL, header="time [s],azimuth [degree],elevation [deg]"),
     r"column 'azimuth' needs its unit in brackets, one of deg, rad, arcsec; got 'azimuth \[degree\]'$"),
    ("an unknown time unit", ".csv", csv_text(T, AZ, EL, header="time [h],azimuth [deg],elevation [deg]"),
     r"column 'time' needs its unit in brackets, one of s, ms; got 'time \[h\]'$"),
    ("radians under a deg header", ".csv", csv_text(T, AZ, EL, scale=(1.0, 1.0, 1.0)),
     r"elevation: every row is outside \[5, 90\] deg as \[deg\] \(0\.523\d* to 0\.872\d*\); read as \[rad\] they "
     r"fit: is the header's unit right\?$"),
    ("degrees under a rad header", ".csv", csv_text(T, AZ, EL, header="time [s],azimuth [rad],elevation [rad]"),
     r"elevation: every row is outside \[5, 90\] deg as \[rad\] \(30 to 50\); read as \[deg\] they fit"),
    ("degrees under an arcsec header", ".csv",
     csv_text(T, AZ, EL, header="time [s],azimuth [arcsec],elevation [arcsec]"),
     r"elevation: every row is outside .* as \[arcsec\] \(30 to 50\); read as \[deg\] they fit"),
    ("a column twice", ".csv", csv_text(T, AZ, EL, header="time [s],azimuth [deg],azimuth [rad]"),
     r"needs the columns time, azimuth, elevation once each, got time, azimuth, azimuth$"),
    ("an unknown column", ".csv", csv_text(T, AZ, EL, header="time [s],az [deg],elevation [deg]"),
     r"column 'az \[deg\]' is not one of time, azimuth, elevation"),
    ("an empty file", ".csv", "",
     r"empty: no header line \(time \[s\],azimuth \[deg\],elevation \[deg\]\) and no rows"),
    ("comments only", ".csv", "# a log\n\n# nothing\n", r"empty: no header line"),
    ("a header without rows", ".csv", HEADER + "\n", r"1 problem\(s\): 0 rows: a replay needs at least 5$"),
    ("one row", ".csv", HEADER + "\n0,10,30\n", r"1 row: a replay needs at least 5$"),
    ("four rows (scipy's spline needs five)", ".csv", HEADER + "\n" + "".join(f"{k / 20},10,30\n" for k in range(4)),
     r"4 rows: a replay needs at least 5$"),
    ("columns separated by semicolons", ".csv", csv_text(T, AZ, EL).replace(",", ";"),
     r"the header 'time \[s\];azimuth \[deg\];elevation \[deg\]' is separated by ';'; a replay table's columns "
     r"are separated by commas$"),
    ("a digit separator", ".csv", with_cell(4, 1, "1_0"), r"row 4, column 'azimuth \[deg\]': '1_0' is not a number$"),
    ("a binary file", ".csv", b"\x00\x01MBREPLAY?", r"a binary file \(NUL byte at offset 0\), not a CSV table"),
    ("a file not UTF-8", ".csv", (HEADER + "\n0,10\xb0,30\n").encode("latin-1"),
     r"not UTF-8 text \(byte 0xb0 at offset 43\)"),
    ("an npz with wrong keys", ".npz", lambda d: npz(d / "k.npz", t=T, az=AZ, el=EL),
     r"column 't' is not one of time, azimuth, elevation \(written 'name \[unit\]'\)"),
    ("an npz without a column", ".npz", lambda d: npz(d / "k.npz", **{"time [s]": T, "azimuth [rad]": AZ}),
     r"needs the columns time, azimuth, elevation once each, got time, azimuth$"),
    ("an npz without units", ".npz", lambda d: npz(d / "k.npz", time=T, azimuth=AZ, elevation=EL),
     r"column 'time' needs its unit in brackets, one of s, ms; got 'time'"),
    ("an npz of a 2-D column", ".npz", lambda d: npz(d / "k.npz", **{**SI, "azimuth [rad]": np.c_[AZ, AZ]}),
     r"array 'azimuth \[rad\]' is float64 of shape \(\d+, 2\); a column is a 1-D array of numbers"),
    ("an npz of text", ".npz", lambda d: npz(d / "k.npz", **{**SI, "time [s]": T.astype(str)}),
     r"array 'time \[s\]' is <U\d+ of shape .*a column is a 1-D array of numbers"),
    ("an npz of objects (pickled)", ".npz",
     lambda d: npz(d / "k.npz", **{**SI, "time [s]": np.array([T], dtype=object)}),
     r"not an npz file of numeric arrays \(Object arrays cannot be loaded when allow_pickle=False\)"),
    ("an npz of other lengths", ".npz", lambda d: npz(d / "k.npz", **{**SI, "time [s]": T[:-1]}),
     r"the columns have different lengths \(\d+, \d+, \d+\)"),
    ("an npz that is not one", ".npz", HEADER + "\n0,1,2\n", r"not an npz file of numeric arrays"),
]


@pytest.mark.parametrize("what, suffix, contents, message", REFUSED, ids=[r[0] for r in REFUSED])
def test_a_defect_is_refused_naming_its_row_and_reason(tmp_path, what, suffix, contents, message):
    path = tmp_path / f"log{suffix}"
    contents = contents(tmp_path) if callable(contents) else contents
    path.write_bytes(contents if isinstance(contents, bytes) else contents.encode())
    with pytest.raises(InvalidInputError) as error:
        rp.load(path, P)
    text = str(error.value)
    assert text.startswith(str(path)), text
    assert re.search(message, text), (what, text)


def test_a_folder_a_missing_file_and_a_huge_one_are_refused(tmp_path, monkeypatch):
    """Before anything is read: a folder, a file that is not there, a file over MAX_BYTES,
    a table of more than MAX_ROWS rows (the limits lowered here; shipped: a day at 20 Hz)."""
    with pytest.raises(InvalidInputError, match=r"is not a regular file \(a folder, a device or a pipe\)"):
        rp.load(tmp_path, P)
    with pytest.raises(InvalidInputError, match=r"replay table '.*none\.csv' does not exist"):
        rp.load(tmp_path / "none.csv", P)
    path = tmp_path / "log.csv"
    path.write_text(csv_text(T, AZ, EL))
    assert rp.MAX_ROWS == 24 * 3600 * 20 + 1 and rp.MAX_BYTES == 256 << 20
    monkeypatch.setattr(rp, "MAX_ROWS", T.size - 1)
    with pytest.raises(InvalidInputError, match=rf"{T.size} rows, more than the {T.size - 1} \(a day at 20 Hz\)"):
        rp.read_table(path)
    npz = tmp_path / "log.npz"
    np.savez(npz, **SI)
    with pytest.raises(InvalidInputError, match=rf"{T.size} rows, more than the {T.size - 1}"):
        rp.load(npz, P)
    monkeypatch.setattr(rp, "MAX_BYTES", 1 << 20)
    path.write_bytes(b"#" * ((1 << 20) + (2 << 20)))
    with pytest.raises(InvalidInputError, match=r"3 MiB, larger than the 1 MiB a replay table may be"):
        rp.load(path, P)


def replayed(text, tmp_path, name="log.csv"):
    path = tmp_path / name
    path.write_text(text)
    return rp.load(path, P)


def axes_of(replay, t=None):
    return replay_track(P, replay, T[1:-1] if t is None else t)


@pytest.mark.parametrize("start, target, offset, wraps, turns", [
    ((350 * DEG, 40 * DEG), (370 * DEG, 45 * DEG), 0.0, 1, 0),      # up through north, logged in [0, 360)
    ((10 * DEG, 40 * DEG), (-10 * DEG, 45 * DEG), 0.0, 1, 0),       # down through north, logged in [0, 360)
    ((170 * DEG, 40 * DEG), (190 * DEG, 45 * DEG), np.pi, 1, 0),    # through south, logged in [-180, 180)
    ((200 * DEG, 40 * DEG), (220 * DEG, 45 * DEG), np.pi, 0, 1),    # logged in [-180, 180) as -160..-140 deg
])
def test_a_wrap_at_360_is_handled_in_either_direction_and_convention(tmp_path, start, target, offset, wraps, turns):
    """A log written modulo 360 deg ([0, 360), or [-180, 180): offset pi) replays as the
    continuous motion: the rows of each wrap listed, the track the slew's within the
    docs' smoothing bound; a log without the wrap's turn is moved by whole turns into
    the cable wrap (Replay.turns), the same motion."""
    t, az, el = sampled(start, target)
    logged = np.mod(az + offset, 2 * np.pi) - offset
    replay = replayed(csv_text(t, logged, el), tmp_path)
    steps = np.flatnonzero(np.abs(np.diff(logged)) > np.pi)
    assert replay.wraps == tuple(int(i) + 2 for i in steps) and len(steps) == wraps
    assert replay.turns == turns
    got, truth = axes_of(replay, t), slew(P, start, target, t - 5.0)
    error = got.azimuth - truth.azimuth - 2 * np.pi * round((got.azimuth[0] - truth.azimuth[0]) / (2 * np.pi))
    assert np.abs(error).max() <= 0.322 * J * H ** 2
    assert rp.AZIMUTH_LIMITS[0] <= got.azimuth.min() and got.azimuth.max() <= rp.AZIMUTH_LIMITS[1]
    wrap_aware = replayed(csv_text(t, az, el), tmp_path, "aware.csv")
    # the same motion: to the rounding of the 2 pi-shifted values, differenced twice (measured 4e-12)
    np.testing.assert_allclose(got.A_ddot, axes_of(wrap_aware, t).A_ddot, rtol=0, atol=1e-10)


def test_a_wrap_aware_log_past_the_wrap_is_not_moved(tmp_path):
    """A log that carries the turn (values beyond 360 deg) and leaves the wrap is refused,
    not moved: only a log written modulo 360 deg is taken on another turn."""
    t, az, el = sampled((440 * DEG, 40 * DEG), (460 * DEG, 45 * DEG))
    with pytest.raises(InvalidInputError, match=r"azimuth 450\.\d+ deg \(unwrapped\) is outside the cable wrap"):
        replayed(csv_text(t, az, el), tmp_path)


def test_units_comments_and_epoch_times_replay_as_the_plain_log(tmp_path):
    """The same slew written in arcsec, rad, ms, with '#' lines and blank lines between its
    rows, with quoted cells, a header in capitals and CRLF line ends, or with times from a
    Unix epoch (1.7e9 s): the same motion as the plain log."""
    plain = axes_of(replayed(csv_text(T, AZ, EL), tmp_path, "plain.csv"))
    arcsec = csv_text(T * 1e3, AZ, EL, header="time [ms],azimuth [arcsec],elevation [rad]",
                      scale=(1.0, 648000 / np.pi, 1.0))
    lines = csv_text(T, AZ, EL).splitlines()
    commented = "# encoder log\n\n" + "\n".join(line + ("\n# a note\n" if k % 50 == 0 else "")
                                               for k, line in enumerate(lines)) + "\n"
    quoted = "\r\n".join(",".join(f'"{cell}"' for cell in line.split(",")) for line in lines).replace(
        "time [s]", "Time [S]") + "\r\n"        # quoted cells, a header in other case, CRLF line ends
    for name, text in (("arcsec.csv", arcsec), ("commented.csv", commented), ("quoted.csv", quoted)):
        got = axes_of(replayed(text, tmp_path, name))
        np.testing.assert_allclose(got.azimuth, plain.azimuth, rtol=0, atol=1e-12, err_msg=name)
        np.testing.assert_allclose(got.E_ddot, plain.E_ddot, rtol=0, atol=1e-11, err_msg=name)
    epoch = replayed(csv_text(T + 1.7e9, AZ, EL), tmp_path, "epoch.csv")
    got = axes_of(epoch)          # the first time is t = 0 (2.4e-7 s is a double's resolution at 1.7e9 s)
    assert np.abs(got.azimuth - plain.azimuth).max() < 1e-9
    assert np.abs(got.A_ddot - plain.A_ddot).max() < 1e-6 * J


def test_small_noise_and_a_short_dropout_are_handled(tmp_path):
    """Encoder noise within the drives is smoothed (docs: 0.297 sigma / sqrt(r h^5) in
    acceleration), a dropout up to max_gap (1 s) is bridged: the track stays within the
    clean slew's smoothing bound plus the noise's share."""
    t, az, el = sampled()
    rng = np.random.default_rng(7)
    sigma = 2.0 / 3600 * DEG
    keep = np.ones(t.size, bool)
    keep[300:318] = False                         # 0.95 s without samples in the slew
    text = csv_text(t[keep], (az + sigma * rng.normal(size=t.size))[keep], (el + sigma * rng.normal(size=t.size))[keep])
    got, truth = axes_of(replayed(text, tmp_path), t), slew(P, (10 * DEG, 30 * DEG), (40 * DEG, 50 * DEG), t - 5.0)
    assert np.abs(got.azimuth - truth.azimuth).max() <= 0.322 * J * H ** 2 + 4 * 0.515 * sigma / np.sqrt(20 * H)
    assert np.abs(got.A_ddot - truth.A_ddot).max() <= 1.0 * J + 4 * 0.297 * sigma / np.sqrt(20 * H ** 5)


def test_a_spline_that_is_not_finite_is_refused_by_its_rows(monkeypatch):
    """A guard, not a seen case (times 1e-12 s apart still fit): were scipy's spline not
    finite on an interval, the rows are named here rather than the C refusing the spline."""
    real = rp._spline

    def broken(t, y, h):
        coef = real(t, y, h)
        coef[41, 2] = np.nan
        return coef
    monkeypatch.setattr(rp, "_spline", broken)
    with pytest.raises(InvalidInputError, match=r"1 problem\(s\): rows 42-43: the smoothing spline is not finite"):
        rp.replay_table(rp.Table(T, AZ, EL), P)
