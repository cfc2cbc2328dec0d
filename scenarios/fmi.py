"""A thin layer over fmpy's FMU2Slave: one extracted copy per FMU file, variables by
name, preallocated ctypes buffers for the per-step exchange, the FMU's log captured,
and every failing call turned into an error that names the instance, time and log.

The per-step calls (doStep, getReal, setReal) go to fmpy's loaded C functions directly
and check the returned status here: fmpy's Python wrapper around each call costs more
than the call itself at a 1 ms step (benchmarks/bench_scenarios.py)."""
import atexit
import hashlib
import pathlib
import re
import shutil
import zipfile
from functools import lru_cache

import numpy as np
from fmpy import extract, read_model_description
from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import (FMU2Slave, fmi2CallbackAllocateMemoryTYPE, fmi2CallbackFreeMemoryTYPE,
                       fmi2CallbackFunctions, fmi2CallbackLoggerTYPE, fmi2Real, fmi2ValueReference)
from fmpy import calloc, free

_LABELS = ("OK", "WARNING", "DISCARD", "ERROR", "FATAL", "PENDING")


class FmuError(RuntimeError):
    """An FMU answered Discard/Error/Fatal; the message names the instance, time and log."""


MAX_MEMBER_BYTES = 1 << 30     # an FMU member larger than this is refused before extracting
_FOLDERS = []                  # extraction folders of this process, removed at exit


class FmuFileError(ValueError):
    """An FMU path that is not a usable FMU file (a folder, not a zip, truncated, huge)."""


def check_file(path):
    """The zip listing of an FMU file; FmuFileError naming the path and the problem for
    a folder, a missing file, a file that is not a zip, a truncated zip, one without
    modelDescription.xml or with a member too large to extract. Reads the listing only."""
    path = pathlib.Path(path)
    if path.is_dir():
        raise FmuFileError(f"FMU {path}: is a folder; an FMU is a .fmu (zip) file")
    if not path.is_file():
        raise FmuFileError(f"FMU {path}: does not exist")
    try:
        with zipfile.ZipFile(path) as archive:
            members = archive.infolist()
    except (zipfile.BadZipFile, OSError, ValueError) as exc:
        raise FmuFileError(f"FMU {path}: not a readable zip file ({exc}); it may be truncated, rebuild it") from None
    names = {m.filename for m in members}
    if "modelDescription.xml" not in names:
        raise FmuFileError(f"FMU {path}: has no modelDescription.xml")
    huge = [m for m in members if m.file_size > MAX_MEMBER_BYTES]
    if huge:
        raise FmuFileError(f"FMU {path}: member {huge[0].filename} unpacks to {huge[0].file_size / 2**30:.1f} GiB "
                           f"(limit {MAX_MEMBER_BYTES / 2**30:.0f} GiB); refused")
    return members


@lru_cache(maxsize=None)
def unpack(path):
    """Model description and extraction folder of an FMU file, once per process; the
    folder is removed when the process ends."""
    check_file(path)
    try:
        description = read_model_description(str(path))
        folder = extract(str(path))
    except (zipfile.BadZipFile, OSError, ValueError) as exc:   # a member's CRC or XML fails
        raise FmuFileError(f"FMU {path}: cannot be read ({exc}); rebuild it") from None
    _FOLDERS.append(folder)
    return description, folder


@atexit.register
def _remove_folders():
    for folder in _FOLDERS:
        shutil.rmtree(folder, ignore_errors=True)


_BUILD_ID = re.compile(rb"(\x04\x00\x00\x00\x14\x00\x00\x00\x03\x00\x00\x00GNU\x00).{20}", re.S)
_STAMP = re.compile(rb'\s(?:guid|generationDateAndTime)="[^"]*"')


def content_digest(path):
    """SHA-256 of what decides an FMU's numbers: every member's name and bytes, with what
    each build makes anew (the guid wherever it appears, the generation time, the ELF
    build id) blanked. Two builds of the same sources give the same digest."""
    with zipfile.ZipFile(path) as archive:
        xml = archive.read("modelDescription.xml")
        guid = re.search(rb'\sguid="([^"]*)"', xml)
        digest = hashlib.sha256()
        for name in sorted(archive.namelist()):
            data = archive.read(name)
            if guid and guid.group(1):
                data = data.replace(guid.group(1), b"<guid>")
            data = _STAMP.sub(b"", data) if name == "modelDescription.xml" else _BUILD_ID.sub(rb"\1", data)
            digest.update(name.encode() + b"\0" + len(data).to_bytes(8, "little") + data)
    return digest.hexdigest()


class Instance:
    """One FMU instance: instantiate, set parameters, initialise, step, read/write."""

    def __init__(self, path, name):
        self.name = name
        self.md, folder = unpack(path)
        self.variables = {v.name: v for v in self.md.modelVariables}
        self.log = []
        self._logger = fmi2CallbackLoggerTYPE(self._on_log)
        callbacks = fmi2CallbackFunctions()
        callbacks.logger = self._logger
        callbacks.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
        callbacks.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
        self._callbacks = callbacks
        self.fmu = FMU2Slave(guid=self.md.guid, unzipDirectory=folder, instanceName=name,
                             modelIdentifier=self.md.coSimulation.modelIdentifier)
        self.time = 0.0
        self.freed = False
        self.call("instantiate", loggingOn=True, callbacks=callbacks)

    def _on_log(self, component, instance, status, category, message):
        self.log.append(f"[{_LABELS[status]}] {message.decode(errors='replace')}")

    def call(self, function, *args, **kwargs):
        """Call an FMU2Slave method; on a bad status raise FmuError naming what happened."""
        try:
            return getattr(self.fmu, function)(*args, **kwargs)
        except FMICallException as exc:
            self.fail(function, exc)

    def fail(self, function, status):
        log = "\n  ".join(self.log[-5:]) or "(no log message)"
        raise FmuError(f"FMU instance '{self.name}' failed in {function} at t = {self.time:.6g} s "
                       f"({status}). Log:\n  {log}") from None

    def raw(self, function):
        """fmpy's ctypes function itself: call it with the component, check the status."""
        return self.fmu._functions[function]

    def vr(self, name):
        if name not in self.variables:
            raise KeyError(f"FMU instance '{self.name}' has no variable '{name}'")
        return self.variables[name].valueReference

    def set(self, name, value):
        """Set one variable by name, with the FMI type its description says."""
        self.vr(name)
        kind = self.variables[name].type
        if kind in ("Integer", "Enumeration"):   # FMI 2.0 sets an Enumeration as an Integer
            self.call("setInteger", [self.vr(name)], [int(value)])
        elif kind == "Boolean":
            self.call("setBoolean", [self.vr(name)], [bool(value)])
        elif kind == "String":
            self.call("setString", [self.vr(name)], [str(value)])
        else:
            self.call("setReal", [self.vr(name)], [float(value)])

    def get_real(self, name):
        return self.call("getReal", [self.vr(name)])[0]

    def initialize(self, start_time, values=None):
        """Set up, set ``values`` (parameters and start inputs) in initialization mode, exit."""
        self.time = start_time
        self.call("setupExperiment", startTime=start_time)
        self.call("enterInitializationMode")
        for name, value in (values or {}).items():
            self.set(name, value)
        self.call("exitInitializationMode")
        self._do_step = self.raw("fmi2DoStep")

    def do_step(self, t, h):
        self.time = t
        status = self._do_step(self.fmu.component, t, h, 1)
        if status > 1:
            self.fail("doStep", f"status {_LABELS[status]}")

    def terminate(self):
        """End and free the instance, once; a failed FMU may refuse terminate, it is
        freed regardless."""
        if self.freed:
            return
        self.freed = True
        try:
            self.fmu.terminate()
        except FMICallException:
            pass
        finally:
            self.fmu.freeInstance()


class RealPort:
    """A fixed list of Real variables of one instance, read or written in one FMI call
    through preallocated ctypes buffers (half the cost of fmpy's list-based calls)."""

    def __init__(self, instance, names):
        self.instance = instance
        self.names = list(names)
        n = len(self.names)
        self.n = n
        self._vr = (fmi2ValueReference * n)(*[instance.vr(v) for v in self.names])
        self._buf = (fmi2Real * n)()
        self.values = np.ctypeslib.as_array(self._buf)
        self._get, self._set = instance.raw("fmi2GetReal"), instance.raw("fmi2SetReal")

    def read(self):
        status = self._get(self.instance.fmu.component, self._vr, self.n, self._buf)
        if status > 1:
            self.instance.fail("getReal", f"status {_LABELS[status]}")
        return self.values

    def write(self, values):
        self.values[:] = values
        status = self._set(self.instance.fmu.component, self._vr, self.n, self._buf)
        if status > 1:
            self.instance.fail("setReal", f"status {_LABELS[status]}")
