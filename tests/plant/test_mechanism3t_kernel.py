"""The C kernel of the 3T mechanism (plant/c/mechanism3t.c through plant.mechanism3t_kernel)
against the numba kernel it replaced (git revision 73017ff), function by function, and its
C-only per-step calls against the calls they combine."""
import importlib
import pathlib
import subprocess
import sys

import numpy as np
import pytest

from plant.errors import ConvergenceError
from plant.mechanism3t import kernel
from plant.mechanism3t import model as m3t

ROOT = pathlib.Path(__file__).resolve().parents[2]
NUMBA_REVISION = "73017ff"
P = m3t.Mechanism1Params.paper()
RHO_REF = np.array(m3t.PAPER_REFERENCE_RHO_MM) * m3t.MM
REL = 1e-13


def load_numba_kernel(directory, revision=NUMBA_REVISION):
    """plant/mechanism3t/kernel.py and plant/linalg.py of ``revision`` imported as a package in
    ``directory`` (their other imports point at today's plant). Needs git and numba."""
    name = f"m3t_numba_{revision}"
    package = pathlib.Path(directory) / name
    package.mkdir(exist_ok=True)
    (package / "__init__.py").write_text("")
    for file in ("mechanism3t_kernel.py", "linalg.py"):
        source = subprocess.run(["git", "-C", str(ROOT), "show", f"{revision}:plant/{file}"],
                                check=True, capture_output=True, text=True).stdout
        source = source.replace("from .errors import", "from plant.errors import")
        source = source.replace("from .mechanism3t import", "from plant.mechanism3t.model import")
        (package / file).write_text(source)
    sys.path.insert(0, str(directory))
    try:
        return importlib.import_module(f"{name}.mechanism3t_kernel")
    finally:
        sys.path.remove(str(directory))


@pytest.fixture(scope="module")
def old(tmp_path_factory):
    pytest.importorskip("numba")
    try:
        return load_numba_kernel(tmp_path_factory.mktemp("numba_kernel"))
    except (OSError, subprocess.CalledProcessError) as error:
        pytest.skip(f"git revision {NUMBA_REVISION} not available: {error}")


def _states(rng):
    """~1000 configurations: near the paper's, on every inverse-position branch of random O',
    and over a box far wider than the workspace (unreachable and singular ones included)."""
    inverse = []
    while len(inverse) < 400:
        p = rng.uniform([-0.1, -0.32, P.l1 + P.l5], [0.38, 0.45, P.l1 + P.l5 + P.l4])
        try:
            inverse.extend(m3t.inverse_position(P, p))
        except m3t.UnreachableError:
            pass
    near_sin = [[x, 0.0, P.d] for x in np.linspace(-3e-16, 3e-16, 7)]   # sin theta -> 0
    return np.r_[RHO_REF + rng.uniform(-0.03, 0.03, (300, 3)), np.array(inverse[:400]),
                 rng.uniform([-0.3, -0.5, -0.5], [0.4, 0.5, 0.5], (300, 3)), near_sin]


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
    and message) and the same numbers to 1e-13 relative, on ~1000 configurations x 2 modes."""
    rng = np.random.default_rng(9)
    pa = kernel.pack(P)
    np.testing.assert_array_equal(pa, old.pack(P))
    statuses, worst = set(), 0.0
    for rho in _states(rng):
        rho_dot, rho_ddot, forces = rng.normal(0, 0.3, 3), rng.normal(0, 3.0, 3), rng.normal(0, 100.0, 3)
        for mode in (1, -1):
            p_new, p_old = np.empty(3), np.empty(3)
            status = kernel.position_kernel(pa, rho, mode, p_new)
            assert status == old.position_kernel(pa, rho, mode, p_old)
            _close(p_new, p_old)
            new, was = [np.empty((3, 3)), np.empty(3), np.empty(3)], [np.empty((3, 3)), np.empty(3), np.empty(3)]
            status = kernel.terms(pa, rho, rho_dot, mode, *new)
            assert status == old.terms(pa, rho, rho_dot, mode, *was), (rho, mode)
            statuses.add(status)
            if status == kernel.OK:
                for a, b in zip(new, was):
                    _close(a, b)
                    worst = max(worst, np.abs(a - b).max() / np.abs(b).max())
            f_new, f_old = np.empty(3), np.empty(3)
            status = kernel.slider_forces_kernel(pa, rho, rho_dot, rho_ddot, mode, f_new)
            assert status == old.slider_forces_kernel(pa, rho, rho_dot, rho_ddot, mode, f_old)
            if status == kernel.OK:
                _close(f_new, f_old)
            a_new, a_old = np.empty(3), np.empty(3)
            status = kernel.forward_dynamics_kernel(pa, rho, rho_dot, forces, mode, a_new)
            assert status == old.forward_dynamics_kernel(pa, rho, rho_dot, forces, mode, a_old)
            if status == kernel.OK:
                _close(a_new, a_old)
            x = np.r_[rho, rho_dot]
            (s_new, xd_new), (s_old, xd_old) = kernel.rhs_kernel(pa, x, forces, mode), old.rhs_kernel(pa, x, forces, mode)
            assert s_new == s_old
            if s_new == kernel.OK:
                _close(xd_new, xd_old)
            for name, args in (("dynamics_terms", (rho, rho_dot)), ("slider_forces", (rho, rho_dot, rho_ddot)),
                               ("forward_dynamics", (rho, rho_dot, forces)), ("forward_branch", (rho,))):
                a = _outcome(lambda: getattr(kernel, name)(P, *args, mode))
                b = _outcome(lambda: getattr(old, name)(P, *args, mode))
                assert a[0] == b[0], (name, rho, mode, a, b)
                if a[0] == "ok":
                    for u, v in zip(np.atleast_1d(a[1]) if name != "dynamics_terms" else a[1],
                                    np.atleast_1d(b[1]) if name != "dynamics_terms" else b[1]):
                        _close(u, v)
                else:
                    assert a[1] == b[1]
    # every kind of outcome was met: OK, unreachable (eq. 10-11, arccos, limbs) and singular
    assert {kernel.OK, kernel.UNREACH_D3E3, kernel.UNREACH_ARCCOS, kernel.SING_SIN} <= statuses, statuses
    assert len(statuses) >= 6, statuses
    print(f"largest relative difference of M, bias, O' (C vs numba): {worst:.2e}")


def test_c_advance_equals_the_numba_advance(old):
    """advance_fixed, RK4 and Euler, from states near the paper's under forces large enough
    that some runs leave the workspace: same status, same state (also where it stopped)."""
    rng = np.random.default_rng(4)
    pa = kernel.pack(P)
    statuses = set()
    for _ in range(150):
        x0 = np.r_[RHO_REF + rng.uniform(-0.05, 0.05, 3), rng.normal(0, 0.2, 3)]
        forces = rng.normal(0, 400.0, 3)
        substeps, dt, rk4 = int(rng.integers(1, 60)), float(rng.uniform(1e-4, 5e-3)), bool(rng.integers(2))
        s_new, x_new = kernel.advance_fixed(pa, x0, forces, 1, rk4, substeps, dt)
        s_old, x_old = old.advance_fixed(pa, x0, forces, 1, rk4, substeps, dt)
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
