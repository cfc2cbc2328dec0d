"""Drive an FMU from a process that is not Python: tests/hosts/c_host/fmi2_host.c, compiled with
the machine's cc against fmpy's FMI 2 headers, run in a fresh process per call.

Why: fmpy runs FMUs inside a Python process, which hides what a C importer sees (an
embedded interpreter's shutdown, statuses the Python wrapper folds away). The host is
generic; everything FMU-specific (value references, GUID) comes from the model
description here.

pythonfmu FMUs embed CPython: in a C host they need libpython loaded globally
(LD_PRELOAD) and PYTHONPATH naming where the FMU's Python dependencies live
(pythonfmu_env below; docs/fmi-notes-measured.md).
"""
import dataclasses
import hashlib
import math
import os
import pathlib
import re
import signal
import subprocess
import sys
import sysconfig
import tempfile
import zipfile

import fmpy
from fmpy import read_model_description

from fmu_src import catalogue

SOURCE = pathlib.Path(__file__).resolve().parent / "c_host" / "fmi2_host.c"
MISUSE = SOURCE.with_name("misuse.c")
MISUSE3 = SOURCE.with_name("misuse3.c")   # the FMI 3.0 misuse host
HEADERS = pathlib.Path(fmpy.__file__).resolve().parent / "c-code"


@dataclasses.dataclass
class HostRun:
    returncode: int       # the host's exit code (worst fmi2Status), or -signal
    signal: str | None    # e.g. "SIGSEGV" when the process died of a signal
    stdout: str
    stderr: str

    def lines(self, tag):
        """The value lists of stdout lines starting with ``tag`` ("out", "replay", ...)."""
        return [[float(x) for x in line.split()[1:]] for line in self.stdout.splitlines()
                if line.startswith(tag + " ")]

    def statuses(self):
        """(call, status) for every call that did not answer fmi2OK."""
        return [tuple(line.split()[1:3]) for line in self.stdout.splitlines() if line.startswith("status ")]


def compile_host(cache=None, source=SOURCE):
    """Path of the compiled host (``source``: fmi2_host.c, misuse.c or misuse3.c), built once per
    source/header/flags hash into a temporary cache. MOVINGBASE_HOST_CFLAGS adds compiler
    flags: .ci/sanitize.sh builds the host with the sanitizers of the FMUs it loads."""
    flags = os.environ.get("MOVINGBASE_HOST_CFLAGS", "").split()
    digest = hashlib.sha256(source.read_bytes() + " ".join(flags).encode())
    for header in sorted([*HEADERS.glob("fmi*.h"), *source.parent.glob("*.h")]):   # fmpy's and misuse_common.h
        digest.update(header.read_bytes())
    cache = pathlib.Path(cache or tempfile.gettempdir()) / "movingbase-c-host"
    cache.mkdir(parents=True, exist_ok=True)
    exe = cache / f"{source.stem}-{digest.hexdigest()[:16]}"
    if not exe.exists():
        tmp = exe.with_suffix(f".{os.getpid()}.tmp")
        cc = os.environ.get("CC", "cc")
        p = subprocess.run([cc, "-O1", "-g", "-Wall", "-Wextra", "-Werror", *flags, "-I", str(HEADERS), str(source),
                            "-o", str(tmp), "-ldl", "-lpthread"], capture_output=True, text=True)
        if p.returncode:
            raise RuntimeError(f"compiling {source.name} with {cc} failed:\n{p.stderr}")
        tmp.replace(exe)   # atomic: parallel test processes never see half a binary
    return exe


def extract(fmu, folder):
    """Unzip an FMU into folder; returns the folder."""
    folder = pathlib.Path(folder)
    with zipfile.ZipFile(fmu) as z:
        z.extractall(folder)
    return folder


def pythonfmu_env(extra_paths=()):
    """Environment for a C host running a pythonfmu FMU: libpython preloaded (the wrapper
    links no libpython, and numpy's extension modules need its symbols global) and
    PYTHONPATH = this interpreter's sys.path (its site-packages and, for the editable
    install, the checkout), so the FMU's Python finds what this one finds: the
    environment docs/hosts.md gives a C-tool user."""
    libpython = pathlib.Path(sysconfig.get_config_var("LIBDIR")) / sysconfig.get_config_var("INSTSONAME")
    paths = [*extra_paths, *(p for p in sys.path if p and os.path.isdir(p))]
    env = dict(os.environ)
    env["LD_PRELOAD"] = str(libpython)
    env["PYTHONPATH"] = os.pathsep.join(dict.fromkeys(paths))
    env.pop("PYTHONHOME", None)
    return env


class HostFmu:
    """An extracted FMU with its model description: names to value references."""

    def __init__(self, fmu, folder):
        self.folder = extract(fmu, folder)
        self.md = read_model_description(str(fmu))
        self.vars = {v.name: v for v in self.md.modelVariables}

    def vr(self, name):
        return self.vars[name].valueReference

    def run(self, steps=10, h=1e-3, real=None, integer=None, real_init=None, real_at=None, out=(),
            state=None, keep_going=False, dlclose=True, env=None, timeout=120, timed=False, init_out=False):
        """Run the host once on this FMU. ``real``/``integer``/``real_init``: {name: value};
        ``real_at``: {(step, name): value}; ``out``: names printed every step (and, with
        ``init_out``, in initialization mode: the "init" line)."""
        args = [str(compile_host()), str(self.folder), self.md.coSimulation.modelIdentifier, self.md.guid,
                "--steps", str(steps), "--h", repr(h)]
        for option, values in (("--real", real), ("--int", integer), ("--real-init", real_init)):
            for name, value in (values or {}).items():
                args += [option,
                         f"{self.vr(name)}={float(value)!r}" if option != "--int" else f"{self.vr(name)}={int(value)}"]
        for (step, name), value in (real_at or {}).items():
            args += ["--real-at", f"{step}:{self.vr(name)}={float(value)!r}"]
        if out:
            args += ["--out", ",".join(str(self.vr(n)) for n in out)]
        if state is not None:
            args += ["--state", str(state)]
        if keep_going:
            args.append("--keep-going")
        if not dlclose:
            args.append("--no-dlclose")
        if timed:
            args.append("--time")
        if init_out:
            args.append("--init-out")
        p = subprocess.run(args, capture_output=True, text=True, timeout=timeout,
                           env=pythonfmu_env() if env is None else env)
        sig = signal.Signals(-p.returncode).name if p.returncode < 0 else None
        return HostRun(p.returncode, sig, p.stdout, p.stderr)


MODELS = sorted(catalogue.BY_IDENTIFIER)   # every FMU of the kit: a new one meets the hostile hosts too


class Fmu:
    """An extracted FMU: folder, model description, value references by name."""

    def __init__(self, folder, env=None, host=MISUSE):
        self.folder = pathlib.Path(folder)
        self.host = host   # misuse.c (FMI 2.0) or misuse3.c (FMI 3.0)
        self.md = read_model_description(str(self.folder / "modelDescription.xml"))
        self.id = self.md.coSimulation.modelIdentifier
        self.vars = {v.name: v for v in self.md.modelVariables}
        self.env = env

    def vr(self, name):
        return self.vars[name].valueReference

    def first(self, causality):
        """The first Real (FMI 3.0: Float64, maybe an array) variable of a causality, or None."""
        return next((v.name for v in self.md.modelVariables
                     if v.causality == causality and v.type in ("Real", "Float64")), None)

    def count(self, name):
        """Number of elements of a variable (an FMI 3.0 array: its dimensions' product)."""
        return math.prod(int(d.start) for d in self.vars[name].dimensions or [])


def run(fmu, *script, timeout=60, wrapper=()):
    """Run misuse.c on ``fmu`` with ``script`` (words; a ("vr", name) pair is the value
    reference of name); asserts the process ended by itself, cleanly."""
    words = []
    for word in script:
        words.append(str(fmu.vr(word[1])) if isinstance(word, tuple) else repr(word) if isinstance(word, float)
                     else str(word))
    args = [*wrapper, str(compile_host(source=fmu.host)), str(fmu.folder), fmu.id, fmu.md.guid, *words]
    p = subprocess.run(args, capture_output=True, text=True, timeout=timeout, env=fmu.env)
    assert p.returncode == 0, (p.returncode, p.stdout[-2000:], p.stderr[-3000:])
    assert "runtime error" not in p.stderr and "Sanitizer" not in p.stderr, p.stderr[-3000:]
    answers = Answers(p.stdout)
    assert answers.lines and answers.lines[-1] == "done", p.stdout[-2000:]
    answers.check_log_states_status()
    return answers


INIT = ("setup", 0.0, "enter", "exit")


# ======================================================================= FMI 3.0
# The FMI 3.0 builds of the same models (fmu_src/native/fmi3_layer.c over the FMI 2.0
# layer) under misuse3.c. Statuses as FMI 3.0 specifies: fmi3Error with a log line for a
# call its state machine does not allow (Instantiated, InitializationMode, StepMode,
# StepDiscarded, Terminated), for wrong nValues, unknown value references, NULL arrays
# and bytes that are not a state; Discard (terminateSimulation true, the instance then
# StepDiscarded) for a step the model refuses.
INIT3 = ("enter", 0.0, "exit")


def run3(fmu, *script, **kwargs):
    return run(fmu, *words3(fmu, script), **kwargs)


class Answers:
    """What one run printed: calls with their statuses, log lines, values."""

    def __init__(self, stdout):
        self.lines = stdout.splitlines()
        self.calls = [tuple(line.split()) for line in self.lines if re.fullmatch(r"fmi[23]\w+ \w+", line)]
        self.logs = [line[4:] for line in self.lines if line.startswith("log ")]
        self.values = {int(line.split()[1]): float(line.split()[2]) for line in self.lines if line.startswith("value ")}
        self.vectors = [[float(x) for x in line.split()[2:]] for line in self.lines if line.startswith("value ")]

    def statuses(self, call):
        return [status for name, status in self.calls if name == call]

    def check_log_states_status(self):
        """Each call that did not answer OK follows a log line of its own status."""
        for k, line in enumerate(self.lines):
            match = re.fullmatch(r"(fmi[23]\w+) (Warning|Discard|Error|Fatal|NULL)", line)
            if match:
                expected = "Error" if match[2] == "NULL" else match[2]
                assert k > 0 and self.lines[k - 1].startswith(f"log {expected} "), (line, self.lines[max(0, k - 2):k])


def words3(fmu, script):
    """Expand a script's FMI 3 shorthands: ("get", name) -> getf VR N; ("set", name, x)
    -> setf VR N x..x (every element x); ("vr", name) -> VR."""
    out = []
    for word in script:
        if isinstance(word, tuple) and word[0] == "get":
            out += ["getf", ("vr", word[1]), fmu.count(word[1])]
        elif isinstance(word, tuple) and word[0] == "set":
            out += ["setf", ("vr", word[1]), fmu.count(word[1]), *[word[2]] * fmu.count(word[1])]
        else:
            out.append(word)
    return out
