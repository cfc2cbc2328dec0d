"""Kane kernel of the hexapod: M, h, J per state, and the ID / FD solves, in C.

The physics is plant/c/hexapod.c (API and units in plant/c/hexapod.h), compiled at
install by cffi into plant._kernel and into the native FMUs from the same source; this
module only hands it numpy arrays. Why C: numpy's fixed cost per call (~1 µs) times the
~200 small operations of one state made a single inverse-dynamics call cost ~350 µs, and
the FMU calls forward dynamics four times per RK4 substep; a C loop does a state in
~1-2 µs. Built ahead of time, so importing costs no compile wait.

Equations (derivation in plant.hexapod.model's docstring): generalised speeds u = (v, w) of {P}
relative to {B}, in {B};  M du/dt + h = J^T F.

Two levels: the functions below validate their arrays on every call (float64,
C-contiguous, shapes), for batched and occasional use; HexapodKernel validates
long-lived arrays once and keeps their C pointers, for the per-step paths (the FMU's
advance, a controller's inverse dynamics), where a call costs a few µs of Python.
The public, validated, batched API is plant.hexapod.model; this module is its engine.
"""
import numpy as np

from plant._kernel import ffi, lib
from plant.errors import InvalidInputError, SingularConfigurationError

ID, FD, TERMS = lib.MB_HEXAPOD_ID, lib.MB_HEXAPOD_FD, lib.MB_HEXAPOD_TERMS  # what the kernel solves for
BASE_NONE, BASE_GRAVITY, BASE_FULL = (lib.MB_HEXAPOD_BASE_NONE, lib.MB_HEXAPOD_BASE_GRAVITY,
                                      lib.MB_HEXAPOD_BASE_FULL)  # how much base motion it keeps
OK, BAD_INPUT, DIVERGED, STROKE, WORK = (lib.MB_HEXAPOD_OK, lib.MB_HEXAPOD_BAD_INPUT, lib.MB_HEXAPOD_DIVERGED,
                                         lib.MB_HEXAPOD_STROKE, lib.MB_HEXAPOD_WORK)  # advance_* status codes
NDATA = lib.MB_HEXAPOD_NDATA   # length of StewartParams.kernel_data
ACTUATOR_NDATA = lib.MB_ACTUATOR_NDATA   # [bandwidth, reflected_mass, coulomb, viscous, friction_velocity, force_limit]
_F64 = np.dtype(np.float64)   # numpy's float64 dtype is one object: compared by identity
_DOUBLES = ffi.typeof("double[]")
_from_buffer = ffi.from_buffer   # positional arguments, type object: the cheapest call
_empty = np.empty
_ndarray = np.ndarray
_ONE = (6,)
_NOTHING = object()   # what no caller passes: the held slot of an input never seen or converted


def pointer(array, shape, name):
    """A C pointer into ``array`` after checking it is float64, C-contiguous and of
    ``shape``: C would read any other layout as garbage or run past the end. For
    arrays C writes (and long-lived ones whose pointer is kept)."""
    if type(array) is np.ndarray and array.dtype is _F64 and array.shape == shape:
        try:
            return ffi.from_buffer("double[]", array)
        except ValueError:   # cffi refuses a strided view
            pass
    got = (f"{array.dtype} {array.shape}" + ("" if array.flags.c_contiguous else " (strided)")
           if isinstance(array, np.ndarray) else type(array).__name__)
    raise InvalidInputError(f"{name} must be a C-contiguous float64 array of shape {shape}, got {got}")


def reading(array, shape, name):
    """A C pointer to ``array`` as float64, C-contiguous and of ``shape``, copying only
    when it is not that already: for arguments C only reads."""
    if type(array) is np.ndarray and array.dtype is _F64 and array.shape == shape:
        try:
            return ffi.from_buffer("double[]", array)
        except ValueError:   # a strided view: copied below
            pass
    array = np.ascontiguousarray(array, dtype=np.float64)
    if array.shape != shape:
        raise InvalidInputError(f"{name} must have shape {shape}, got {array.shape}")
    return ffi.from_buffer("double[]", array)


def readings(arrays, shape, names):
    """reading() of several arrays of one shape, in one pass when all are float64 of
    that shape already (the per-step case: a few hundred ns saved per call)."""
    for a in arrays:
        if type(a) is not np.ndarray or a.dtype is not _F64 or a.shape != shape:
            break
    else:
        try:
            return [_from_buffer(_DOUBLES, a) for a in arrays]
        except ValueError:   # a strided view among them
            pass
    return [reading(a, shape, name) for a, name in zip(arrays, names)]


def _bandwidth(actuator):
    """The bandwidth [Hz] in an actuator array or pointer (decides the state size)."""
    return actuator[lib.MB_ACT_BANDWIDTH]


STATE_NAMES = ("pose", "rate", "arg", "base_pose", "base_rate", "base_acc")


def kane(base_joints, platform_joints, data, pose, rate, arg, base_pose, base_rate, base_acc,
         base_mode, legs, twist_speeds, solve, M, h, J, ldot, length, out, det, reflected_mass=0.0, wrench=None):
    """Fill M, h, J, leg rates for every state n and solve for ``out``.

    data = [m_p, I_p(3), m_f, l_f, m_m, l_m, I_axial, I_transverse, g].
    rate: RPY-angle rates, or the twist (v, w) when twist_speeds.
    arg: pose_acc (or twist acceleration) for ID, leg forces for FD.
    out: forces (ID) or pose_acc (twist acceleration when twist_speeds) (FD).
    length, ldot: leg lengths and rates.
    det: det(J) of each state, for the singularity check.
    All (n, 6) but M, J (n, 6, 6) and det (n,); the base arrays are read per base_mode.
    reflected_mass [kg] along every leg, wrench (n, 6) on the platform in {B} (None: none):
    plant/c/hexapod.h mb_hexapod_kane_ext (h then holds -wrench)."""
    n = pose.shape[0] if isinstance(pose, np.ndarray) and pose.ndim == 2 else -1
    if n < 0:
        raise InvalidInputError(f"pose must be an (n, 6) array, got {np.shape(pose)}")
    s6, s66 = (n, 6), (n, 6, 6)
    lib.mb_hexapod_kane_ext(
        reading(base_joints, (6, 3), "base_joints"), reading(platform_joints, (6, 3), "platform_joints"),
        reading(data, (NDATA,), "data"), n, reading(pose, s6, "pose"), reading(rate, s6, "rate"),
        reading(arg, s6, "arg"), reading(base_pose, s6, "base_pose"), reading(base_rate, s6, "base_rate"),
        reading(base_acc, s6, "base_acc"), base_mode, bool(legs), bool(twist_speeds), solve, float(reflected_mass),
        ffi.NULL if wrench is None else reading(wrench, s6, "wrench"), pointer(M, s66, "M"), pointer(h, s6, "h"),
        pointer(J, s66, "J"), pointer(ldot, s6, "ldot"),
        pointer(length, s6, "length"), pointer(out, s6, "out"), pointer(det, (n,), "det"))


def rhs(bj, pj, data, x, forces, base0, t0, t, base_mode, legs):
    """dx/dt and |det J| of one state x = [pose, twist] under ``forces`` (6,) with the
    base extrapolated from base0 (3, 6) at t0: for implicit integrators and tests."""
    dx = np.empty(12)
    det = lib.mb_hexapod_rhs(reading(bj, (6, 3), "base_joints"), reading(pj, (6, 3), "platform_joints"),
                             reading(data, (NDATA,), "data"), reading(x, (12,), "x"),
                             reading(np.reshape(forces, 6), (6,), "forces"), reading(base0, (3, 6), "base0"),
                             t0, t, base_mode, bool(legs), ffi.from_buffer("double[]", dx))
    return dx, det


def advance_fixed(rk4, substeps, bj, pj, data, x, inputs, t0, h, base_mode, legs, bounds, outputs):
    """Advance x = [pose, twist] over [t0, t0 + h] by ``substeps`` equal steps of classic
    RK4 (or explicit Euler), all in C: the plant FMU's hot path, one call per
    communication step. The same methods as plant.integrators (a test holds them equal).

    inputs (4, 6): leg forces, base pose, base rate, base acc, held over the step.
    bounds (2, 6): lowest and highest leg lengths allowed (the stroke).
    Writes x in place and outputs (3, 6) = leg lengths, leg rates, pose rates at t0 + h.
    Returns (smallest |det J| met, status: OK, BAD_INPUT, DIVERGED or STROKE)."""
    return HexapodKernel(bj, pj, data).advance_fixed(rk4, substeps, x, inputs, t0, h, base_mode, legs,
                                                     bounds, outputs)


class HexapodKernel:
    """One hexapod's parameters held as C pointers, for the per-step calls: the
    parameter arrays are checked once here, the long-lived buffers of a caller once by
    ``pointer``, and a call then converts only what changes."""

    def __init__(self, base_joints, platform_joints, data):
        self._arrays = (base_joints, platform_joints, data)
        self.params = (reading(base_joints, (6, 3), "base_joints"),   # each keeps its array alive
                       reading(platform_joints, (6, 3), "platform_joints"), reading(data, (NDATA,), "data"))
        self._det = ffi.new("double *")
        self.counts = ffi.new("int[2]")   # advance_controlled's substeps: accepted, rejected

    def __reduce__(self):   # pointers do not pickle: rebuild from the arrays
        return HexapodKernel, self._arrays

    def run(self, pose, rate, arg, base_pose, base_rate, base_acc, base_mode, legs, twist_speeds, solve,
            batch=None):
        """plant.hexapod.kernel.kane on n states given as (n, 6) arrays, its outputs views of one
        block: (M, h, J, ldot, length, out, det) with shapes batch + (6, 6), (6,), (6, 6),
        (6,), (6,), (6,), () where ``batch`` (default (n,)) is any leading shape of n states."""
        batch = (len(pose),) if batch is None else batch
        bad, out, det, work = self.checked_run(pose, rate, arg, base_pose, base_rate, base_acc, base_mode, legs,
                                               twist_speeds, solve, batch)
        if bad:
            raise InvalidInputError(f"{', '.join(n for k, n in enumerate(STATE_NAMES) if bad >> k & 1)} "
                                    "contains NaN or inf")
        return (*self.terms(work, batch), out, det)

    def checked_run(self, pose, rate, arg, base_pose, base_rate, base_acc, base_mode, legs, twist_speeds, solve,
                    batch=None):
        """``run`` on n states given as (n, 6) arrays, or on one given as (6,) arrays,
        after the kernel's own NaN/inf check (mb_hexapod_kane_checked): plant.hexapod.model's
        engine. Returns (bad, out, det, work): ``bad`` the check's bitmask (nonzero:
        nothing computed), ``out`` shaped ``batch`` + (6,) (default: the states' shape),
        det J (a float for one (6,) state and no ``batch``) and the block of all
        outputs, for ``terms``."""
        shape = pose.shape
        n = shape[0] if len(shape) == 2 else 1
        work = _empty(97 * n)
        bad = lib.mb_hexapod_kane_checked(*self.params, n, *readings((pose, rate, arg, base_pose, base_rate, base_acc),
                                                                     shape, STATE_NAMES),
                                          base_mode, bool(legs), bool(twist_speeds), solve,
                                          _from_buffer(_DOUBLES, work))
        if len(shape) == 1 and batch is None:
            return bad, work[90:96], work.item(96), work
        batch = shape[:-1] if batch is None else batch
        return bad, work[90 * n:96 * n].reshape(batch + (6,)), work[96 * n:].reshape(batch), work

    @staticmethod
    def terms(work, batch):
        """(M, h, J, ldot, length) of a ``run`` with states of leading shape ``batch``:
        views of its block."""
        n = len(work) // 97
        s6, s66 = batch + (6,), batch + (6, 6)
        return (work[:36 * n].reshape(s66), work[36 * n:42 * n].reshape(s6), work[42 * n:78 * n].reshape(s66),
                work[78 * n:84 * n].reshape(s6), work[84 * n:90 * n].reshape(s6))

    def advance_fixed(self, rk4, substeps, x, inputs, t0, h, base_mode, legs, bounds, outputs):
        """plant.hexapod.kernel.advance_fixed on this hexapod; ``inputs``, ``bounds`` and
        ``outputs`` are arrays or pointers from ``pointer``."""
        if isinstance(inputs, np.ndarray):
            inputs = reading(inputs, (4, 6), "inputs")
        if isinstance(bounds, np.ndarray):
            bounds = reading(bounds, (2, 6), "bounds")
        if isinstance(outputs, np.ndarray):
            outputs = pointer(outputs, (3, 6), "outputs")
        if not substeps >= 1:
            raise InvalidInputError(f"substeps must be >= 1, got {substeps}")
        status = lib.mb_hexapod_advance_fixed(bool(rk4), substeps, *self.params, pointer(x, (12,), "x"),
                                              inputs, t0, h, base_mode, bool(legs), bounds, outputs, self._det)
        return self._det[0], status

    def advance_actuated(self, rk4, substeps, actuator, x, inputs, t0, h, base_mode, legs, bounds, outputs):
        """advance_fixed with the leg actuator ``actuator`` (MB_ACTUATOR_NDATA values: plant/c/hexapod.h)
        and the platform wrench: x (12,) or (18,) with a bandwidth (the six motor forces
        last), inputs (5, 6) with the wrench last, outputs (4, 6) with the delivered leg
        forces last; arrays or pointers from ``pointer``."""
        if isinstance(actuator, np.ndarray):
            actuator = reading(actuator, (ACTUATOR_NDATA,), "actuator")
        if isinstance(inputs, np.ndarray):
            inputs = reading(inputs, (5, 6), "inputs")
        if isinstance(bounds, np.ndarray):
            bounds = reading(bounds, (2, 6), "bounds")
        if isinstance(outputs, np.ndarray):
            outputs = pointer(outputs, (4, 6), "outputs")
        if not substeps >= 1:
            raise InvalidInputError(f"substeps must be >= 1, got {substeps}")
        nx = 18 if _bandwidth(actuator) > 0 else 12
        status = lib.mb_hexapod_advance_actuated(bool(rk4), substeps, *self.params, actuator,
                                                 pointer(x, (nx,), "x"), inputs, t0, h, base_mode, bool(legs),
                                                 bounds, outputs, self._det)
        return self._det[0], status

    def advance_controlled(self, tol, max_step, max_substeps, actuator, x, inputs, t0, h, base_mode, legs, bounds,
                           outputs):
        """advance_actuated with error-controlled RK4 substeps of at most ``max_step`` and
        the lag exact (mb_hexapod_advance_controlled): each substep's pose error at most
        ``tol``, at most ``max_substeps`` tries (else status WORK, x untouched); the
        substeps accepted and rejected are in ``counts``. Pointers as advance_actuated's."""
        nx = 18 if _bandwidth(actuator) > 0 else 12
        status = lib.mb_hexapod_advance_controlled(tol, max_step, max_substeps, *self.params, actuator,
                                                   pointer(x, (nx,), "x"), inputs, t0, h, base_mode, bool(legs),
                                                   bounds, outputs, self._det, self.counts)
        return self._det[0], status

    def rhs_actuated(self, actuator, x, command, wrench, base0, t0, t, base_mode, legs, dx, force=None):
        """|det J| of x ((12,) or (18,) with a bandwidth); dx/dt into dx (same shape), the
        delivered leg forces into ``force`` (6,) when given; wrench (6,) or None."""
        n = len(x)
        return lib.mb_hexapod_rhs_actuated(
            *self.params, reading(actuator, (ACTUATOR_NDATA,), "actuator"), reading(x, (n,), "x"),
            reading(command, (6,), "command"), ffi.NULL if wrench is None else reading(wrench, (6,), "wrench"),
            reading(base0, (3, 6), "base0"), t0, t, base_mode, bool(legs), pointer(dx, (n,), "dx"),
            ffi.NULL if force is None else pointer(force, (6,), "force"))

    def rhs(self, x, forces, base0, t0, t, base_mode, legs, dx):
        """|det J| of x (12,), dx/dt written into dx (12,); forces, base0 arrays or bound
        pointers ((6,) and (3, 6))."""
        if isinstance(forces, np.ndarray):
            forces = reading(np.reshape(forces, 6), (6,), "forces")
        if isinstance(base0, np.ndarray):
            base0 = reading(base0, (3, 6), "base0")
        return lib.mb_hexapod_rhs(*self.params, reading(x, (12,), "x"), forces, base0, t0, t, base_mode,
                                  bool(legs), pointer(dx, (12,), "dx"))

    def leg_kinematics(self, x, outputs):
        """outputs (3, 6) = leg lengths, leg rates and pose rates of x = [pose, twist]."""
        lib.mb_hexapod_leg_kinematics(self.params[0], self.params[1], reading(x, (12,), "x"),
                                      pointer(outputs, (3, 6), "outputs"))


class StateInverseDynamicsCall:
    """mb_hexapod_inverse_dynamics of one state at a time into three buffers of 6 (leg
    forces, lengths, rates), for a caller that calls it every step (plant.hexapod.model's
    StateInverseDynamics builds on it). The inputs' C pointers live in the C setup
    (mb_hexapod_state_inverse_dynamics) and are kept while the caller passes the same
    array object again (held here: the object and its memory live on, and its buffer
    export stops numpy from resizing it), so arrays a caller keeps and refills cost no
    conversion; any other input is checked and converted as ``reading``. A call returns
    the buffers, after ``singular(det)`` when |det J| < ``det_min``."""

    NAMES = ("pose", "pose_rate", "pose_acc", "base_pose", "base_rate", "base_acc")
    __slots__ = ("_keep", "_setup", "_state", "_solve", "_buffers", "_det_min", "_held", "_ptrs")

    def __init__(self, kernel, base_mode, legs, buffers, det_min):
        self._buffers, self._det_min = tuple(buffers), det_min
        out = [pointer(a, np.shape(a) if np.size(a) == 6 else (6,), name)   # any shape of 6 values
               for a, name in zip(self._buffers, ("forces", "leg_lengths", "leg_rates"))]
        self._setup = setup = ffi.new("struct mb_hexapod_state_id *")
        setup.base_joints, setup.platform_joints, setup.data = kernel.params
        setup.base_mode, setup.legs = base_mode, bool(legs)
        setup.forces, setup.length, setup.ldot = out
        self._state = setup.state   # the six input pointers, set by _take
        self._keep = (kernel, out)   # the struct's pointers do not keep their arrays alive: these do
        self._solve = lib.mb_hexapod_state_inverse_dynamics
        self._held, self._ptrs = [_NOTHING] * 6, [None] * 6   # and these keep the inputs' buffers

    def __call__(self, pose, pose_rate, pose_acc, base_pose, base_rate, base_acc):
        """The buffers (leg forces, lengths, rates) of the state: all (6,) float arrays."""
        held = self._held   # unrolled: a loop costs ~0.1 us more per call
        if pose is not held[0]:
            self._take(0, pose)
        if pose_rate is not held[1]:
            self._take(1, pose_rate)
        if pose_acc is not held[2]:
            self._take(2, pose_acc)
        if base_pose is not held[3]:
            self._take(3, base_pose)
        if base_rate is not held[4]:
            self._take(4, base_rate)
        if base_acc is not held[5]:
            self._take(5, base_acc)
        det = self._solve(self._setup)
        if abs(det) < self._det_min:
            self.singular(det)
        return self._buffers

    def singular(self, det):
        """Called with det J when |det J| < det_min: raises SingularConfigurationError."""
        raise SingularConfigurationError(f"singular configuration: |det J| = {abs(det):.2e} < {self._det_min:.2e}")

    def _take(self, k, a):
        """Input k is a new object: its pointer, kept with it when it needs no conversion."""
        try:
            if type(a) is not _ndarray or a.dtype is not _F64 or a.shape != _ONE:
                raise ValueError
            ptr, self._held[k] = _from_buffer(_DOUBLES, a), a   # ValueError when strided
        except ValueError:
            ptr, self._held[k] = reading(a, _ONE, self.NAMES[k]), _NOTHING
        self._ptrs[k] = self._state[k] = ptr
