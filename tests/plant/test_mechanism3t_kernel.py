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


def _close(got, want):
    want = np.asarray(want)
    np.testing.assert_allclose(got, want, rtol=0, atol=REL * max(np.abs(want).max(), 1e-300))


def _outcome(call):
    try:
        return "ok", call()
    except (m3t.InvalidInputError, m3t.UnreachableError, m3t.SingularConfigurationError) as error:
        return type(error), str(error)


def test_c_kernel_equals_the_numba_kernel(old):
    """Every status-returning kernel and every raising wrapper: the same status (or error type
    and message) and the same numbers to 1e-13 relative, on ~1000 configurations x 2 modes
    (near the paper's, on every inverse-position branch of random O', and over a box far
    wider than the workspace: unreachable and singular ones included)."""
    pa = kernel.pack(P)
    np.testing.assert_array_equal(pa, old["pack"])
    statuses, worst = set(), 0.0
    row = 0   # the stored per-mode rows: state 0 mode 1, state 0 mode -1, state 1 mode 1, ...
    for rho, rho_dot, rho_ddot, forces in zip(old["rho"], old["rho_dot"], old["rho_ddot"], old["forces"]):
        for mode in (1, -1):
            p_new = np.empty(3)
            status = kernel.position_kernel(pa, rho, mode, p_new)
            assert status == old["position_status"][row]
            _close(p_new, old["position_p"][row])
            new = [np.empty((3, 3)), np.empty(3), np.empty(3)]
            status = kernel.terms(pa, rho, rho_dot, mode, *new)
            assert status == old["terms_status"][row], (rho, mode)
            statuses.add(status)
            if status == kernel.OK:
                for k, a in enumerate(new):
                    b = old[f"terms_{k}"][row]
                    _close(a, b)
                    worst = max(worst, np.abs(a - b).max() / np.abs(b).max())
            f_new = np.empty(3)
            status = kernel.slider_forces_kernel(pa, rho, rho_dot, rho_ddot, mode, f_new)
            assert status == old["slider_forces_status"][row]
            if status == kernel.OK:
                _close(f_new, old["slider_forces_out"][row])
            a_new = np.empty(3)
            status = kernel.forward_dynamics_kernel(pa, rho, rho_dot, forces, mode, a_new)
            assert status == old["forward_dynamics_status"][row]
            if status == kernel.OK:
                _close(a_new, old["forward_dynamics_out"][row])
            s_new, xd_new = kernel.rhs_kernel(pa, np.r_[rho, rho_dot], forces, mode)
            assert s_new == old["rhs_status"][row]
            if s_new == kernel.OK:
                _close(xd_new, old["rhs_xdot"][row])
            for name, args in (("dynamics_terms", (rho, rho_dot)), ("slider_forces", (rho, rho_dot, rho_ddot)),
                               ("forward_dynamics", (rho, rho_dot, forces)), ("forward_branch", (rho,))):
                a = _outcome(lambda: getattr(kernel, name)(P, *args, mode))
                kind, message = old[f"{name}_kind"][row], old[f"{name}_message"][row]
                assert (a[0] if a[0] == "ok" else a[0].__name__) == kind, (name, rho, mode, a, kind, message)
                if kind == "ok":   # each array of dynamics_terms, each number of the others
                    if name == "dynamics_terms":
                        pairs = zip(a[1], (old[f"{name}_{k}"][row] for k in range(3)))
                    else:
                        pairs = zip(np.atleast_1d(a[1]), old[f"{name}_value"][row])
                    for u, v in pairs:
                        _close(u, v)
                else:
                    assert a[1] == message
            row += 1
    assert row == len(old["position_status"])
    # every kind of outcome was met: OK, unreachable (eq. 10-11, arccos, limbs) and singular
    assert {kernel.OK, kernel.UNREACH_D3E3, kernel.UNREACH_ARCCOS, kernel.SING_SIN} <= statuses, statuses
    assert len(statuses) >= 6, statuses
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
