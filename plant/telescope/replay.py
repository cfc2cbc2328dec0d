"""Replay a table of azimuth/elevation samples (a pointing log, a schedule's track) as the
telescope's motion: read it, check it row by row, smooth it into a spline the C evaluates.

Why a smoothing spline: the loop's feedforward sees the base's acceleration, the second
derivative of the logged angles. Interpolating 20 Hz encoder samples exactly turns their
noise into acceleration spikes (1 arcsec of noise at 20 Hz differenced twice is ~400
arcsec/s^2); a cubic smoothing spline (scipy's ``make_smoothing_spline``, knots at every
sample) has continuous rate and acceleration and removes what is faster than the smoothing
time h. With the penalty lam = r h^4 (r the sampling rate) it acts as Silverman's (1984)
equivalent kernel of bandwidth h, gain 1 / (1 + (w h)^4): a smooth motion is kept to
h^4 |x''''|, and the errors the docs state (docs/conventions/telescope.md, "Replaying a
table") follow from that kernel: at an acceleration step J, 0.161 J h^2 in angle,
0.354 J h in rate, J / 2 in acceleration (3.4 % overshoot); encoder noise sigma leaves
0.515, 0.297 and 0.297 sigma / sqrt(r h^(1, 3, 5)) in angle, rate and acceleration; a
rate or acceleration pulse at a drive's limit is passed by at most 6.7 % (LIMIT_MARGIN).

A table: columns ``time [s|ms]``, ``azimuth [deg|rad|arcsec]`` (astronomical, north
through east), ``elevation [deg|rad|arcsec]``, the unit in brackets in the header (CSV,
'#' lines ignored) or in the array names (npz). Its first time is the profile's t = 0.
Every defect class is refused with its row and reason or handled as docs/bad-input.md
says (a wrap at 360 deg, a log written modulo 360 deg, noise, short dropouts).

A prepared replay table is a Replay as bytes (prepared_bytes; fmu_src/replay_table.py
writes them, ``python -m fmu_src.replay_table LOG -o FILE``): what the native Telescope FMUs read, in C,
without scipy. Its layout (PREPARED_*): b"MBREPLAY", version (uint32), knot count n
(uint32), smoothing time [s] (float64), the n knots, the (n - 1, 8) coefficients, all
little-endian. load() takes a prepared table as it takes a log, so both FMUs evaluate the
same coefficients, bit for bit. The drives' limits are checked when it is prepared.
"""
import csv
import math
import pathlib
import zipfile
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from plant.errors import InvalidInputError

COLUMNS = ("time", "azimuth", "elevation")
UNITS = {"time": {"s": 1.0, "ms": 1e-3}, "angle": {"deg": math.pi / 180, "rad": 1.0, "arcsec": math.pi / 648000}}
SMOOTHING_TIME = 0.25    # s, h: the kernel's bandwidth (the docs' error figures are for it)
MAX_GAP = 1.0            # s, longest step between two rows the spline bridges (a dropout)
WRAP_JUMP = math.pi      # rad: an azimuth step larger than this between two rows is a 360 deg wrap
# Assumed axis ranges (no public Tianma figure): a cable wrap of 540 deg as large alt-az
# antennas have (GBT -90..450 deg), elevation from 5 deg (a typical lower limit) to the zenith.
AZIMUTH_LIMITS = (math.radians(-90.0), math.radians(450.0))
ELEVATION_LIMITS = (math.radians(5.0), math.radians(90.0))
LIMIT_MARGIN = 0.08      # the spline's rate and acceleration may pass a drive limit by this share:
#                          the kernel overshoots a pulse at the limit by up to 6.7 % (its positive
#                          lobe's area, 1.067), plus 1.3 % for noise and the table's ends
MIN_ROWS = 5             # scipy's smoothing spline needs 5 samples
MAX_ROWS = 1_728_001     # a day at 20 Hz, both ends: a longer table is refused before it is smoothed (~45 s
#                          per 720,000 rows)
MAX_BYTES = 256 << 20    # a CSV or npz file larger than this is refused before it is read (a day at 20 Hz: ~60 MiB)
SHOWN_PROBLEMS = 10      # problems listed in one error; the rest counted
PREPARED_MAGIC = b"MBREPLAY"
PREPARED_VERSION = 1
PREPARED_HEADER = np.dtype([("magic", "S8"), ("version", "<u4"), ("n", "<u4"), ("smoothing", "<f8")])
PREPARED_SUFFIX = ".mbreplay"
RESOURCE = "resource:"   # a Telescope FMU's replay_table "resource:<name>": a file in its resources folder


@dataclass(frozen=True)
class Table:
    """Times [s], astronomical azimuth and elevation [rad] of a table, as read (not checked)."""

    time: np.ndarray
    azimuth: np.ndarray
    elevation: np.ndarray
    source: str = "table"
    units: dict | None = None    # column -> the unit its header wrote (None: given in SI, not read from a file)


def _column(name, header, source):
    """(column, SI factor, unit) of a header cell 'name [unit]'."""
    text = header.strip()
    key, _, unit = text.partition("[")
    key, unit = key.strip().lower(), unit.rstrip("]").strip().lower()
    for separator in (";", "\t"):
        if separator in text:
            raise InvalidInputError(f"{source}: the header {text!r} is separated by {separator!r}; a replay table's "
                                    "columns are separated by commas")
    if key not in COLUMNS:
        raise InvalidInputError(f"{source}: column {text!r} is not one of {', '.join(COLUMNS)} "
                                "(written 'name [unit]')")
    units = UNITS["time" if key == "time" else "angle"]
    if unit not in units:
        raise InvalidInputError(f"{source}: column {key!r} needs its unit in brackets, one of "
                                f"{', '.join(units)}; got {text!r}")
    return key, units[unit], unit


def read_table(path):
    """A Table from a CSV or npz file (units in the header or the arrays' names);
    InvalidInputError for a file that is missing, not a regular file, larger than
    MAX_BYTES, empty, binary or not UTF-8 (a CSV), not an npz of numeric arrays (an npz), or
    whose columns are not time, azimuth, elevation once each with their units."""
    path = pathlib.Path(path)
    source = str(path)
    if not path.exists():
        raise InvalidInputError(f"replay table {source!r} does not exist")
    if not path.is_file():
        raise InvalidInputError(f"replay table {source!r} is not a regular file (a folder, a device or a pipe)")
    size = path.stat().st_size
    if size > MAX_BYTES:
        raise InvalidInputError(f"{source}: {size >> 20} MiB, larger than the {MAX_BYTES >> 20} MiB a replay table "
                                f"may be (a day at 20 Hz is ~60 MiB of CSV): cut it into runs")
    named = _npz_columns(path, source) if path.suffix.lower() == ".npz" else _csv_columns(path, source)
    found = [key for key, _, _ in named]
    if sorted(found) != sorted(COLUMNS):
        raise InvalidInputError(f"{source}: needs the columns {', '.join(COLUMNS)} once each, got "
                                f"{', '.join(found) or 'none'}")
    si = {key: array * factor for (key, factor, _), array in named.items()}
    return Table(si["time"], si["azimuth"], si["elevation"], source, {key: unit for key, _, unit in named})


def _npz_columns(path, source):
    """{(column, SI factor, unit): values} of an npz file: one 1-D numeric array per column."""
    try:
        data = np.load(path, allow_pickle=False)
        if not isinstance(data, np.lib.npyio.NpzFile):
            raise ValueError(f"one {type(data).__name__}, not named arrays")
        with data:
            arrays = {name: data[name] for name in data.files}
    except (OSError, ValueError, EOFError, zipfile.BadZipFile) as exc:
        raise InvalidInputError(f"{source}: not an npz file of numeric arrays ({exc})") from None
    named = {}
    for name, array in arrays.items():
        key = _column(name, name, source)
        if array.dtype.kind not in "iuf" or array.ndim != 1:
            raise InvalidInputError(f"{source}: array {name!r} is {array.dtype} of shape {array.shape}; a column is "
                                    "a 1-D array of numbers")
        named[key] = array.astype(float)
    return named


def _csv_columns(path, source):
    """{(column, SI factor, unit): values} of a CSV file: a header 'name [unit]', ... then numbers."""
    data = path.read_bytes()
    if b"\0" in data:
        raise InvalidInputError(f"{source}: a binary file (NUL byte at offset {data.find(0)}), not a CSV table")
    try:
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise InvalidInputError(f"{source}: not UTF-8 text (byte 0x{data[exc.start]:02x} at offset {exc.start}); "
                                "a replay table is a CSV file in UTF-8 or an npz file") from None
    lines = [line for line in text.splitlines() if line.strip() and not line.lstrip().startswith("#")]
    if not lines:
        raise InvalidInputError(f"{source}: empty: no header line (time [s],azimuth [deg],elevation [deg]) and no rows")
    if len(lines) - 1 > MAX_ROWS:
        raise InvalidInputError(f"{source}: {len(lines) - 1} rows, more than the {MAX_ROWS} (a day at 20 Hz) a "
                                "replay table may have: cut it into runs")
    header = next(csv.reader(lines[:1]))
    keys = [_column(cell, cell, source) for cell in header]
    if len(set(k for k, _, _ in keys)) != len(keys):
        raise InvalidInputError(f"{source}: needs the columns {', '.join(COLUMNS)} once each, got "
                                f"{', '.join(k for k, _, _ in keys)}")
    values = _numbers(lines[1:], len(keys))
    if values is None:
        values = _cells([header, *csv.reader(lines[1:])], source)
    return {key: values[:, j] for j, key in enumerate(keys)}


def _numbers(lines, width):
    """The CSV data lines as an (n, width) float array, or None if a row or a cell is not a number."""
    if not lines:
        return np.empty((0, width))
    try:
        values = np.loadtxt(lines, delimiter=",", ndmin=2, dtype=float)
    except ValueError:
        return None
    return values if values.shape == (len(lines), width) else None


def _cells(rows, source):
    """The data rows (csv.reader's: quoted numbers taken) as an (n, width) float array;
    InvalidInputError naming the first row of the wrong length or cell that is not a number."""
    header, values = rows[0], []
    for i, row in enumerate(rows[1:]):
        if len(row) != len(header):
            raise InvalidInputError(f"{source}: row {i + 1} has {len(row)} values, the header {len(header)}")
        for j, cell in enumerate(row):
            if not cell.strip():
                raise InvalidInputError(f"{source}: row {i + 1}, column {header[j].strip()!r}: is empty")
            try:
                if "_" in cell:     # Python's float reads "1_0" as 10; a log means no such thing
                    raise ValueError(cell)
                values.append(float(cell))
            except ValueError:
                raise InvalidInputError(f"{source}: row {i + 1}, column {header[j].strip()!r}: "
                                        f"{cell!r} is not a number") from None
    return np.array(values, dtype=float).reshape(len(rows) - 1, len(header))


def _unwrap(azimuth):
    """The azimuth with every step beyond WRAP_JUMP taken as a 360 deg wrap, and the rows
    (1-based) where one was."""
    steps = np.diff(azimuth)
    turns = np.round(steps / (2 * math.pi)) * (np.abs(steps) > WRAP_JUMP)
    return azimuth - 2 * math.pi * np.concatenate(([0.0], np.cumsum(turns))), np.flatnonzero(turns) + 2


def _unit_hint(elevation, low, high, written):
    """A problem saying the elevation column's unit is wrong, when every row is outside
    [low, high] and the values read in another angle unit fit it; else None."""
    if written is None or ((elevation >= low) & (elevation <= high)).any():
        return None
    units = UNITS["angle"]
    raw = elevation / units[written]
    for unit, factor in units.items():
        if unit != written and low <= raw.min() * factor and raw.max() * factor <= high:
            return (f"elevation: every row is outside [{math.degrees(low):g}, {math.degrees(high):g}] deg as "
                    f"[{written}] ({raw.min():.6g} to {raw.max():.6g}); read as [{unit}] they fit: is the header's "
                    "unit right?")
    return None


def _turns(azimuth):
    """Whole turns to add to the unwrapped azimuth: 0 if it fits the cable wrap as written;
    for a log that does not carry the wrap's turn (every value in [0, 360) or in [-180, 180)
    deg), the fewest turns that put it inside the wrap (the motion is the same: the base's
    pose depends on the azimuth modulo 360 deg); 0 if none does (the check names the rows)."""
    az = _unwrap(azimuth)[0]
    low, high = AZIMUTH_LIMITS
    modular = (azimuth.min() >= 0 and azimuth.max() < 2 * math.pi) or (azimuth.min() >= -math.pi
                                                                        and azimuth.max() < math.pi)
    for k in (0, 1, -1, 2, -2):
        if (k == 0 or modular) and low <= az.min() + 2 * math.pi * k and az.max() + 2 * math.pi * k <= high:
            return k
    return 0


@dataclass(frozen=True, eq=False)
class Replay:
    """A checked table as its smoothing spline: breakpoints [s] and per interval the cubic
    coefficients (n - 1, 8) of azimuth and elevation [rad] (mb_tel_profile's replay_*)."""

    breakpoints: np.ndarray
    coefficients: np.ndarray
    smoothing_time: float
    wraps: tuple             # rows (1-based) where the azimuth wrapped by 360 deg
    source: str
    turns: int = 0           # whole turns added to the log's azimuth to put it in the cable wrap (_turns)

    @property
    def duration(self):
        return float(self.breakpoints[-1] - self.breakpoints[0])


def _spline(t, y, h):
    """Cubic coefficients (n - 1, 4) of the smoothing spline of y(t) on each interval."""
    # imported here: scenario checking imports this module, and scipy costs a run without
    # a replay table ~0.3 s (tests/scenarios/output/test_report.py, issue 21)
    from scipy.interpolate import make_smoothing_spline
    rate = 1.0 / float(np.median(np.diff(t)))
    spline = make_smoothing_spline(t, y, lam=rate * h ** 4)
    mid = 0.5 * (t[1:] + t[:-1])
    left = t[:-1]
    return np.column_stack([spline(left), spline(left, 1), spline(left, 2) / 2, spline(mid, 3) / 6])


def _derivatives(t, coef):
    """Rate and acceleration at the breakpoints, the intervals' midpoints and their ends."""
    s = np.diff(t)[:, None] * np.array([0.0, 0.5, 1.0])
    c = coef[:, :, None]
    rate = c[:, 1] + 2 * c[:, 2] * s + 3 * c[:, 3] * s ** 2
    acc = 2 * c[:, 2] + 6 * c[:, 3] * s
    return rate, acc


def _problems(table, params, max_gap, smoothing_time):
    """The problems of a table, each naming its row (1-based, as the file's data rows), and
    the spline's coefficients (None if a problem stopped the checks before them)."""
    t, az, el = table.time, table.azimuth, table.elevation
    problems = []
    if not (t.size == az.size == el.size):
        return [f"the columns have different lengths ({t.size}, {az.size}, {el.size})"], None
    if t.size < MIN_ROWS:
        return [f"{t.size} row{'' if t.size == 1 else 's'}: a replay needs at least {MIN_ROWS}"], None
    if t.size > MAX_ROWS:
        return [f"{t.size} rows, more than the {MAX_ROWS} (a day at 20 Hz) a replay table may have: cut it into "
                "runs"], None
    for name, values in (("time", t), ("azimuth", az), ("elevation", el)):
        problems += [f"row {i + 1}: {name} is {float(values[i])!r}, not a finite number"
                     for i in np.flatnonzero(~np.isfinite(values))]
    if problems:
        return problems, None
    hint = _unit_hint(el, *ELEVATION_LIMITS, (table.units or {}).get("elevation"))
    if hint:
        return [hint], None
    step = np.diff(t)
    problems += [f"row {i + 2}: time {t[i + 1]:.6g} s " + ("repeats row {}'s (a duplicate time)".format(i + 1)
                                                          if step[i] == 0 else
                                                          f"goes back from row {i + 1}'s {t[i]:.6g} s (out of order)")
                 for i in np.flatnonzero(step <= 0)]
    problems += [f"rows {i + 1}-{i + 2}: a gap of {step[i]:.6g} s from {t[i]:.6g} s, more than the {max_gap:g} s "
                 "the spline may bridge" for i in np.flatnonzero(step > max_gap)]
    az = _unwrap(az)[0] + 2 * math.pi * _turns(table.azimuth)
    low, high = AZIMUTH_LIMITS
    problems += [f"row {i + 1}: azimuth {math.degrees(az[i]):.6g} deg (unwrapped) is outside the cable wrap "
                 f"[{math.degrees(low):g}, {math.degrees(high):g}] deg"
                 for i in np.flatnonzero((az < low) | (az > high))]
    low, high = ELEVATION_LIMITS
    problems += [f"row {i + 1}: elevation {math.degrees(el[i]):.6g} deg is outside [{math.degrees(low):g}, "
                 f"{math.degrees(high):g}] deg" for i in np.flatnonzero((el < low) | (el > high))]
    if problems:
        return problems, None
    t = t - t[0]      # the first time is t = 0: fitted from there (a log's Unix times keep their resolution)
    coef = np.concatenate([_spline(t, az, smoothing_time), _spline(t, el, smoothing_time)], axis=1)
    unfit = np.flatnonzero(~np.isfinite(coef).all(axis=1))
    if unfit.size:   # not seen (times 1e-12 s apart fit); the C would refuse the spline without its row
        return [f"rows {i + 1}-{i + 2}: the smoothing spline is not finite there (times too close?)"
                for i in unfit[:1]], None
    for axis, col, limits in (("azimuth", 0, (params.az_rate_max, params.az_acc_max)),
                              ("elevation", 4, (params.el_rate_max, params.el_acc_max))):
        for what, values, limit, unit in zip(("rate", "acceleration"), _derivatives(t, coef[:, col:col + 4]), limits,
                                             ("deg/s", "deg/s2")):
            worst = np.abs(values).max(axis=1)
            for first, last in _runs(np.flatnonzero(worst > limit * (1 + LIMIT_MARGIN))):
                rows = f"row {first + 1}" if first == last else f"rows {first + 1}-{last + 1}"
                peak = math.degrees(worst[first:last + 1].max())
                problems.append(f"{rows}: the smoothed {axis} {what} {'' if first == last else 'up to '}"
                                f"{peak:.4g} {unit} passes the drive's {math.degrees(limit):.4g} {unit} "
                                f"(+{LIMIT_MARGIN:.0%} allowed)")
    return problems, coef


def _runs(indices):
    """(first, last) of each run of consecutive indices."""
    breaks = np.flatnonzero(np.diff(indices) > 1)
    return [(int(indices[a]), int(indices[b])) for a, b in zip(np.r_[0, breaks + 1], np.r_[breaks, indices.size - 1])
            ] if indices.size else []


def replay_table(table, params, max_gap=MAX_GAP, smoothing_time=SMOOTHING_TIME):
    """A checked Table as a Replay for ``params`` (a TelescopeParams: the drives' limits).
    InvalidInputError listing every problem with its row: fewer than MIN_ROWS or more than
    MAX_ROWS rows, a value not finite, a time out of order or repeated, a gap beyond
    ``max_gap`` [s], an axis outside its range (or every elevation, when another unit
    explains it), a smoothed rate or acceleration beyond the drive's limit (runs of rows).
    Handled, not refused: a 360 deg azimuth wrap either way (unwrapped), a log written
    modulo 360 deg (put on the turn inside the cable wrap), noise (smoothed over
    ``smoothing_time`` [s]), gaps up to max_gap."""
    if not (np.isfinite(smoothing_time) and smoothing_time > 0):
        raise InvalidInputError(f"smoothing_time must be finite and > 0, got {smoothing_time!r}")
    if not (np.isfinite(max_gap) and max_gap > 0):
        raise InvalidInputError(f"max_gap must be finite and > 0, got {max_gap!r}")
    problems, coef = _problems(table, params, max_gap, smoothing_time)
    if problems:
        more = len(problems) - SHOWN_PROBLEMS
        raise InvalidInputError(f"{table.source}: {len(problems)} problem(s): " + "; ".join(problems[:SHOWN_PROBLEMS])
                                + (f"; and {more} more" if more > 0 else ""))
    _, wraps = _unwrap(table.azimuth)
    return Replay(np.ascontiguousarray(table.time - table.time[0], dtype=float), np.ascontiguousarray(coef),
                  float(smoothing_time), tuple(int(r) for r in wraps), table.source, _turns(table.azimuth))


def prepared_bytes(result):
    """A Replay as a prepared replay table (the module's docstring gives the layout)."""
    n = result.breakpoints.size
    head = np.array([(PREPARED_MAGIC, PREPARED_VERSION, n, result.smoothing_time)], dtype=PREPARED_HEADER)
    return b"".join(np.ascontiguousarray(a).tobytes() for a in (
        head, result.breakpoints.astype("<f8"), result.coefficients.astype("<f8")))


def is_prepared(path):
    """Does the file start as a prepared replay table?"""
    path = pathlib.Path(path)
    with path.open("rb") as f:
        return f.read(len(PREPARED_MAGIC)) == PREPARED_MAGIC


def read_prepared(path, smoothing_time=None):
    """The Replay a prepared replay table holds, checked as the native FMU checks it
    (version, size, finite and increasing knots; its smoothing time ``smoothing_time`` if
    given); InvalidInputError naming the problem."""
    source = str(path)
    data = pathlib.Path(path).read_bytes()
    if len(data) < PREPARED_HEADER.itemsize or not data.startswith(PREPARED_MAGIC):
        raise InvalidInputError(f"{source}: not a prepared replay table (no {PREPARED_MAGIC.decode()} header)")
    head = np.frombuffer(data[:PREPARED_HEADER.itemsize], dtype=PREPARED_HEADER)[0]
    n = int(head["n"])
    expected = PREPARED_HEADER.itemsize + 8 * (n + 8 * (n - 1))
    if int(head["version"]) != PREPARED_VERSION or n < 2 or len(data) != expected:
        raise InvalidInputError(f"{source}: version {int(head['version'])} (read: {PREPARED_VERSION}), {n} knots (2..) "
                                f"in {len(data)} bytes ({expected} expected): truncated or damaged")
    body = np.frombuffer(data, dtype="<f8", offset=PREPARED_HEADER.itemsize).astype(float)
    t, coef = body[:n], body[n:].reshape(n - 1, 8)
    bad = np.flatnonzero(~np.isfinite(t) | np.r_[False, ~(np.diff(t) > 0)] | np.r_[~np.isfinite(coef).all(1), False])
    if bad.size:
        raise InvalidInputError(f"{source}: knot {bad[0]} (0-based) is not finite or does not follow the one before")
    h = float(head["smoothing"])
    if smoothing_time is not None and h != smoothing_time:
        raise InvalidInputError(f"{source} was smoothed over {h!r} s, replay_smoothing is {smoothing_time!r} s: "
                                "prepare it with this smoothing time or set it to the table's")
    return Replay(t, coef, h, (), source)


def load(path, params, max_gap=MAX_GAP, smoothing_time=SMOOTHING_TIME):
    """read_table then replay_table: the Replay of a file (a prepared one: read_prepared,
    its smoothing time ``smoothing_time``). The last few are kept, keyed by the file's
    path, size and modification time and the settings: the scenario check and the FMU read
    a night's table (720,000 rows: ~45 s to smooth) once between them."""
    if not str(path):
        raise InvalidInputError("the replay profile needs a table: replay_table is empty")
    path = pathlib.Path(path)
    if path.is_file() and is_prepared(path):
        return read_prepared(path, float(smoothing_time))
    stat = path.stat() if path.is_file() else None
    if stat is None:
        return replay_table(read_table(path), params, max_gap, smoothing_time)
    return _load(str(path.resolve()), stat.st_size, stat.st_mtime_ns, params, float(max_gap), float(smoothing_time))


@lru_cache(maxsize=4)
def _load(path, size, mtime_ns, params, max_gap, smoothing_time):
    result = replay_table(read_table(path), params, max_gap, smoothing_time)
    for array in (result.breakpoints, result.coefficients):
        array.flags.writeable = False     # shared between callers
    return result
