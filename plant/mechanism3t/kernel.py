"""Single-state kernel of the 3T mechanism (plant.mechanism3t.model): O', the generalised mass
matrix M, the bias forces and the forward dynamics for ONE state, an RHS and fixed-step
RK4 / Euler for the plant FMU: the C kernel plant/c/mechanism3t.c called through cffi
(plant._kernel, built at install), which the native FMUs compile too.

Why compiled: plant.mechanism3t.model evaluates the bodies with numpy on tiny arrays, ~420 µs of
fixed per-call costs for a single state; the plant FMU calls forward dynamics four times per
RK4 substep and the slider controller the inverse dynamics once per step. The validated,
batched numpy API in plant.mechanism3t.model stays the reference (tests hold the two equal to
~1e-12 relative); the C code repeats its formulas term by term (its header documents the
arguments and the packed parameters of pack()).

The kernels never raise: they return a status code (OK or one of the codes below), and
the Python wrappers raise the reference's errors with the reference's messages
(InvalidInputError for NaN/inf, UnreachableError, SingularConfigurationError), never NaN.
Per-call cost is mostly argument passing: inputs that are already contiguous float64
arrays of the right shape are handed to C without a copy, and the C pointer of every
packed parameter array is made once and cached.
"""
import functools

import numpy as np

from plant._kernel import ffi, lib
from plant.errors import ConvergenceError, InvalidInputError, SingularConfigurationError
from plant.mechanism3t.model import Mechanism3TParams, UnreachableError, _check_mode

OK = lib.MB_M3T_OK
BAD_RHO, BAD_RHO_DOT, BAD_FORCE, BAD_RHO_DDOT, BAD_MODE = (
    lib.MB_M3T_BAD_RHO, lib.MB_M3T_BAD_RHO_DOT, lib.MB_M3T_BAD_FORCE, lib.MB_M3T_BAD_RHO_DDOT, lib.MB_M3T_BAD_MODE)
UNREACH_D3E3, UNREACH_ARCCOS, UNREACH_LIMB1, UNREACH_LIMB2 = (
    lib.MB_M3T_UNREACH_D3E3, lib.MB_M3T_UNREACH_ARCCOS, lib.MB_M3T_UNREACH_LIMB1, lib.MB_M3T_UNREACH_LIMB2)
SING_SIN, SING_W, SING_LIMB1, SING_LIMB2, SING_MASS = (
    lib.MB_M3T_SING_SIN, lib.MB_M3T_SING_W, lib.MB_M3T_SING_LIMB1, lib.MB_M3T_SING_LIMB2, lib.MB_M3T_SING_MASS)
DIVERGED = lib.MB_M3T_DIVERGED

# Body order of the packed masses (that of plant.mechanism3t.model._bodies) and of the turning ones.
BODIES = ("slider_2", "slider_1", "slider_3", "b1c1", "c1d1", "b2c2", "c2d2", "b3c3", "c3d3", "d3e3", "platform")
TURNING = ("b1c1", "c1d1", "b2c2", "c2d2", "b3c3", "d3e3")
assert (len(BODIES), len(TURNING)) == (lib.MB_M3T_NBODY, lib.MB_M3T_NTURN)


@functools.lru_cache(maxsize=16)
def pack(P):
    """Mechanism3TParams as the float64 array the kernels read (layout: plant/c/mechanism3t.h)."""
    head = [P.a, P.b, P.d, P.e, P.l1, P.l2, P.l3, P.l4, P.l5, P.l6, P.g, float(P.knee_1), float(P.knee_2)]
    masses = [P.m_slider] * 3 + [getattr(P, "m_" + n) for n in BODIES[3:-1]] + [P.m_platform + P.m_payload]
    inertias = [getattr(P, "i_" + n) for n in TURNING]
    packed = np.array(head + masses + inertias, dtype=float)
    packed.flags.writeable = False
    return packed


# ---------------------------------------------------------------- argument passing

_F8 = np.dtype(float)
_DOUBLES = ffi.typeof("double[]")
_new_buffer = ffi.from_buffer   # positional arguments only: cffi's keyword path costs ~0.3 µs
_empty = np.empty
_ndarray = np.ndarray
_POINTERS: dict = {}   # id(P or packed array) -> (it, its C pointer, the array pointed to): kept alive, ids stay unique


def _params(P):
    """The C pointer of the packed parameters of Mechanism3TParams P or of a packed array,
    made once per object (P is frozen; pack() arrays are read-only)."""
    hit = _POINTERS.get(id(P))
    if hit is not None:
        return hit[1]
    arr = _array("packed parameters", pack(P) if type(P) is Mechanism3TParams else P, (lib.MB_M3T_NPARAM,))
    ptr = _new_buffer(_DOUBLES, arr)
    if arr is P or type(P) is Mechanism3TParams:   # not a converted temporary: cache
        if len(_POINTERS) >= 64:
            _POINTERS.clear()
        _POINTERS[id(P)] = (P, ptr, arr)
    return ptr


def _array(name, value, shape):
    """value as a C-contiguous float64 array of ``shape`` (itself when it already is one)."""
    if not (type(value) is _ndarray and value.dtype is _F8 and value.flags.c_contiguous):
        value = np.ascontiguousarray(value, dtype=float)
    if value.shape != shape:
        raise InvalidInputError(f"{name} has shape {value.shape}, expected {shape}")
    return value


def _in(name, value, n=3):
    """C pointer to a read-only input of n doubles (no copy of a contiguous float64 array)."""
    if type(value) is _ndarray and value.dtype is _F8 and value.shape == (n,):
        try:
            return _new_buffer(_DOUBLES, value)
        except ValueError:   # not contiguous: converted below
            pass
    return _new_buffer(_DOUBLES, _array(name, value, (n,)))


def _out(name, value, shape):
    """C pointer into a caller's output array, which must be writable, contiguous float64."""
    if type(value) is _ndarray and value.dtype is _F8 and value.shape == shape and value.flags.writeable:
        try:
            return _new_buffer(_DOUBLES, value)
        except ValueError:   # not contiguous
            pass
    raise InvalidInputError(f"{name} must be a writable C-contiguous float64 array of shape {shape}")


def _copy(name, value, n):
    """A new contiguous float64 array holding value (n,): the state a kernel advances in place."""
    arr = np.array(value, dtype=float, order="C")
    if arr.shape != (n,):
        raise InvalidInputError(f"{name} has shape {arr.shape}, expected {(n,)}")
    return arr, _new_buffer(_DOUBLES, arr)


def _fresh(n):
    arr = _empty(n)
    return arr, _new_buffer(_DOUBLES, arr)


def _mode(mode):
    _check_mode(mode)
    return int(mode)


# ---------------------------------------------------------------- kernels (status codes, no raising)

def terms(pa, rho, rho_dot, mode, M, bias, p):
    """M (3, 3) and bias (3,) of dynamics_terms and O' p (3,) for one state, written in place.
    Returns the status (OK, BAD_RHO, BAD_RHO_DOT, BAD_MODE, UNREACH_*, SING_*)."""
    return lib.mb_m3t_terms(_params(pa), _in("rho", rho), _in("rho_dot", rho_dot), mode,
                            _out("M", M, (3, 3)), _out("bias", bias, (3,)), _out("p", p, (3,)))


def slider_forces_kernel(pa, rho, rho_dot, rho_ddot, mode, out):
    """slider_forces = M rho_ddot + bias for one state, written into out (3,); returns the status."""
    return lib.mb_m3t_slider_forces(_params(pa), _in("rho", rho), _in("rho_dot", rho_dot),
                                    _in("rho_ddot", rho_ddot), mode, _out("out", out, (3,)))


def forward_dynamics_kernel(pa, rho, rho_dot, forces, mode, rho_ddot):
    """rho_ddot (3,) = M^-1 (forces - bias) written in place; returns the status."""
    return lib.mb_m3t_forward_dynamics(_params(pa), _in("rho", rho), _in("rho_dot", rho_dot),
                                       _in("slider forces", forces), mode, _out("rho_ddot", rho_ddot, (3,)))


def rhs_kernel(pa, x, forces, mode):
    """(status, dx/dt) of the plant state x = (rho, rho_dot) under held slider forces."""
    xdot, ptr = _fresh(6)
    return lib.mb_m3t_rhs(_params(pa), _in("x", x, 6), _in("slider forces", forces), mode, ptr), xdot


def advance_fixed(pa, x, forces, mode, rk4, substeps, dt):
    """x (6,) = (rho, rho_dot) advanced by ``substeps`` equal steps dt of classic RK4 (or
    explicit Euler) under held forces: plant.integrators.rk4 / euler with the same
    arithmetic, compiled. Works on a copy; returns (status, new x), the new x being the
    state at the start of the failing substep on a non-OK status."""
    x, ptr = _copy("x", x, 6)
    return lib.mb_m3t_advance_fixed(_params(pa), ptr, _in("slider forces", forces), mode, rk4, substeps, dt), x


def plant_step(pa, x, forces, mode, rk4, substeps, dt):
    """advance_fixed, then DIVERGED if the new state is not finite, then O' of the new slider
    positions: a plant FMU step in one C call. Returns (status, new x (6,), O' (3,))."""
    (x, px), (p, pp) = _copy("x", x, 6), _fresh(3)
    return lib.mb_m3t_plant_step(_params(pa), px, _in("slider forces", forces), mode, rk4, substeps, dt, pp), x, p


def position_kernel(pa, rho, mode, p):
    """O' (3,) of assembly mode `mode` written in place; returns the status."""
    return lib.mb_m3t_position(_params(pa), _in("rho", rho), mode, _out("p", p, (3,)))


def reference_forces(pa, t, centre, amplitude, omega, mode):
    """The slider controller's feedforward at t in one C call: the paper_motion reference
    and its slider forces. Returns (status, ref, ref_rate, ref_acc, forces), each (3,)."""
    (ref, r), (rate, rr), (acc, ra), (forces, rf) = _fresh(3), _fresh(3), _fresh(3), _fresh(3)
    status = lib.mb_m3t_reference_forces(_params(pa), t, _in("centre", centre), amplitude, omega, mode,
                                         r, rr, ra, rf)
    return status, ref, rate, acc, forces


# ---------------------------------------------------------------- Python wrappers

_INVALID = {BAD_RHO: "rho contains NaN or inf", BAD_RHO_DOT: "rho_dot contains NaN or inf",
            BAD_FORCE: "slider forces contains NaN or inf", BAD_RHO_DDOT: "rho_ddot contains NaN or inf"}
_SINGULAR = {
    SING_SIN: "output singularity (paper 3.3, f33 = 0): sin theta = 0, D3C3 perpendicular to B3C3",
    SING_W: "output singularity (paper 3.3, f33 = 0): x - e + a + l4 cos theta = 0, E3 and C3 share x",
    SING_LIMB1: "limb I fully stretched or folded (|BD| = l2 +- l3)",
    SING_LIMB2: "limb II fully stretched or folded (|BD| = l2 +- l3)",
    SING_MASS: "mass matrix singular: no slider accelerations solve M rho_ddot = F - bias",
}
_UNREACHABLE = {
    UNREACH_D3E3: "eq. 10-11: l6^2 - (y_A1 + d - y_A3)^2 < 0 (D3E3 too short for the y offset)",
    UNREACH_LIMB1: "limb I cannot close: eq. 8 square root negative (|B1D1| outside [|l2 - l3|, l2 + l3])",
    UNREACH_LIMB2: "limb II cannot close: eq. 8 square root negative (|B2D2| outside [|l2 - l3|, l2 + l3])",
}


def raise_status(status, mode):
    """Raise the error plant.mechanism3t.model raises for a kernel status (nothing for OK)."""
    if status == OK:
        return
    if status in _INVALID:
        raise InvalidInputError(_INVALID[status])
    if status in _SINGULAR:
        raise SingularConfigurationError(_SINGULAR[status])
    if status == BAD_MODE:
        _check_mode(mode)
    if status == DIVERGED:
        raise ConvergenceError("fixed-step integration diverged: the state is no longer finite")
    if status == UNREACH_ARCCOS:
        sign = "+" if mode > 0 else "-"
        raise UnreachableError(f"eq. 11: arccos argument (N3 {sign} sqrt(l6^2 - N4^2))/l4 outside [-1, 1]")
    raise UnreachableError(_UNREACHABLE[status])


def dynamics_terms(P, rho, rho_dot, mode=1):
    """(M (3, 3), bias (3,), O' (3,)) of one state: plant.mechanism3t.model.dynamics_terms compiled."""
    mode = _mode(mode)
    (M, pm), (bias, pb), (p, pp) = _fresh((3, 3)), _fresh(3), _fresh(3)
    raise_status(lib.mb_m3t_terms(_params(P), _in("rho", rho), _in("rho_dot", rho_dot), mode, pm, pb, pp), mode)
    return M, bias, p


def slider_forces(P, rho, rho_dot, rho_ddot, mode=1):
    """plant.mechanism3t.model.slider_forces for one state, as M rho_ddot + bias."""
    mode = _mode(mode)
    out, ptr = _fresh(3)
    raise_status(lib.mb_m3t_slider_forces(_params(P), _in("rho", rho), _in("rho_dot", rho_dot),
                                          _in("rho_ddot", rho_ddot), mode, ptr), mode)
    return out


def forward_dynamics(P, rho, rho_dot, forces, mode=1):
    """plant.mechanism3t.model.forward_dynamics for one state: rho_ddot = M^-1 (forces - bias)."""
    mode = _mode(mode)
    out, ptr = _fresh(3)
    raise_status(lib.mb_m3t_forward_dynamics(_params(P), _in("rho", rho), _in("rho_dot", rho_dot),
                                             _in("slider forces", forces), mode, ptr), mode)
    return out


def forward_branch(P, rho, mode=1):
    """plant.mechanism3t.model.forward_branch for one rho (3,)."""
    mode = _mode(mode)
    p, ptr = _fresh(3)
    raise_status(lib.mb_m3t_position(_params(P), _in("rho", rho), mode, ptr), mode)
    return p
