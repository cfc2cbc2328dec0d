"""Recorded time series of one run: float64 columns in memory, written as one npz file.

Why npz: numpy writes and reads it without a new dependency, with no per-float
formatting (the master's CSV rows cost 43-48 % of a run, docs/speed.md), and any tool that
reads .npy reads it (a zip of one .npy per column: numpy, pandas through
``pandas.DataFrame(dict(numpy.load(path)))``, Julia's NPZ.jl, MATLAB's npy-matlab).
Parquet or HDF5 would add pyarrow or h5py for the same columns.

Each column is one array in the file, keyed by the CSV's header cell, "time [s]" first,
then "inst.var [unit]" in recording order: the CSV export (``to_csv``) is the same table
with the same header and each float as its shortest repr (exact).
"""
from __future__ import annotations

import io
import os
import pathlib
import re
import zipfile
from collections.abc import Sequence
from typing import Any

import numpy as np

from fmu_src.atomic import replacing, write_bytes_later

TIME = "time [s]"
_HEADER = re.compile(r"(.*) \[(.*)\]")


class Records:
    """A run's recorded rows, preallocated for the record grid: ``time``, ``names``
    ("inst.var"), ``units`` and ``values`` (rows x columns), rows filled so far only."""

    def __init__(self, names: Sequence[str], units: Sequence[str], rows: int):
        self.names, self.units = list(names), list(units)
        self._data = np.empty((rows, 1 + len(self.names)))
        self.count = 0

    @classmethod
    def of(cls, time: np.ndarray, names: Sequence[str], units: Sequence[str], values: np.ndarray) -> Records:
        """Records holding arrays already made (``values``: rows x columns)."""
        records = cls(names, units, 0)
        records._data = np.column_stack([time, values]) if len(names) else np.asarray(time, float)[:, None]
        records.count = len(records._data)
        return records

    def extend(self, t: np.ndarray, rows: np.ndarray) -> None:
        """Add rows (n, columns) at times t (n,) (a full grid's worth of rows was preallocated)."""
        stop = self.count + len(t)
        self._data[self.count:stop, 0] = t
        self._data[self.count:stop, 1:] = rows
        self.count = stop

    @property
    def time(self) -> np.ndarray:
        return self._data[:self.count, 0]

    @property
    def values(self) -> np.ndarray:
        return self._data[:self.count, 1:]

    @property
    def header(self) -> list[str]:
        """The column titles, as in the CSV: "time [s]", "inst.var [unit]", ..."""
        return [TIME] + [f"{n} [{u}]" for n, u in zip(self.names, self.units)]

    @property
    def columns(self) -> dict[str, np.ndarray]:
        """{header cell: column}, the table as the file and the CSV hold it."""
        data = self._data[:self.count]
        return {title: data[:, j] for j, title in enumerate(self.header)}

    def __getitem__(self, name: str) -> np.ndarray:
        """One column by "inst.var" (or "time")."""
        if name == "time":
            return self.time
        if name not in self.names:
            raise KeyError(f"no recorded variable {name!r}; recorded: {', '.join(self.names)}")
        return self._data[:self.count, 1 + self.names.index(name)]

    def save(self, path: str | os.PathLike[str], later: bool = False) -> pathlib.Path:
        """Write the npz file (one array per column, keyed by its header cell), atomically
        (fmu_src.atomic: a reader never finds a torn file); ".npz" is added as numpy would.
        ``later``: made in memory now, written to disk on a thread (atomic.write_bytes_later),
        in place once atomic.settle() has returned."""
        path = pathlib.Path(path)
        if path.suffix != ".npz":
            path = path.with_name(path.name + ".npz")
        columns: dict[str, Any] = self.columns
        if later:
            made = io.BytesIO()
            np.savez(made, **columns)
            write_bytes_later(path, made.getbuffer())
            return path
        with replacing(path) as file:
            np.savez(file, **columns)
        return path

    def to_csv(self, path: str | os.PathLike[str]) -> pathlib.Path:
        """Export as CSV: the header with units, each float as its shortest repr."""
        path = pathlib.Path(path)
        with replacing(path, text=True, newline="") as f:
            f.write(",".join(self.header) + "\r\n")
            f.writelines(",".join(map(repr, row)) + "\r\n" for row in self._data[:self.count].tolist())
        return path


class Block:
    """Recorded rows buffered for an evaluation a block at a time (scenarios.runs.metrics,
    flags.Watch): ``size`` rows of ``width`` values and their times. ``add`` copies rows in
    slices and calls ``full()`` whenever the block fills, so blocks end at the same row
    counts however the rows arrive (one at a time or many)."""

    def __init__(self, size: int, width: int):
        self.t, self.rows, self.filled = np.empty(size), np.empty((size, width)), 0

    def add(self, t: np.ndarray, parts: Sequence[tuple[np.ndarray, Any]], full: Any) -> None:
        """Rows at times t (n,); ``parts``: (values (n, w), the block's columns they go to)."""
        done = 0
        while done < len(t):
            n = min(len(self.t) - self.filled, len(t) - done)
            at = slice(self.filled, self.filled + n)
            self.t[at] = t[done:done + n]
            for values, columns in parts:
                self.rows[at, columns] = values[done:done + n]
            self.filled += n
            done += n
            if self.filled == len(self.t):
                full()

    def take(self) -> tuple[np.ndarray, np.ndarray]:
        """(times, rows) buffered, views of the block, which starts empty again."""
        n, self.filled = self.filled, 0
        return self.t[:n], self.rows[:n]


def read_records(path: str | os.PathLike[str]) -> Records:
    """The one reader of a recorded run's file (what Records.save wrote). Anything else (an
    .npy array, a CSV renamed, columns of other lengths or types, times that are not
    finite and increasing) is a ValueError naming the file and what is wrong with it."""
    path = pathlib.Path(path)
    try:
        with open(path, "rb") as file:
            magic = file.read(4)
        if magic not in (b"PK\x03\x04", b"PK\x05\x06"):   # np.load would take any other bytes for a pickle
            what = "one array (an .npy file)" if magic == b"\x93NUM" else "not an npz archive"
            raise ValueError(f"{what}; a run's records are an npz of columns (a CSV export is not read back)")
        with np.load(path, allow_pickle=False) as data:
            titles = list(data.files)
            columns = [data[t] for t in titles]
    except (OSError, ValueError, EOFError, zipfile.BadZipFile) as exc:    # truncated, bit-flipped
        raise ValueError(f"{path}: cannot read recorded data: {exc}") from None
    matched = [_HEADER.fullmatch(t) for t in titles[1:]]
    if not titles or titles[0] != TIME or not all(matched):
        raise ValueError(f"{path}: not a run's records (expected {TIME!r}, then 'inst.var [unit]' columns; "
                         f"found {', '.join(titles[:3]) or 'none'})")
    bad = [t for t, c in zip(titles, columns) if c.ndim != 1 or c.dtype.kind != "f" or len(c) != len(columns[0])]
    if bad:
        raise ValueError(f"{path}: not a run's records: columns {', '.join(map(repr, bad[:3]))} are not floats of "
                         f"the {len(columns[0])} times of {TIME!r}")
    time = columns[0]
    if not np.isfinite(time).all() or (np.diff(time) <= 0).any():
        raise ValueError(f"{path}: not a run's records: its times are not finite and increasing")
    parts = [m.groups() for m in matched if m]
    return Records.of(time, [n for n, _ in parts], [u for _, u in parts],
                      np.column_stack(columns[1:]) if parts else np.empty((len(time), 0)))


def run_records(run: Any) -> Records | None:
    """A run's records: in memory if it ran in this process, else read from its file;
    None if it stopped before its first row."""
    if run.records is not None:
        return run.records
    return read_records(run.record_path) if run.record_path else None
