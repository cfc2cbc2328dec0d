"""A thin layer over fmpy's FMU2Slave: one extracted copy per FMU file (kept between
processes in a cache keyed by the file's bytes), variables by name, preallocated ctypes
buffers for the per-step exchange, the FMU's log captured, and every failing call turned
into an error that names the instance, time and log.

The per-step calls (doStep, getReal, setReal) go to fmpy's loaded C functions directly
and check the returned status here: fmpy's Python wrapper around each call costs more
than the call itself at a 1 ms step (benchmarks/bench_scenarios.py)."""
import atexit
import contextlib
import copy
import errno
import hashlib
import io
import json
import os
import pathlib
import pickle
import re
import shutil
import tempfile
import time
import zipfile
import zlib
from ctypes import CFUNCTYPE, POINTER, byref, c_bool, c_double, c_int, c_int32, c_size_t, c_uint, c_void_p
from functools import lru_cache

import numpy as np
from fmpy import __version__ as fmpy_version
from fmpy import calloc, extract, free, read_model_description
from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import (
    FMU2Slave,
    fmi2CallbackAllocateMemoryTYPE,
    fmi2CallbackFreeMemoryTYPE,
    fmi2CallbackFunctions,
    fmi2CallbackLoggerTYPE,
    fmi2Real,
    fmi2ValueReference,
)
from fmpy.fmi3 import FMU3Slave

_LABELS = ("OK", "WARNING", "DISCARD", "ERROR", "FATAL", "PENDING")


class FmuError(RuntimeError):
    """An FMU answered Discard/Error/Fatal; the message names the instance, time and log."""


MAX_MEMBER_BYTES = 1 << 30     # an FMU member larger than this is refused before extracting
_FOLDERS: list = []                  # extraction folders of this process, removed at exit
_LOADED: dict = {}                   # (fmpy slave class, extraction folder) -> the slave whose library instances share


class FmuFileError(ValueError):
    """An FMU path that is not a usable FMU file (a folder, not a zip, truncated, huge)."""


def check_file(path, data=None):
    """The zip listing of an FMU file; FmuFileError naming the path and the problem for
    a folder, a missing file, a file that is not a zip, a truncated zip, one without
    modelDescription.xml or with a member too large to extract. Reads the listing only
    (of ``data``, the file's bytes, if given)."""
    path = pathlib.Path(path)
    if path.is_dir():
        raise FmuFileError(f"FMU {path}: is a folder; an FMU is a .fmu (zip) file")
    if not path.is_file():
        raise FmuFileError(f"FMU {path}: does not exist")
    try:
        with zipfile.ZipFile(path if data is None else io.BytesIO(data)) as archive:
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
    """Model description and extraction folder of an FMU file, once per process: from the
    cache of unpacked FMUs (cache_folder) when there is one, else unpacked into a folder
    removed when the process ends (also when the cache cannot be written: read-only, full)."""
    try:
        data = pathlib.Path(path).read_bytes()
    except OSError:
        data = None                                            # check_file names the problem
    members = check_file(path, data)
    cache = cache_folder()
    if cache is not None:
        try:
            return _cached(data, members, cache)
        except OSError:
            pass
        except (zipfile.BadZipFile, ValueError) as exc:        # a member's CRC or XML fails
            raise FmuFileError(f"FMU {path}: cannot be read ({exc}); rebuild it") from None
    folder = scratch("movingbase-fmu-")
    try:
        return _unpacked(data, folder), folder
    except (zipfile.BadZipFile, OSError, ValueError) as exc:   # a member's CRC or XML fails, a full disk
        shutil.rmtree(folder, ignore_errors=True)               # nothing half-unpacked is left behind
        if isinstance(exc, OSError) and exc.errno == errno.ENOSPC:
            raise FmuFileError(f"FMU {path}: no space left to unpack it in {pathlib.Path(folder).parent} "
                               "(TMPDIR): free some, or set TMPDIR to a larger disk") from None
        raise FmuFileError(f"FMU {path}: cannot be read ({exc}); rebuild it") from None


def _unpacked(data, folder):
    """The model description of the FMU file's bytes ``data``, its members extracted into ``folder``."""
    description = read_model_description(io.BytesIO(data))
    extract(io.BytesIO(data), unzipdir=folder)
    return description


# ----------------------------------------------------------- the cache of unpacked FMUs
# Unpacking an FMU (fmpy's modelDescription parse with lxml, the zip extracted to a new
# folder) cost ~10 ms an FMU in every process. The cache keeps each FMU file's unpacked
# members and its parsed model description (pickled) in a folder named by the SHA-256 of
# the file's bytes: a rebuilt FMU is another entry, never a stale one. An entry is made in
# a temporary folder beside it and renamed into place whole, so concurrent processes
# (campaign workers, tests) see a complete entry or none; each use checks it (_checked:
# every member's size and modification time as written, the binaries' CRC-32 against the
# FMU's zip listing, the description's SHA-256; a CRC of every member took 3 ms an FMU),
# and one that fails is made again. Entries unused for STALE_DAYS go when one is made.
CACHE = "MOVINGBASE_FMU_CACHE"   # the cache's folder; "off": each process unpacks into its own temporary folder
CACHE_REVISION = 1               # in each entry's name: raised when an entry's layout changes
STALE_DAYS = 7
_MANIFEST = "manifest.json"


def cache_folder():
    """The folder of the unpacked-FMU cache: $MOVINGBASE_FMU_CACHE, else movingbase/fmu
    in $XDG_CACHE_HOME (~/.cache); None if $MOVINGBASE_FMU_CACHE is "off"."""
    chosen = os.environ.get(CACHE)
    if chosen == "off":
        return None
    if chosen:
        return pathlib.Path(chosen)
    return pathlib.Path(os.environ.get("XDG_CACHE_HOME") or pathlib.Path.home() / ".cache") / "movingbase" / "fmu"


def _entry_name(data):
    salt = f"movingbase FMU cache {CACHE_REVISION}, fmpy {fmpy_version}\0".encode()
    return hashlib.sha256(salt + data).hexdigest()[:32]


def _checked(entry, members):
    """The model description an entry holds if it is whole and unchanged, else None:
    every member there with the size of the FMU's listing and the size and modification
    time it was written with, the FMU's binaries (the code a run loads) with the listing's
    CRC-32 too, and the description the one written with them (its SHA-256)."""
    try:
        manifest = json.loads((entry / _MANIFEST).read_text(encoding="utf-8"))
        pickled = (entry / "description.pickle").read_bytes()
        if hashlib.sha256(pickled).hexdigest() != manifest["description_sha256"]:
            return None
        written = manifest["files"]
        for member in members:
            if member.is_dir():
                continue
            file = entry / "fmu" / member.filename
            stat = file.stat()
            if stat.st_size != member.file_size or written.get(member.filename) != [stat.st_size, stat.st_mtime_ns]:
                return None
            if member.filename.startswith("binaries/") and zlib.crc32(file.read_bytes()) != member.CRC:
                return None
        return pickle.loads(pickled)
    except Exception:   # missing, unreadable, torn or foreign: not trusted
        return None


def _written(folder, members):
    """{member: [size, modification time (ns)]} of the members as extracted into ``folder``."""
    stats = {m.filename: (folder / m.filename).stat() for m in members if not m.is_dir()}
    return {name: [stat.st_size, stat.st_mtime_ns] for name, stat in stats.items()}


def _cached(data, members, cache):
    """(model description, extraction folder) of the FMU file's bytes ``data`` from the
    cache, the entry made (or made again) first if it is missing or fails its check."""
    entry = cache / _entry_name(data)
    description = _checked(entry, members)
    if description is not None:
        with contextlib.suppress(OSError):   # a cache this process may read but not write
            os.utime(entry)                  # used: kept by the pruning
        return description, str(entry / "fmu")
    cache.mkdir(parents=True, exist_ok=True)
    made = pathlib.Path(tempfile.mkdtemp(prefix=".part-", dir=cache))
    try:
        description = _unpacked(data, made / "fmu")
        pickled = pickle.dumps(description, protocol=pickle.HIGHEST_PROTOCOL)
        (made / "description.pickle").write_bytes(pickled)
        (made / _MANIFEST).write_text(json.dumps({"description_sha256": hashlib.sha256(pickled).hexdigest(),
                                                  "files": _written(made / "fmu", members)}), encoding="utf-8")
        _prune(cache)
        for _ in range(2):
            try:
                os.rename(made, entry)   # atomic; refused while a (non-empty) entry of that name exists
                return description, str(entry / "fmu")
            except OSError:
                found = _checked(entry, members)
                if found is not None:    # another process made it meanwhile
                    return found, str(entry / "fmu")
                _discard(entry)          # a damaged entry: moved aside, ours takes its place
        raise OSError(errno.EEXIST, f"cache entry {entry} keeps being replaced")   # unpacked for this process
    finally:
        shutil.rmtree(made, ignore_errors=True)   # (gone once renamed into place)


def _discard(folder):
    """Move ``folder`` aside (one rename: no process finds it half-removed), then remove it."""
    aside = folder.with_name(f".stale-{folder.name}-{os.getpid()}-{time.monotonic_ns()}")
    try:
        os.rename(folder, aside)
    except OSError:
        return
    shutil.rmtree(aside, ignore_errors=True)


def _prune(cache):
    """Remove the entries unused for STALE_DAYS, and the parts that killed processes left."""
    now = time.time()
    for folder in cache.iterdir():
        try:
            age = now - folder.stat().st_mtime
        except OSError:
            continue
        if age > STALE_DAYS * 86400 or (folder.name.startswith((".part-", ".stale-")) and age > 3600):
            _discard(folder)


SCRATCH = "MOVINGBASE_SCRATCH"   # where a process makes its temporary folders (the campaign workers': the
                                 # client's folder, which it removes even when a worker was killed)


def scratch(prefix):
    """A new temporary folder, removed when the process ends (atexit: a normal end,
    Ctrl-C, SIGTERM to the command); under $MOVINGBASE_SCRATCH if set."""
    folder = tempfile.mkdtemp(prefix=prefix, dir=os.environ.get(SCRATCH) or None)
    _FOLDERS.append(folder)
    return folder


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


def _slave(cls, folder, guid, identifier, name):
    """An fmpy slave for one new instance, on its FMU's library loaded and bound once per
    process: loading it and binding its functions (fmpy inspects every signature) cost
    ~3 ms an instance, half of a campaign run's engine overhead (docs/speed.md). Each instance
    is still its own fmi2Instantiate (fmi3Instantiate...), so nothing but the library's
    code is shared between runs (the native FMUs keep no state outside their instance);
    the library stays loaded until the process ends."""
    loaded = _LOADED.get((cls, folder))
    if loaded is None:
        loaded = _LOADED[(cls, folder)] = cls(guid=guid, unzipDirectory=folder, instanceName=name,
                                              modelIdentifier=identifier)
        loaded.freeLibrary = lambda: None      # freeInstance unloads it otherwise, under the other instances
    slave = copy.copy(loaded)                  # the same library and bound functions
    slave.instanceName, slave.component, slave.callbacks = name, None, None
    return slave

class Instance:
    """One FMU instance: instantiate, set parameters, initialise, step, read/write."""

    def __new__(cls, path, name):
        """An FMI 3.0 FMU file opens as an Instance3."""
        if cls is Instance and unpack(path)[0].fmiVersion.startswith("3"):
            cls = Instance3
        return super().__new__(cls)

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
        self.fmu = _slave(FMU2Slave, folder, self.md.guid, self.md.coSimulation.modelIdentifier, name)
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

    def __new__(cls, instance, names):
        """A port of an FMI 3.0 instance is a RealPort3."""
        return super().__new__(RealPort3 if isinstance(instance, Instance3) else cls)

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


# ------------------------------------------------------------------------- FMI 3.0
# An FMI 3.0 FMU (fmu_src/native_build.build_native3) runs in the same master: Instance3
# shows its variables as the FMI 2.0 FMU names them (leg_force[1..6] for the array
# leg_force, each element's value reference the array's plus its offset, as
# native_build numbers them), so the checks and the exchange are the same code for
# both; its ports (RealPort3) and the C stepping loop make the FMI 3.0 calls.
_TYPES3 = {"Float64": "Real", "Int32": "Integer", "Enumeration": "Enumeration", "String": "String"}
_GET3 = CFUNCTYPE(c_int, c_void_p, POINTER(c_uint), c_size_t, POINTER(c_double), c_size_t)
_DERIVATIVES3 = CFUNCTYPE(c_int, c_void_p, POINTER(c_uint), c_size_t, POINTER(c_int32), POINTER(c_double), c_size_t)
_DO_STEP3 = CFUNCTYPE(c_int, c_void_p, c_double, c_double, c_int, POINTER(c_bool), POINTER(c_bool),
                      POINTER(c_bool), POINTER(c_double))


def element_count(var):
    """How many values an FMI 3.0 variable holds: the product of its dimensions (1: a scalar)."""
    return int(np.prod([int(d.start) for d in var.dimensions])) if var.dimensions else 1


def _elements(md3):
    """The FMI 3.0 model description ``md3`` with its variables as FMI 2.0 elements: an
    array name of n elements becomes name[1] .. name[n]; the independent time is left out."""
    md = copy.copy(md3)
    md.modelVariables = []
    for var in md3.modelVariables:
        if var.causality == "independent":
            continue
        if var.type not in _TYPES3:
            raise FmuError(f"{md3.modelName}: variable {var.name} is an FMI 3 {var.type}, which the master does not "
                           "exchange")
        count = element_count(var)
        starts = [var.start] if var.type == "String" else var.start.split() if var.start is not None else [None] * count
        for k in range(count):
            element = copy.copy(var)
            element.name = f"{var.name}[{k + 1}]" if var.dimensions else var.name
            element.valueReference = var.valueReference + k
            element.type = _TYPES3[var.type]
            element.unit = var.unit or getattr(var.declaredType, "unit", None)   # a unit by Float64Type
            element.displayUnit = var.displayUnit or getattr(var.declaredType, "displayUnit", None)
            element.declaredType = var.declaredType if var.type == "Enumeration" else None
            element.start = starts[k]
            element.dimensions = []
            md.modelVariables.append(element)
    return md


def description(path):
    """The model description a scenario is checked against: an FMI 3.0 FMU's variables as
    FMI 2.0 elements (see _elements), an FMI 2.0 FMU's as they are."""
    md = unpack(path)[0]
    return _elements(md) if md.fmiVersion.startswith("3") else md


def derivative_orders(md3):
    """FMI 3 output value reference -> the highest order of time derivative
    fmi3GetOutputDerivatives gives of it: the chain of outputs declared each other's
    derivative (the Float64 attribute derivative), at most maxOutputDerivativeOrder."""
    outputs = {v.valueReference for v in md3.modelVariables if v.causality == "output"}
    derivative_of = {v.derivative.valueReference: v.valueReference for v in md3.modelVariables
                     if v.valueReference in outputs and getattr(v, "derivative", None) is not None
                     and v.derivative.valueReference in outputs}
    top = int(md3.coSimulation.maxOutputDerivativeOrder or 0)

    def order(vr):
        return 1 + order(derivative_of[vr]) if vr in derivative_of else 0
    return {vr: min(order(vr), top) for vr in outputs if order(vr) and top}


class Instance3(Instance):
    """An FMI 3.0 instance behind Instance's interface (fmpy's FMU3Slave): variables by
    their FMI 2.0 element names, read and written through RealPort3 (whole FMI 3
    variables in one call); ``raw`` gives the dll's fmi3DoStep/fmi3GetFloat64/
    fmi3SetFloat64, which the C stepping loop calls directly (master.Loop)."""

    def __init__(self, path, name):
        self.name = name
        md3, folder = unpack(path)
        self.md = _elements(md3)
        self.variables = {v.name: v for v in self.md.modelVariables}
        self.arrays = {}   # element value reference -> (FMI 3 value reference, offset, element count)
        for var in md3.modelVariables:
            count = element_count(var)
            for k in range(count):
                self.arrays[var.valueReference + k] = (var.valueReference, k, count)
        self.starts = {v.valueReference: v.start for v in self.md.modelVariables}
        self.log = []
        self.fmu = _slave(FMU3Slave, folder, md3.guid, md3.coSimulation.modelIdentifier, name)
        self.time = 0.0
        self.freed = False
        self.call("instantiate", loggingOn=True, logMessage=self._on_log3)
        dll = self.fmu.dll
        self._raw3 = {"fmi3GetFloat64": _GET3(("fmi3GetFloat64", dll)),
                      "fmi3SetFloat64": _GET3(("fmi3SetFloat64", dll)),
                      "fmi3DoStep": _DO_STEP3(("fmi3DoStep", dll)),
                      "fmi3GetOutputDerivatives": _DERIVATIVES3(("fmi3GetOutputDerivatives", dll))}
        self.derivative_order = derivative_orders(md3)
        self._step_out = c_bool(), c_bool(), c_bool(), c_double()

    def _on_log3(self, environment, status, category, message):
        self.log.append(f"[{_LABELS[status]}] {message.decode(errors='replace')}")

    def raw(self, function):
        return self._raw3[function]

    def plan(self, vrs):
        """For element value references ``vrs``: the FMI 3 variables they lie in, the
        number of values of those, and where each element is among those values."""
        arrays, at = [], {}
        for vr in vrs:
            if vr not in self.arrays:
                raise KeyError(f"FMU instance '{self.name}': no Float64 element has value reference {vr}")
            array, _, count = self.arrays[vr]
            if array not in at:
                at[array] = sum(self.arrays[a][2] for a in arrays)
                arrays.append(array)
        total = sum(self.arrays[a][2] for a in arrays)
        return arrays, total, np.array([at[self.arrays[vr][0]] + self.arrays[vr][1] for vr in vrs], dtype=np.intp)

    def _check(self, function, status):
        if status > 1:
            self.fail(function, f"status {_LABELS[status]}")

    def set(self, name, value):
        self.vr(name)
        var = self.variables[name]
        if var.type == "Integer":
            self.call("setInt32", [var.valueReference], [int(value)])
        elif var.type == "Enumeration":
            self.call("setInt64", [var.valueReference], [int(value)])
        elif var.type == "String":
            self.call("setString", [var.valueReference], [str(value)])
        else:
            RealPort3(self, [name]).write([float(value)])

    def get_real(self, name):
        return RealPort3(self, [name]).read()[0]

    def initialize(self, start_time, values=None):
        """Enter initialization mode at ``start_time``, set ``values``, exit. An array's
        elements are set in one call: those not given keep their start values."""
        self.time = start_time
        self.call("enterInitializationMode", startTime=start_time)
        reals = {}
        for name, value in (values or {}).items():
            self.vr(name)
            var = self.variables[name]
            if var.type == "Real":
                array, offset, count = self.arrays[var.valueReference]
                if array not in reals:
                    reals[array] = [float(self.starts[array + k]) for k in range(count)]
                reals[array][offset] = float(value)
            else:
                self.set(name, value)
        for array, elements in reals.items():
            self.call("setFloat64", [array], elements)
        self.call("exitInitializationMode")

    def do_step(self, t, h):
        self.time = t
        self._check("doStep", self._raw3["fmi3DoStep"](self.fmu.component, t, h, True,
                                                        *(byref(out) for out in self._step_out)))


class RealPort3(RealPort):
    """RealPort of an FMI 3.0 instance: the FMI 3 variables holding the elements, read or
    written whole in one fmi3GetFloat64/fmi3SetFloat64 call (master.Loop hands the same
    plan to the C loop). A write of part of an array reads it first: the elements not
    written keep the values the FMU holds."""

    def __init__(self, instance, names):
        self.instance = instance
        self.names = list(names)
        self.n = len(self.names)
        arrays, self.total, self.index = instance.plan([instance.vr(v) for v in self.names])
        self.vrs3 = arrays
        self.partial = len(set(self.index.tolist())) != self.total
        self._vr = (c_uint * len(arrays))(*arrays)
        self._buf = (c_double * self.total)()
        self._all = np.ctypeslib.as_array(self._buf)
        # the elements are the variables' values in order (scalars, whole arrays): no gather
        self._direct = self.total == self.n and np.array_equal(self.index, np.arange(self.n))
        self.values = self._all if self._direct else np.zeros(self.n)
        self._get, self._set = instance.raw("fmi3GetFloat64"), instance.raw("fmi3SetFloat64")

    def _get_all(self):
        status = self._get(self.instance.fmu.component, self._vr, len(self.vrs3), self._buf, self.total)
        if status > 1:
            self.instance.fail("getReal", f"status {_LABELS[status]}")

    def read(self):
        self._get_all()
        if not self._direct:
            self.values[:] = self._all[self.index]
        return self.values

    def write(self, values):
        self.values[:] = values
        if self.partial:
            self._get_all()
        if not self._direct:
            self._all[self.index] = self.values
        status = self._set(self.instance.fmu.component, self._vr, len(self.vrs3), self._buf, self.total)
        if status > 1:
            self.instance.fail("setReal", f"status {_LABELS[status]}")
