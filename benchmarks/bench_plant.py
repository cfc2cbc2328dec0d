"""Hexapod plant speed on one core: the C kernel (plant/c/hexapod.c) side by side with
the numba kernel it replaced, git 73017ff (its plant/ modules kane, linalg, stewart,
hexapod_ode and their helpers, loaded as a package from git when numba is importable:
the `bench` extra), on the kernel itself and on the paths its callers take; and the
import cost of a fresh process. Prints figures; it asserts nothing (speed is not a test)."""
import os
import subprocess
import sys
import tempfile
import timeit
from pathlib import Path

os.environ.setdefault("NUMBA_NUM_THREADS", "1")
import numpy as np

from plant.hexapod import kernel as kane
from plant.hexapod import model as stewart
from plant.hexapod import ode as hexapod_ode

ROOT = Path(__file__).resolve().parents[1]
REVISION = "73017ff"
OLD_MODULES = ("kane", "linalg", "stewart", "errors", "rotations", "integrators", "hexapod_ode")


def side_by_side(fns, number, repeat=9):
    """Seconds per call of each of ``fns``, timed in alternation (best of ``repeat``) so
    that a busy machine slows them alike."""
    for fn in fns:
        fn()
    best = [float("inf")] * len(fns)
    for _ in range(repeat):
        for k, fn in enumerate(fns):
            best[k] = min(best[k], timeit.timeit(fn, number=number) / number)
    return best


def old_package(folder):
    """The plant modules of REVISION written as package ``plant_numba`` in ``folder``;
    None when git or the revision is not at hand."""
    package = Path(folder) / "plant_numba"
    package.mkdir()
    (package / "__init__.py").write_text("")
    for name in OLD_MODULES:
        done = subprocess.run(["git", "show", f"{REVISION}:plant/{name}.py"], cwd=ROOT, capture_output=True,
                              text=True)
        if done.returncode:
            return None
        (package / f"{name}.py").write_text(done.stdout)
    return package


def fresh_process(code):
    """Seconds the snippet ``code`` reports (it prints one float) in a new interpreter."""
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True,
                         env=dict(os.environ, PYTHONPATH=os.pathsep.join(sys.path)))
    if out.returncode:
        raise RuntimeError(f"fresh process failed:\n{out.stderr}")
    return float(out.stdout.split()[-1])


FIRST_CALL = """
import time, numpy as np
t = time.perf_counter()
{imports}
{call}
print(time.perf_counter() - t)
"""


def cases(rng):
    """(name, calls per timing, states per call or None for [us], function of a package
    namespace (kane, stewart, hexapod_ode) giving the callable)."""
    n = 100_000
    home = stewart.HOME_POSE
    pose = home + rng.normal(size=(n, 6)) * 0.02
    rate, acc = rng.normal(size=(n, 6)) * 0.1, rng.normal(size=(n, 6))
    base = [np.tile(np.array([0, 0, 25.0, 0.7, 0, 0.5]), (n, 1)), rng.normal(size=(n, 6)), rng.normal(size=(n, 6))]
    big = [np.empty((n, 6, 6)), np.empty((n, 6)), np.empty((n, 6, 6)), np.empty((n, 6)), np.empty((n, 6)),
           np.empty((n, 6)), np.empty(n)]
    b1 = [b[0].copy() for b in base]
    z6 = np.zeros(6)

    def batched_kernel(m):
        p = m.stewart.StewartParams.paper()
        args = (p.base_joints, p.platform_joints, p.kernel_data)
        return lambda: m.kane.kane(*args, pose, rate, acc, *base, kane.BASE_FULL, True, False, kane.ID, *big)

    def advance_kernel(m):
        """advance_fixed as the plant FMU calls it (through HexapodODE's arrays)."""
        p = m.stewart.StewartParams.paper()
        ode = m.hexapod_ode.HexapodODE(p)
        ode.set_inputs(0.0, m.stewart.inverse_dynamics(p, home, z6, z6, *b1), *b1)
        x0 = np.r_[home, z6]
        if m.kane is kane:
            return lambda: ode._kernel.advance_fixed(True, 1, x0.copy(), ode._inputs, 0.0, 1e-3, ode.base_mode,
                                                     ode.legs, ode._bounds, ode._outputs)
        return lambda: m.kane.advance_fixed(True, 1, *ode._args, x0.copy(), ode.inputs, 0.0, 1e-3, ode.base_mode,
                                            ode.legs, ode.bounds, ode.outputs)

    def plant_advance(m):
        p = m.stewart.StewartParams.paper()
        ode = m.hexapod_ode.HexapodODE(p)
        ode.set_inputs(0.0, m.stewart.inverse_dynamics(p, home, z6, z6))   # at rest, fixed base: stays put
        x = np.r_[home, z6]
        return lambda: ode.advance(x, 1e-3)

    def controller(m):
        sid = m.stewart.StateInverseDynamics(m.stewart.StewartParams.paper())
        return lambda: sid(pose[0], rate[0], acc[0], *b1)

    def controller_rows(m):
        """As the controller FMU calls it: the same six row views of its input block, refilled."""
        sid = m.stewart.StateInverseDynamics(m.stewart.StewartParams.paper())
        block = np.stack([pose[0], rate[0], acc[0], *b1])
        rows = tuple(block)
        return lambda: sid(*rows)

    def api(fn, *args):
        def make(m):
            p = m.stewart.StewartParams.paper()
            return lambda: getattr(m.stewart, fn)(p, *args)
        return make

    return [
        ("kernel: ID, batched 1e5, moving base [states/s]", 1, n, batched_kernel),
        ("kernel: advance_fixed, 1 ms RK4, moving base [us]", 5000, None, advance_kernel),
        ("stewart.inverse_dynamics, batched 1e5 [states/s]", 1, n, api("inverse_dynamics", pose, rate, acc, *base)),
        ("stewart.inverse_dynamics, one state [us]", 3000, None, api("inverse_dynamics", pose[0], rate[0], acc[0],
                                                                     *b1)),
        ("stewart.forward_dynamics, one state [us]", 3000, None, api("forward_dynamics", pose[0], rate[0], z6, *b1)),
        ("StateInverseDynamics, new (6,) views each call [us]", 5000, None, controller),
        ("StateInverseDynamics (controller FMU: kept rows) [us]", 5000, None, controller_rows),
        ("HexapodODE.advance (plant FMU), 1 ms RK4 [us]", 5000, None, plant_advance),
    ]


class Namespace:
    def __init__(self, **modules):
        self.__dict__.update(modules)


def main():
    rng = np.random.default_rng(0)
    packages = [Namespace(kane=kane, stewart=stewart, hexapod_ode=hexapod_ode)]
    with tempfile.TemporaryDirectory() as folder:
        try:
            import numba  # noqa: F401
            found = old_package(folder) is not None
        except ImportError:
            found = False
        cold = warm = None
        if found:
            sys.path.insert(0, folder)
            import plant_numba.hexapod_ode
            import plant_numba.kane
            import plant_numba.stewart
            packages.append(Namespace(kane=plant_numba.kane, stewart=plant_numba.stewart,
                                      hexapod_ode=plant_numba.hexapod_ode))
            # numba compiles lazily, at the first call: time the import and one call, first
            # with the numba cache empty (a new folder), then with the cache the first run left
            snippet = FIRST_CALL.format(
                imports=f"import sys; sys.path.insert(0, {folder!r}); from plant_numba import stewart",
                call="stewart.inverse_dynamics(stewart.StewartParams.paper(), stewart.HOME_POSE, np.zeros(6), "
                     "np.zeros(6))")
            cold, warm = fresh_process(snippet), fresh_process(snippet)
        c_import = fresh_process(FIRST_CALL.format(imports="import plant.stewart", call=""))
        c_first = fresh_process(FIRST_CALL.format(
            imports="from plant import stewart",
            call="stewart.inverse_dynamics(stewart.StewartParams.paper(), stewart.HOME_POSE, np.zeros(6), "
                 "np.zeros(6))"))

        print(f"{'':52s} {'C':>12s} {'numba':>12s} {'C speed-up':>10s}")
        for name, number, states, make in cases(rng):
            times = side_by_side([make(m) for m in packages], number)
            values = [states / t if states else 1e6 * t for t in times]
            line = f"{name:52s} {values[0]:12,.2f}"
            if len(values) > 1:   # > 1: C is faster
                line += f" {values[1]:12,.2f} {times[1] / times[0]:10.2f}"
            print(line)
        print()
        print("fresh process, import and first inverse_dynamics call [s]")
        print(f"{'C: import plant.stewart':52s} {c_import:12.3f}")
        print(f"{'C: import plant.stewart + one inverse_dynamics':52s} {c_first:12.3f}")
        if found:
            print(f"{'numba 73017ff: the same, empty numba cache':52s} {cold:12.3f}")
            print(f"{'numba 73017ff: the same, numba cache on disk':52s} {warm:12.3f}")


if __name__ == "__main__":
    main()
