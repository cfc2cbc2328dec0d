"""cffi builders of the C kernels, run when the package installs (setup.py).

The physics exists once, in C: plant/c/*.c (hexapod, 3T mechanism, telescope, small
linear solves) and controller/c/*.c (PID). The Python API calls them through the
extension modules built here (plant._kernel, controller._kernel); the native FMUs compile
the same files into their binaries (fmu_src/native). scenarios/cosim/c/cosim.c is the
co-simulation master's stepping loop (scenarios.cosim._cosim, called by scenarios/cosim/master.py).

Every header of a folder is declared to cffi, minus its preprocessor lines, so a header
holds only plain C declarations (functions, enums, structs without macros in them).
Compiled with -ffp-contract=off so that no fused multiply-add makes the cffi build and an
FMU build of the same source round differently.
"""
import pathlib

from cffi import FFI

ROOT = pathlib.Path(__file__).resolve().parent
CFLAGS = ["-O2", "-std=c99", "-ffp-contract=off"]


def declarations(folder):
    """The C declarations of every header in ``folder`` (preprocessor lines dropped)."""
    lines = []
    for header in sorted(folder.glob("*.h")):
        lines += [ln for ln in header.read_text().splitlines() if not ln.lstrip().startswith("#")]
    return "\n".join(lines)


def builder(module, folders):
    """An FFI building ``module`` from the C files of ``folders`` (relative to ROOT);
    the headers of the first folder are the module's interface."""
    ffi = FFI()
    ffi.cdef(declarations(ROOT / folders[0]))
    headers = "\n".join(f'#include "{h.name}"' for f in folders for h in sorted((ROOT / f).glob("*.h")))
    sources = [str(c.relative_to(ROOT)) for f in folders for c in sorted((ROOT / f).glob("*.c"))]
    ffi.set_source(module, headers, sources=sources, include_dirs=[str(ROOT / f) for f in folders],
                   extra_compile_args=CFLAGS, libraries=["m"])
    return ffi


plant_ffi = builder("plant._kernel", ["plant/c"])
controller_ffi = builder("controller._kernel", ["controller/c"])
scenarios_ffi = builder("scenarios.cosim._cosim", ["scenarios/cosim/c"])

