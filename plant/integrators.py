"""Integrators for plant models over one communication step.

One contract, as scipy.integrate's: ``advance(f, t, x, h, max_step) -> x_new`` with
``f(t, x) -> dx/dt``. Fixed-step methods split h into ceil(h / max_step) equal substeps.
Methods: "euler" (explicit, order 1: shown to fail beyond its stability limit), "rk4"
(explicit, order 4: the default) and "radau" (implicit Radau IIA of scipy, order 5,
adaptive, for stiff settings and reference solutions). ``counters`` counts f calls.
"""
import math

import numpy as np

from plant.errors import ConvergenceError, WorkBoundError

INTEGRATORS = ("rk4", "euler", "radau")


# The most substeps one step may take: a bound on the work of one call, the same as the
# native FMUs' MB_MAX_SUBSTEPS (fmu_src/native/model.h); ~5 s of RK4 at the most here.
MAX_SUBSTEPS = 1_000_000


def substep_count(h, max_step):
    """ceil(h / max_step) (at least 1); WorkBoundError past MAX_SUBSTEPS (worded as the
    native FMUs word it)."""
    ratio = h / max_step
    n = math.ceil(ratio - 1e-9) if math.isfinite(ratio) else math.inf
    if not n <= MAX_SUBSTEPS:
        raise WorkBoundError(f"a step of {h!r} s needs {float(n):.3g} substeps of at most {max_step!r} s, more "
                             f"than the {MAX_SUBSTEPS} a doStep may take: take shorter communication steps")
    return max(1, n)


def _substeps(h, max_step):
    n = substep_count(h, max_step)
    return n, h / n


def euler(f, t, x, h, max_step):
    n, dt = _substeps(h, max_step)
    for k in range(n):
        x = x + dt * f(t + k * dt, x)
    return x


def rk4(f, t, x, h, max_step):
    n, dt = _substeps(h, max_step)
    for k in range(n):
        tk = t + k * dt
        k1 = f(tk, x)
        k2 = f(tk + 0.5 * dt, x + 0.5 * dt * k1)
        k3 = f(tk + 0.5 * dt, x + 0.5 * dt * k2)
        k4 = f(tk + dt, x + dt * k3)
        x = x + dt / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
    return x


def radau(f, t, x, h, max_step, rtol=1e-9, atol=1e-12):
    from scipy.integrate import solve_ivp  # here: scipy costs a run that never asks for radau ~0.3 s
    sol = solve_ivp(f, (t, t + h), x, method="Radau", rtol=rtol, atol=atol, max_step=max_step)
    if not sol.success:
        raise ConvergenceError(f"Radau failed over [{t}, {t + h}]: {sol.message}")
    return sol.y[:, -1]


METHODS = {"rk4": rk4, "euler": euler, "radau": radau}


def advance(method, f, t, x, h, max_step):
    """x at t + h. Raises ConvergenceError when the state leaves the finite numbers
    (an explicit method beyond its stability limit), never returning NaN."""
    if method not in METHODS:
        raise ValueError(f"unknown integrator {method!r}; choose one of {INTEGRATORS}")
    x_new = METHODS[method](f, t, x, h, max_step)
    if not np.all(np.isfinite(x_new)):
        raise ConvergenceError(f"integrator {method} diverged over [{t:.6g}, {t + h:.6g}] s "
                               f"(substep {min(h, max_step):.3g} s): state is no longer finite")
    return x_new
