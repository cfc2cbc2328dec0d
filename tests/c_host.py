"""Drive an FMU from a process that is not Python: tests/c_host/fmi2_host.c, compiled with
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
import functools
import hashlib
import os
import pathlib
import signal
import site
import subprocess
import sys
import sysconfig
import tempfile
import zipfile

import fmpy
from fmpy import read_model_description

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


@functools.cache
def _site_folder():
    """A folder holding a sitecustomize.py that adds this interpreter's site-packages as a
    site directory (its .pth files, the editable install's finder among them, are read)."""
    folder = tempfile.mkdtemp(prefix="movingbase-site-")
    sites = [p for p in site.getsitepackages() if os.path.isdir(p)]
    pathlib.Path(folder, "sitecustomize.py").write_text(
        "import site\n" + "".join(f"site.addsitedir({p!r})\n" for p in sites))
    return folder


def pythonfmu_env(extra_paths=()):
    """Environment for a C host running a pythonfmu FMU: libpython preloaded (the wrapper
    links no libpython, and numpy's extension modules need its symbols global) and
    PYTHONPATH = this interpreter's sys.path, so the FMU's Python finds what this one
    finds. The editable install maps ``movingbase`` onto the checkout's folders by a
    finder that a .pth file in site-packages installs, and .pth files are read only in
    site directories, not on PYTHONPATH: a sitecustomize adds this interpreter's
    site-packages as a site directory (_site_folder)."""
    libpython = pathlib.Path(sysconfig.get_config_var("LIBDIR")) / sysconfig.get_config_var("INSTSONAME")
    paths = [*extra_paths, _site_folder(), *(p for p in sys.path if p and os.path.isdir(p))]
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
                args += [option, f"{self.vr(name)}={float(value)!r}" if option != "--int" else f"{self.vr(name)}={int(value)}"]
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
