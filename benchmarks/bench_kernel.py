"""The hexapod kernel's forward dynamics against its throughput floor (the kernel's goal, docs/speed.md).

The RK4 step of the plant FMU (mb_hexapod_advance_actuated, full base motion, massive legs,
four forward-dynamics evaluations and the leg read-out) per evaluation, timed next to a loop
doing only the operations of that step that bound it from below at their throughput, each
independent of the others (counted in plant/c/hexapod.c and linalg.c, and as executed by
callgrind's per-instruction counts):
  divides  4 x (15 in det J's elimination, 21 in the solve of M, 1 in the RPY rates)
           + 2 for the step size + 7 in the read-out (leg rates, RPY rates), scalar; and
           4 x 7 per pair of legs x 3 pairs, two-lane
  sqrt     4 x 6 leg lengths + 6 in the read-out
  sincos   4 x 3 of the pose's angles + 3 x 3 of the base's (the two middle stages share a
           time, so a base) + 3 in the read-out.
Both come from
benchmarks/kernel_floor.c, compiled with the native FMUs' flags; runs alternate, the
medians are printed. ``--against REV`` compiles the kernel of git revision REV too and
times it in the same run (before / after); ``--digest`` prints a hash of every output bit
of both over random states of every mode (equal hashes: the same bits); ``--callgrind``
counts the instructions of 2000 RK4 steps of each under valgrind's callgrind (repeatable
on a loaded machine, where times are not).
Prints figures; it asserts nothing (speed is not a test).

    python benchmarks/bench_kernel.py [--against REV] [--digest] [--callgrind] [--repeats 41]
"""
import argparse
import ctypes
import os
import pathlib
import re
import statistics
import subprocess
import tempfile

import numpy as np

from fmu_src.native_build import CFLAGS
from plant.hexapod.model import HOME_POSE, StewartParams, inverse_dynamics

ROOT = pathlib.Path(__file__).resolve().parents[1]
KERNEL_FILES = ("hexapod.c", "hexapod.h", "linalg.c", "linalg.h")
DIVIDES, PAIR_DIVIDES = 4 * (15 + 21 + 1) + 2 + 7, 4 * 7 * 3   # an RK4 step
SQRTS, SINCOS = 4 * 6 + 6, 4 * 3 + 3 * 3 + 3
STEPS = 4000   # a run of ~15 ms: short, so that the machine's load changes little within a round


def compile_driver(folder, source, program=False):
    """kernel_floor.c over the kernel files in ``source`` (a folder), compiled into ``folder``
    with the native FMUs' flags: a shared library, or (``program``) the callgrind driver."""
    target = pathlib.Path(folder) / f"kernel_{abs(hash(str(source)))}{'' if program else '.so'}"
    sources = [ROOT / "benchmarks" / "kernel_floor.c", source / "hexapod.c", source / "linalg.c"]
    flags = [f for f in CFLAGS if not f.startswith("-fvisibility") and not (program and f in ("-shared", "-fPIC"))]
    cmd = [os.environ.get("CC", "cc"), *flags, *(["-DKERNEL_FLOOR_MAIN"] if program else []), f"-I{source}",
           *map(str, sources), "-o", str(target), "-lm"]
    run = subprocess.run(cmd, capture_output=True, text=True)
    if run.returncode:
        raise RuntimeError(f"compiling the kernel benchmark failed:\n{' '.join(cmd)}\n{run.stderr}")
    return target


def instructions(folder, source, numbers, steps=2000):
    """Instructions callgrind counts for ``steps`` RK4 steps of the kernel in ``source``."""
    program = compile_driver(folder, source, program=True)
    data = pathlib.Path(folder) / "numbers.txt"
    data.write_text("\n".join(repr(float(v)) for v in numbers))
    run = subprocess.run(["valgrind", "--tool=callgrind", "--toggle-collect=kernel_time",
                          f"--callgrind-out-file={folder}/callgrind.out", str(program), str(data), str(steps)],
                         capture_output=True, text=True)
    found = re.search(r"Collected : (\d+)", run.stderr)
    if run.returncode or not found:
        raise RuntimeError(f"callgrind failed:\n{run.stderr}")
    return int(found.group(1))


def build(folder, source):
    """The shared library of compile_driver, its functions typed."""
    lib = ctypes.CDLL(str(compile_driver(folder, source)))
    dp = ctypes.POINTER(ctypes.c_double)
    lib.kernel_time.argtypes = [dp, dp, dp, dp, ctypes.c_long]
    lib.kernel_time.restype = ctypes.c_double
    lib.floor_time.argtypes = [ctypes.c_int, ctypes.c_int, ctypes.c_int, ctypes.c_int, ctypes.c_long, dp]
    lib.floor_time.restype = ctypes.c_double
    lib.digest.argtypes = [dp, dp, ctypes.c_long]
    lib.digest.restype = ctypes.c_uint64
    return lib


def revision_sources(folder, rev):
    """The kernel files of git revision ``rev`` written into ``folder``."""
    out = pathlib.Path(folder) / f"rev_{rev}"
    out.mkdir()
    for name in KERNEL_FILES:
        text = subprocess.run(["git", "show", f"{rev}:plant/c/{name}"], cwd=ROOT, check=True, capture_output=True,
                              text=True).stdout
        (out / name).write_text(text)
    return out


def ptr(a):
    return a.ctypes.data_as(ctypes.POINTER(ctypes.c_double))


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--against", help="git revision whose kernel is timed alongside")
    parser.add_argument("--digest", action="store_true", help="print a hash of every output bit")
    parser.add_argument("--callgrind", action="store_true", help="count instructions under valgrind's callgrind")
    parser.add_argument("--repeats", type=int, default=41)
    args = parser.parse_args()

    p = StewartParams.paper()
    params = np.ascontiguousarray(np.r_[p.base_joints.ravel(), p.platform_joints.ravel(), p.kernel_data])
    base = [np.array([3.0, -2.0, 25.0, 0.7, 0.2, 0.5]), np.array([0.1, -0.2, 0.05, 0.02, -0.03, 0.04]),
            np.array([0.3, 0.1, -0.2, 0.05, 0.01, -0.02])]
    pose = HOME_POSE + np.array([0.01, -0.02, 0.03, 0.02, -0.01, 0.03])
    x0 = np.r_[pose, 0.01, -0.02, 0.01, 0.05, -0.03, 0.02, np.zeros(6)]
    forces = inverse_dynamics(p, pose, np.zeros(6), np.zeros(6), *base)
    inputs = np.ascontiguousarray(np.r_[forces, *base, np.zeros(6)])
    act = np.zeros(6)
    home = np.ascontiguousarray(HOME_POSE, dtype=float)
    sink = np.zeros(1)

    with tempfile.TemporaryDirectory() as folder:
        sources = {"this tree": ROOT / "plant" / "c"}
        if args.against:
            sources[args.against] = revision_sources(folder, args.against)
        kernels = {name: build(folder, source) for name, source in sources.items()}
        if args.callgrind:
            for name, source in sources.items():
                n = instructions(folder, source, np.r_[params, x0, inputs, act])
                print(f"callgrind ({name}): {n:,} instructions in 2000 RK4 steps, {n / 8000:,.0f} an evaluation")
        if args.digest:
            for name, lib in kernels.items():
                print(f"digest of the kernel's output bits ({name}): {lib.digest(ptr(params), ptr(home), 2000):016x}")
        lib0 = kernels["this tree"]
        times = {name: [] for name in kernels}
        floor = []
        for lib in kernels.values():   # warm up
            lib.kernel_time(ptr(params), ptr(x0), ptr(inputs), ptr(act), STEPS // 10)
        for _ in range(args.repeats):
            for name, lib in kernels.items():
                times[name].append(lib.kernel_time(ptr(params), ptr(x0), ptr(inputs), ptr(act), STEPS))
            floor.append(lib0.floor_time(DIVIDES, PAIR_DIVIDES, SQRTS, SINCOS, STEPS, ptr(sink)))
        f = statistics.median(floor)
        print(f"throughput floor ({DIVIDES} divides, {PAIR_DIVIDES} two-lane divides, {SQRTS} sqrt, {SINCOS} sincos "
              f"an RK4 step): {1e6 * f:.3f} us/evaluation")
        for name, t in times.items():   # kernel / floor within each round, where both ran under the same load
            ratio = statistics.median(k / fl for k, fl in zip(t, floor))
            print(f"forward dynamics ({name}): {1e6 * statistics.median(t):.3f} us/evaluation -> "
                  f"kernel = {ratio:.2f} x floor")
        if args.against:   # the ratio within each round, where both ran under the same load
            ratios = [a / b for a, b in zip(times["this tree"], times[args.against])]
            print(f"this tree / {args.against}: {statistics.median(ratios):.3f} (median of the ratios of "
                  f"{args.repeats} "
                  f"rounds of {STEPS} RK4 steps each; fastest runs: "
                  f"{min(times['this tree']) / min(times[args.against]):.3f})")


if __name__ == "__main__":
    main()
