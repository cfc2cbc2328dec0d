"""The C kernel of the 3T mechanism (plant/c/mechanism3t.c through plant.mechanism3t.kernel)
against the numba kernel it replaced (git revision 73017ff), function by function, and its
C-only per-step calls against the calls they combine. The numba kernel's inputs and outputs
are stored in tests/golden/mechanism3t_kernel_c_numba.npz; regenerate with
tests/golden/make_numba_golden.py (needs numba, the `bench` extra, and the git history)."""
import pathlib

import numpy as np
import pytest

from plant.errors import ConvergenceError
from plant.mechanism3t import kernel
from plant.mechanism3t import model as m3t
from tests.rounding_helpers import Nudged

# benchmarks/bench_mechanism3t.py imports the numba kernel's loader from here

GOLDEN = pathlib.Path(__file__).resolve().parents[1] / "golden" / "mechanism3t_kernel_c_numba.npz"
P = m3t.Mechanism3TParams.paper()
RHO_REF = np.array(m3t.PAPER_REFERENCE_RHO_MM) * m3t.MM
REL = 1e-13


@pytest.fixture(scope="module")
def old():
    """The arrays of GOLDEN: inputs, and what the numba kernel returned for them."""
    with np.load(GOLDEN) as golden:
        return dict(golden)


def _same(what, call, args, status, *wanted):
    """call(*args) -> (status, outputs...) against the stored status and outputs, as rounding
    explains a difference between machines (tests/rounding_helpers.py): the outputs within
    REL of their largest entry or within the spread a few ulps of the inputs give here; a
    status that differs only where a nudge of the inputs changes it here too (a boundary).
    Returns the status found here, or None when the stored one was the other side of a boundary."""
    found = Nudged(call, *args)
    if found.status != status:
        assert found.borderline, (what, args, found.status, status)
        return None
    if status in (kernel.OK, "ok"):
        for k, want in enumerate(wanted):
            want = np.asarray(want, dtype=float)
            floor = REL * max(np.abs(want).max(initial=0.0), 1e-300)
            np.testing.assert_allclose(found.outputs[k], want, rtol=0, atol=found.tolerance(k, floor), err_msg=what)
    return found.status


def _outcome(name, pa, mode, message=False):
    """The raising wrapper ``name`` as (kind, outputs...): 'ok' and its values, or the error's
    class name (and its message, if asked)."""
    def call(*args):
        try:
            value = getattr(kernel, name)(pa, *args, mode)
        except (m3t.InvalidInputError, m3t.UnreachableError, m3t.SingularConfigurationError) as error:
            return (type(error).__name__, str(error)) if message else (type(error).__name__,)
        return ("ok", *(value if name == "dynamics_terms" else [np.atleast_1d(value)]))
    return call


def test_packed_parameters_are_the_numba_kernels():
    """The packed paper parameters: the paper's numbers, and the link inertias about their own
    centres, at_o - m r^2, with at_o the paper's inertia about O and r the centre from the
    reference pose's kinematics (arccos, sin, cos). That difference cancels up to ~800x
    (d3e3: 0.27 -> 3.3e-4 kg.m2), so a libm or SIMD build that rounds r differently moves the
    inertia by ulps of at_o, not of itself: each entry within 16 ulps of its largest term."""
    pa, stored = kernel.pack(P), np.load(GOLDEN)["pack"]
    scale = np.abs(stored)
    for k, name in enumerate(kernel.TURNING, start=len(pa) - len(kernel.TURNING)):
        scale[k] = m3t.PAPER_INERTIA_AT_O[name][m3t.SWING_AXIS[name]] * m3t.KG_MM2
    ulps = np.abs(pa - stored) / (np.finfo(float).eps * scale)
    assert ulps.max() <= 16, ulps


def test_c_kernel_equals_the_numba_kernel(old):
    """Every status-returning kernel and every raising wrapper: the same status (or error type
    and message) and the same numbers to 1e-13 relative or to what rounding explains (`_same`),
    on ~1000 configurations x 2 modes (near the paper's, on every inverse-position branch of
    random O', and over a box far wider than the workspace: unreachable and singular ones
    included). The kernels read the stored packed parameters, so that only the kernels differ."""
    pa = old["pack"]
    statuses, worst, borderline = set(), 0.0, 0
    row = 0   # the stored per-mode rows: state 0 mode 1, state 0 mode -1, state 1 mode 1, ...
    for rho, rho_dot, rho_ddot, forces in zip(old["rho"], old["rho_dot"], old["rho_ddot"], old["forces"]):
        for mode in (1, -1):
            def position(rho):
                p = np.empty(3)
                return kernel.position_kernel(pa, rho, mode, p), p

            def terms(rho, rho_dot):
                new = [np.empty((3, 3)), np.empty(3), np.empty(3)]
                return (kernel.terms(pa, rho, rho_dot, mode, *new), *new)

            def slider_forces(rho, rho_dot, rho_ddot):
                f = np.empty(3)
                return kernel.slider_forces_kernel(pa, rho, rho_dot, rho_ddot, mode, f), f

            def forward_dynamics(rho, rho_dot, forces):
                a = np.empty(3)
                return kernel.forward_dynamics_kernel(pa, rho, rho_dot, forces, mode, a), a

            def rhs(x, forces):
                return kernel.rhs_kernel(pa, x, forces, mode)

            _same("position", position, (rho,), old["position_status"][row], old["position_p"][row])
            status = _same("terms", terms, (rho, rho_dot), old["terms_status"][row],
                           *(old[f"terms_{k}"][row] for k in range(3)))
            statuses.add(status)
            borderline += status is None
            if status == kernel.OK:
                a, b = terms(rho, rho_dot)[1:], [old[f"terms_{k}"][row] for k in range(3)]
                worst = max([worst] + [np.abs(u - v).max() / np.abs(v).max() for u, v in zip(a, b)])
            _same("slider forces", slider_forces, (rho, rho_dot, rho_ddot), old["slider_forces_status"][row],
                  old["slider_forces_out"][row])
            _same("forward dynamics", forward_dynamics, (rho, rho_dot, forces), old["forward_dynamics_status"][row],
                  old["forward_dynamics_out"][row])
            _same("rhs", rhs, (np.r_[rho, rho_dot], forces), old["rhs_status"][row], old["rhs_xdot"][row])
            for name, args in (("dynamics_terms", (rho, rho_dot)), ("slider_forces", (rho, rho_dot, rho_ddot)),
                               ("forward_dynamics", (rho, rho_dot, forces)), ("forward_branch", (rho,))):
                kind, message = old[f"{name}_kind"][row], old[f"{name}_message"][row]
                stored = (old[f"{name}_{k}"][row] for k in range(3)) if name == "dynamics_terms" else \
                    [old[f"{name}_value"][row]]
                found = _same(name, _outcome(name, pa, mode), args, "ok" if kind == "ok" else kind, *stored)
                if found not in (None, "ok"):   # the same error, with the same message
                    assert _outcome(name, pa, mode, message=True)(*args) == (kind, message)
            row += 1
    assert row == len(old["position_status"])
    # every kind of outcome was met: OK, unreachable (eq. 10-11, arccos, limbs) and singular;
    # a status on a boundary (where another machine may round to the other side) is rare
    assert {kernel.OK, kernel.UNREACH_D3E3, kernel.UNREACH_ARCCOS, kernel.SING_SIN} <= statuses, statuses
    assert len(statuses - {None}) >= 6, statuses
    assert borderline <= 0.01 * row, borderline
    print(f"largest relative difference of M, bias, O' (C vs numba): {worst:.2e}")


def test_c_advance_equals_the_numba_advance(old):
    """advance_fixed, RK4 and Euler, from states near the paper's under forces large enough
    that some runs leave the workspace: same status, same state (also where it stopped)."""
    pa = kernel.pack(P)
    statuses = set()
    for x0, forces, substeps, dt, rk4, s_old, x_old in zip(*(old[f"advance_{name}"] for name in (
            "x0", "forces", "substeps", "dt", "rk4", "status", "x"))):
        s_new, x_new = kernel.advance_fixed(pa, x0, forces, 1, bool(rk4), int(substeps), float(dt))
        assert s_new == s_old and s_new in (kernel.OK, kernel.UNREACH_D3E3, kernel.UNREACH_ARCCOS,
                                            kernel.UNREACH_LIMB1, kernel.UNREACH_LIMB2, kernel.SING_W)
        statuses.add(s_new)
        np.testing.assert_allclose(x_new, x_old, rtol=0, atol=1e-12 * np.abs(x_old).max())
    assert kernel.OK in statuses and len(statuses) >= 2, statuses   # some runs did stop


def test_plant_step_is_advance_then_position():
    """The plant FMU's one call per step: advance_fixed, then O' of the new state; a state
    that stops being finite is DIVERGED, not a NaN O'."""
    pa = kernel.pack(P)
    x0, forces = np.r_[RHO_REF, 0.01, -0.02, 0.03], np.array([120.0, -40.0, 60.0])
    for rk4 in (True, False):
        status, x, p = kernel.plant_step(pa, x0, forces, 1, rk4, 3, 1e-3)
        status_a, x_a = kernel.advance_fixed(pa, x0, forces, 1, rk4, 3, 1e-3)
        assert status == status_a == kernel.OK
        np.testing.assert_array_equal(x, x_a)
        np.testing.assert_array_equal(p, m3t.forward_branch(P, x[:3]))
    # an Euler step of infinite length from a moving state leaves no finite state
    status, x, p = kernel.plant_step(pa, x0, forces, 1, False, 1, np.inf)
    assert status == kernel.DIVERGED and not np.isfinite(x).all()
    with pytest.raises(ConvergenceError, match="no longer finite"):
        kernel.raise_status(status, 1)


def test_reference_forces_are_paper_motion_then_slider_forces():
    """The slider controller's one call per step against paper_motion + numpy slider_forces."""
    pa = kernel.pack(P)
    for t in np.linspace(0.0, 20.0, 41):
        status, ref, rate, acc, forces = kernel.reference_forces(pa, t, RHO_REF, 0.01, 0.5, 1)
        assert status == kernel.OK
        want = m3t.paper_motion(t, RHO_REF, 0.01, 0.5)
        for got, w in zip((ref, rate, acc), want):
            np.testing.assert_allclose(got, w, rtol=1e-15, atol=1e-18)
        f = m3t.slider_forces(P, *want)
        np.testing.assert_allclose(forces, f, rtol=0, atol=1e-12 * np.abs(f).max())
    status, *_ = kernel.reference_forces(pa, 0.0, [0.0, 0.0, 0.4], 0.01, 0.5, 1)
    assert status == kernel.UNREACH_D3E3


def test_bad_mode_and_bad_arguments_are_refused():
    """mode other than +-1 is a status of its own in C (the numba kernel computed with it),
    raised as the reference's mode error; wrong shapes and read-only outputs are named."""
    pa, p = kernel.pack(P), np.empty(3)
    for mode in (0, 2, -3):
        assert kernel.position_kernel(pa, RHO_REF, mode, p) == kernel.BAD_MODE
        assert kernel.rhs_kernel(pa, np.r_[RHO_REF, 0, 0, 0], np.zeros(3), mode)[0] == kernel.BAD_MODE
        with pytest.raises(m3t.InvalidInputError, match="mode must be"):
            kernel.raise_status(kernel.BAD_MODE, mode)
    with pytest.raises(m3t.InvalidInputError, match=r"rho_dot has shape \(2,\)"):
        kernel.slider_forces(P, RHO_REF, [0.0, 0.0], np.zeros(3))
    with pytest.raises(m3t.InvalidInputError, match=r"packed parameters has shape \(29,\)"):
        kernel.forward_branch(kernel.pack(P)[:-1], RHO_REF)
    with pytest.raises(m3t.InvalidInputError, match="writable"):
        kernel.position_kernel(pa, RHO_REF, 1, pa[:3])
    # non-contiguous and non-float64 inputs are converted, not misread
    strided = np.repeat(RHO_REF, 2)[::2]
    np.testing.assert_array_equal(kernel.forward_branch(P, strided), kernel.forward_branch(P, RHO_REF))
    np.testing.assert_array_equal(kernel.forward_branch(P, RHO_REF.astype(np.float32)),
                                  kernel.forward_branch(P, RHO_REF.astype(np.float32).astype(float)))
