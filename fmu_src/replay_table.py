"""Prepared replay tables: a pointing log smoothed once, in Python (scipy), and written as
the spline the Telescope FMUs evaluate (plant/telescope/replay.py prepared_bytes), so that the
native FMUs, which read it in C, replay the same coefficients as the pythonfmu one.

    python -m fmu_src.replay_table LOG [-o FILE] [--smoothing H]

checks and smooths LOG with the Tianma drives' limits and writes FILE (default: LOG with
the suffix .mbreplay). A scenario replaying a log gets it prepared by prepared() into a
cache keyed by the log's bytes and the settings: the scenario check prepares it
(scenarios/spec/checks.py), and the master gives it to the instance (for_fmu).
"""
import argparse
import dataclasses
import hashlib
import pathlib
import tempfile

from fmu_src import atomic
from plant.errors import InvalidInputError
from plant.telescope import model as telescope
from plant.telescope import replay

CACHE = pathlib.Path(tempfile.gettempdir()) / "movingbase-replay"
DRIVE_LIMITS = ("az_rate_max", "az_acc_max", "el_rate_max", "el_acc_max")   # what a table is checked against
CACHE_REVISION = 2   # in the cache key: raised when replay.py reads or smooths a log differently (2: the spline
#                      fitted from the first time, a log written modulo 360 deg put into the cable wrap)
_LOGS: dict = {}   # a prepared table made here -> its log (a sweep of the smoothing prepares that log again)


def write(log, out, params, smoothing_time=replay.SMOOTHING_TIME):
    """The prepared table of the log (or prepared table) ``log`` written whole to ``out``; its path."""
    return atomic.write_bytes(out, replay.prepared_bytes(replay.load(log, params, smoothing_time=smoothing_time)))


def params_of(values):
    """The TelescopeParams a Telescope FMU with these parameter values (name -> SI value)
    checks its table against: its drives' limits, Tianma's (the FMU's defaults) where unset."""
    limits = ("lever_arm", "latitude", "longitude", "az_rate_max", "az_acc_max", "el_rate_max", "el_acc_max")
    return dataclasses.replace(telescope.TelescopeParams.tianma(), **{n: values[n] for n in limits if n in values})


def prepared(log, params, smoothing_time=replay.SMOOTHING_TIME, cache=CACHE):
    """A prepared table of ``log`` for ``params`` (the drives' limits it is checked against)
    and ``smoothing_time``: ``log`` itself if it is one of that smoothing time (checked), else
    a file in ``cache`` named by the hash of the log's bytes and the settings, made when
    missing; a prepared table made here, asked for with another smoothing time (a sweep of
    replay_smoothing over a scene the check prepared), is prepared again from its log."""
    log = pathlib.Path(log)
    if log.is_file() and replay.is_prepared(log):
        made_from = _LOGS.get(str(log))
        if made_from is None or replay.read_prepared(log).smoothing_time == float(smoothing_time):
            replay.read_prepared(log, float(smoothing_time))   # checked; another h is refused
            return log
        log = made_from
    if not log.is_file():
        raise InvalidInputError(f"replay table {str(log)!r} does not exist")
    settings = [float(getattr(params, n)) for n in DRIVE_LIMITS] + [float(smoothing_time), CACHE_REVISION]
    key = hashlib.sha256(log.read_bytes() + repr(settings).encode()).hexdigest()[:24]
    out = pathlib.Path(cache) / f"{log.stem}-{key}{replay.PREPARED_SUFFIX}"
    if not out.is_file():
        out.parent.mkdir(parents=True, exist_ok=True)
        write(log, out, params, smoothing_time)
    _LOGS[str(out)] = log
    return out


def for_fmu(values):
    """A Telescope instance's parameter values (name -> value) as it is given them: with
    profile replay, replay_table (a log, or a prepared table) replaced by its prepared table
    for the instance's drives' limits and replay_smoothing (prepared()), which the native
    and the pythonfmu Telescope read alike. Other values are returned as they are."""
    table = values.get("replay_table")
    if not (isinstance(table, (str, pathlib.Path)) and str(table)
            and values.get("profile") == telescope.PROFILE_KINDS.index("replay")):
        return values
    smoothing = values.get("replay_smoothing", replay.SMOOTHING_TIME)
    return {**values, "replay_table": str(prepared(table, params_of(values), smoothing))}


def main(argv=None):
    parser = argparse.ArgumentParser(prog="python -m fmu_src.replay_table", description=__doc__.split("\n\n")[0])
    parser.add_argument("log", help="a CSV or npz table of time, azimuth, elevation (units in brackets)")
    parser.add_argument("-o", "--out", help="the prepared table (default: LOG with the suffix .mbreplay)")
    parser.add_argument("--smoothing", type=float, default=replay.SMOOTHING_TIME,
                        help="smoothing time h [s] (the FMU's replay_smoothing must equal it)")
    args = parser.parse_args(argv)
    out = pathlib.Path(args.out or pathlib.Path(args.log).with_suffix(replay.PREPARED_SUFFIX))
    try:
        write(args.log, out, telescope.TelescopeParams.tianma(), args.smoothing)
    except InvalidInputError as exc:
        parser.exit(2, f"{exc}\n")
    print(out)


if __name__ == "__main__":
    main()
