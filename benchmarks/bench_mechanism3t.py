"""Per-call time of the 3T single-state kernel: C through cffi (plant.mechanism3t.kernel)
against the numba kernel it replaced (git revision 73017ff, when numba is importable),
measured in one run and printed side by side as ratios; then the step() of the two
pythonfmu slaves that use it (Mechanism3TPlant, SliderController, without the FMI layer)
with either kernel swapped in.

    .venv/bin/python benchmarks/bench_mechanism3t.py [--repeat 7] [--number 20000]
"""
import argparse
import tempfile
import time
import timeit

import numpy as np

from plant._kernel import ffi, lib  # noqa: E402
from plant.mechanism3t import kernel  # noqa: E402
from plant.mechanism3t import model as m3t  # noqa: E402


def calls(k, P, pa):
    """name -> zero-argument call of kernel module k at a state near the paper's."""
    rho = np.array(m3t.PAPER_REFERENCE_RHO_MM) * m3t.MM + 0.004
    rho_dot, rho_ddot, forces = np.array([0.01, -0.02, 0.03]), np.array([0.1, 0.2, -0.3]), np.array([170.0, 40.0,
                                                                                                     -50.0])
    x = np.r_[rho, rho_dot]
    M, bias, p, out = np.empty((3, 3)), np.empty(3), np.empty(3), np.empty(3)
    return {
        "position_kernel": lambda: k.position_kernel(pa, rho, 1, p),
        "terms": lambda: k.terms(pa, rho, rho_dot, 1, M, bias, p),
        "slider_forces_kernel": lambda: k.slider_forces_kernel(pa, rho, rho_dot, rho_ddot, 1, out),
        "forward_dynamics_kernel": lambda: k.forward_dynamics_kernel(pa, rho, rho_dot, forces, 1, out),
        "rhs_kernel": lambda: k.rhs_kernel(pa, x, forces, 1),
        "advance_fixed (RK4, 1 substep)": lambda: k.advance_fixed(pa, x, forces, 1, True, 1, 1e-3),
        "advance_fixed (RK4, 5 substeps)": lambda: k.advance_fixed(pa, x, forces, 1, True, 5, 1e-3),
        "slider_forces (P, raising)": lambda: k.slider_forces(P, rho, rho_dot, rho_ddot, 1),
        "slider_forces (packed, raising)": lambda: k.slider_forces(pa, rho, rho_dot, rho_ddot, 1),
        "forward_dynamics (P, raising)": lambda: k.forward_dynamics(P, rho, rho_dot, forces, 1),
        "dynamics_terms (P, raising)": lambda: k.dynamics_terms(P, rho, rho_dot, 1),
        "forward_branch (P, raising)": lambda: k.forward_branch(P, rho, 1),
    }


def bare_c(pa):
    """The C calls alone, pointers made beforehand: what a native FMU pays, plus cffi's call."""
    rho = np.array(m3t.PAPER_REFERENCE_RHO_MM) * m3t.MM + 0.004
    buf = {n: np.empty(s) for n, s in (("rho", 3), ("rd", 3), ("rdd", 3), ("f", 3), ("out", 3), ("x", 6))}
    buf["rho"][:], buf["rd"][:], buf["rdd"][:], buf["f"][:] = rho, [0.01, -0.02, 0.03], [0.1, 0.2, -0.3], [170, 40, -50]
    c = {n: ffi.from_buffer("double[]", a) for n, a in buf.items()}
    cpa = ffi.from_buffer("double[]", pa)
    return {
        "slider_forces_kernel": lambda: lib.mb_m3t_slider_forces(cpa, c["rho"], c["rd"], c["rdd"], 1, c["out"]),
        "forward_dynamics_kernel": lambda: lib.mb_m3t_forward_dynamics(cpa, c["rho"], c["rd"], c["f"], 1, c["out"]),
    }


def slave_steps(k):
    """name -> zero-argument call of one 1 ms step() of the slaves of fmu_src, using kernel k."""
    from fmu_src import mechanism3t_plant_fmu as mechanism3t_fmu
    from fmu_src import slider_controller_fmu
    mechanism3t_fmu.kernel = slider_controller_fmu.kernel = k
    plant, controller = mechanism3t_fmu.Mechanism3TPlant(instance_name="plant"), \
        slider_controller_fmu.SliderController(instance_name="controller")
    P = m3t.Mechanism3TParams.paper()
    plant.force[:] = kernel.slider_forces(P, plant.initial_position, np.zeros(3), np.zeros(3))   # static
    plant.initialize()
    controller.initialize()
    x0 = plant.x.copy()

    def plant_step():
        plant.x[:] = x0   # stays near the start: 1 ms of static forces from rest
        plant.step(0.0, 1e-3)
    return {"Mechanism3TPlant.step (1 ms, RK4)": plant_step,
            "SliderController.step (1 ms)": lambda: controller.step(0.5, 1e-3)}


def per_call(call, repeat, number):
    """Best per-call CPU time of the process: on a shared machine wall time also counts the
    time spent descheduled, which swings the figures by 2-3x from run to run."""
    return min(timeit.repeat(call, repeat=repeat, number=number, timer=time.process_time)) / number


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=7)
    parser.add_argument("--number", type=int, default=20000)
    args = parser.parse_args()
    P = m3t.Mechanism3TParams.paper()
    pa = kernel.pack(P)
    old = None
    try:
        import numba  # noqa: F401

        from tests.golden.make_numba_golden import load_numba_kernel
        with tempfile.TemporaryDirectory() as tmp:
            start = time.perf_counter()
            old = load_numba_kernel(tmp)
            calls(old, P, pa)["forward_dynamics_kernel"]()   # numba compiles at the first call
            compile_s = time.perf_counter() - start
            print(f"numba kernel of 73017ff: import + first call with a cold cache {compile_s:.1f} s "
                  f"(the C kernel is compiled at install)")
            old_calls = calls(old, P, pa)
            for call in old_calls.values():   # compile every signature before timing
                call()
            _run(calls(kernel, P, pa), old_calls, bare_c(pa), args)
            _run(slave_steps(kernel), slave_steps(old), {}, args)
    except ImportError:
        print("numba not importable: C kernel times only")
        _run(calls(kernel, P, pa), None, bare_c(pa), args)
        _run(slave_steps(kernel), None, {}, args)


def _run(new_calls, old_calls, bare, args):
    print(f"per call, best of {args.repeat} x {args.number} (µs of CPU time); ratio = numba / C")
    print(f"{'call':34s} {'C (cffi)':>9s} {'numba':>9s} {'ratio':>7s} {'bare C':>8s}")
    for name, call in new_calls.items():
        t_new = per_call(call, args.repeat, args.number)   # interleaved: C, numba, per call
        t_old = per_call(old_calls[name], args.repeat, args.number) if old_calls else float("nan")
        t_bare = per_call(bare[name], args.repeat, args.number) if name in bare else float("nan")
        print(f"{name:34s} {t_new * 1e6:9.2f} {t_old * 1e6:9.2f} {t_old / t_new:7.2f} {t_bare * 1e6:8.2f}")


if __name__ == "__main__":
    main()
