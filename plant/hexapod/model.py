"""The 6-UPS subreflector hexapod (Yao et al. 2018): kinematics and Kane dynamics.

Conventions are those of docs/conventions/stewart-6ups.md. Decisions the spec leaves open:

* Generalised speeds u = (v, w): the velocity of o_P and the angular velocity of {P},
  both *relative to the base* and expressed in {B}. The public functions take and return
  RPY-angle rates (the API of the issue); they are converted at the edge.
* The equations of motion read  M(q) du/dt + h(q, u, base) = J(q)^T F,  with J the leg
  Jacobian (dl/dt = J u), F the actuator forces (positive extends the leg). h holds the
  velocity terms, gravity turned into {B} and the base's transport and Coriolis terms.
* Kane's partial velocities of a leg are all linear in the velocity of its platform
  joint, so each leg reduces to a 3x3 "joint mass" K = m_m s s^T + k_t (1 - s s^T),
  k_t = (m_f l_f^2 + m_m (l - l_m)^2 + I_t) / l^2, and M assembles in closed form.
* Only the base's acceleration, angular velocity and angular acceleration enter: a base
  in uniform translation changes nothing, so base_rate[:3] is accepted and unused.
* Leg stroke is not in the paper: we assume home length +- 0.15 m (a parameter).

Fidelity levels (what each drops), chosen by the ``fidelity`` argument:

=================  ===========================================================
``"full"``         everything above.
``"massless_legs"``  the legs' mass and inertia (platform only; base motion in full).
``"base_gravity"``   of the base motion, keeps only gravity turning with {B}; drops the
                   transport, centripetal and Coriolis terms.
``"no_base"``        the base motion altogether: gravity is (0, 0, -g) in {B} (the
                   "fixed-base model" a controller uses when it ignores the base).
=================  ===========================================================
"""
from dataclasses import dataclass, field
from functools import cached_property
from typing import NamedTuple

import numpy as np

from plant.errors import InvalidInputError, SingularConfigurationError, StrokeError, UnreachablePoseError
from plant.hexapod import kernel as kane
from plant.rotations import angular_velocity, cross, rpy_matrix, rpy_rate_matrix

FIDELITIES = ("full", "massless_legs", "base_gravity", "no_base")
HOME_POSE = np.array([0.0, 0.0, -2.6815, 0.0, 0.0, 0.0])
# the paper's S-band pose, the end of its 6 s manoeuvre
S_BAND_POSE = np.array([5.43e-3, 22.55e-3, -2655.07e-3, np.radians(0.07), np.radians(-0.07), 0.0])

# Joint angles of spec Table (deg): base B_i and platform a_i, legs 1..6.
_BASE_ANGLES = np.radians([85, 95, 205, 215, 325, 335])
_PLATFORM_ANGLES = np.radians([35, 145, 155, 265, 275, 25])


@dataclass(frozen=True, eq=False)
class StewartParams:
    """Geometry, masses and inertias (SI) of the hexapod; immutable, built once."""

    base_joints: np.ndarray          # (6, 3) B_i in {B}
    platform_joints: np.ndarray      # (6, 3) a_i in {P}, relative to o_P
    platform_mass: float
    platform_inertia: np.ndarray     # (3,) principal moments at the centre of mass, axes of {P}
    cylinder_mass: float             # base-side leg part
    cylinder_com: float              # l_f, from B_i along the leg
    cylinder_inertia: np.ndarray     # (3,) axial, transverse, transverse
    rod_mass: float                  # platform-side leg part
    rod_com: float                   # l_m, from a_i back along the leg
    rod_inertia: np.ndarray          # (3,)
    gravity: float = 9.8
    d: float = 0.0
    stroke: tuple = field(default=(-0.15, 0.15))  # leg length range about home [m]
    home_pose: np.ndarray = field(default_factory=lambda: HOME_POSE.copy())
    platform_com: np.ndarray = field(default_factory=lambda: np.zeros(3))   # (3,) centre of mass in {P} [m]

    @classmethod
    def paper(cls, d=0.0, **overrides):
        """The paper's Table 1 in SI; ``d`` is the joint-circle height above o_P."""
        R, r = 2.060, 1.555
        base = R * np.stack([np.cos(_BASE_ANGLES), np.sin(_BASE_ANGLES), 0 * _BASE_ANGLES], -1)
        plat = r * np.stack([np.cos(_PLATFORM_ANGLES), np.sin(_PLATFORM_ANGLES), 0 * _BASE_ANGLES], -1)
        plat[:, 2] = d
        values = dict(
            base_joints=base, platform_joints=plat,
            platform_mass=2129.7, platform_inertia=np.array([3683.0, 3683.0, 6474.0]),
            cylinder_mass=299.8, cylinder_com=0.766842, cylinder_inertia=np.array([4.3, 112.6, 112.6]),
            rod_mass=85.91, rod_com=0.806132, rod_inertia=np.array([0.3, 18.28, 18.28]), d=d,
        )
        values.update(overrides)
        return cls(**values)

    @cached_property
    def home_lengths(self):
        return inverse_kinematics(self, self.home_pose)

    @cached_property
    def home_det(self):
        return abs(np.linalg.det(jacobian(self, self.home_pose)))

    @cached_property
    def kernel(self):
        """The C kernel (plant.hexapod.kernel) bound to these parameters, their pointers taken once."""
        return kane.HexapodKernel(self.base_joints, self.platform_joints, self.kernel_data)

    @cached_property
    def kernel_data(self):
        """Scalars in the order plant.hexapod.kernel.kane expects."""
        return np.array([self.platform_mass, *self.platform_inertia, self.cylinder_mass,
                         self.cylinder_com, self.rod_mass, self.rod_com,
                         self.cylinder_inertia[0] + self.rod_inertia[0],
                         self.cylinder_inertia[1] + self.rod_inertia[1], self.gravity, *self.platform_com])


def body_problems(mass, inertia):
    """What no rigid body can have in ``mass`` [kg] and principal moments ``inertia`` (3,)
    [kg.m2] at its centre of mass: a mass not > 0, a moment not > 0 (the tensor, diagonal in
    its principal axes, not positive definite), or a moment larger than the other two
    together (I_a + I_b >= I_c for every axis c: the triangle inequalities, which hold since
    I_a + I_b - I_c = 2 sum m z^2 >= 0). Empty when it is admissible; each problem one line."""
    found = []
    if not (np.isfinite(mass) and mass > 0):
        found.append(f"mass {mass:.6g} kg is not > 0")
    inertia = np.asarray(inertia, dtype=float)
    for c, name in enumerate("xyz"):
        a, b = (inertia[j] for j in range(3) if j != c)
        if not (np.isfinite(inertia[c]) and inertia[c] > 0):
            found.append(f"I{name}{name} = {inertia[c]:.6g} kg.m2 is not > 0 (the inertia tensor must be positive "
                         "definite)")
        elif not inertia[c] <= a + b:
            others = "+".join(f"I{n}{n}" for n in "xyz" if n != name)
            found.append(f"I{name}{name} = {inertia[c]:.6g} kg.m2 exceeds {others} = {a + b:.6g} kg.m2 by "
                         f"{inertia[c] - a - b:.4g} kg.m2 (triangle inequality: no rigid body has it)")
    return found


def check_body(mass, inertia, what="the platform"):
    """InvalidInputError naming every law ``body_problems`` finds broken."""
    found = body_problems(mass, inertia)
    if found:
        raise InvalidInputError(f"{what} is no rigid body: " + "; ".join(found))


class DynamicsTerms(NamedTuple):
    """M du/dt + h = J^T F at one state (batched): mass matrix, bias, leg Jacobian."""

    mass: np.ndarray      # (..., 6, 6)
    bias: np.ndarray      # (..., 6)
    jacobian: np.ndarray  # (..., 6, 6)
    leg_rates: np.ndarray  # (..., 6)
    leg_lengths: np.ndarray  # (..., 6)
    det_ratio: np.ndarray  # (...,) |det J| / |det J at home|: near 0 means singular


# ----------------------------------------------------------------------------- checks
def _state(x, name, width=6):
    x = np.asarray(x, dtype=float)
    if x.ndim == 0 or x.shape[-1] != width:
        raise InvalidInputError(f"{name} must have shape (..., {width}), got {x.shape}")
    if not np.isfinite(x).all():
        raise InvalidInputError(f"{name} contains NaN or inf")
    return x


# ------------------------------------------------------------------------- kinematics
def _legs(params, pose):
    """Platform joints rho = R a_i (in {B}), leg vectors, lengths and unit vectors."""
    R = rpy_matrix(pose[..., 3:6])
    rho = params.platform_joints @ np.swapaxes(R, -1, -2)
    leg = pose[..., None, :3] + rho - params.base_joints
    length = np.sqrt(np.sum(leg * leg, axis=-1, keepdims=True))
    return R, rho, length, leg / length


def inverse_kinematics(params, pose):
    """Leg lengths (..., 6) [m] of the platform pose (..., 6) in {B}."""
    return _legs(params, _state(pose, "pose"))[2][..., 0]


def _twist_jacobian(rho, s):
    return np.concatenate([s, cross(rho, s)], axis=-1)


def jacobian(params, pose):
    """Leg Jacobian (..., 6, 6): dl/dt = J @ (v, w), with v, w of {P} relative to {B} in {B}."""
    _, rho, _, s = _legs(params, _state(pose, "pose"))
    return _twist_jacobian(rho, s)


def pose_jacobian(params, pose):
    """dl/d(pose) (..., 6, 6): the leg Jacobian for RPY-angle rates."""
    return _to_pose_jacobian(jacobian(params, pose), pose)


def _to_pose_jacobian(J, pose):
    return np.concatenate([J[..., :3], J[..., 3:] @ rpy_rate_matrix(pose[..., 3:6])], axis=-1)


SINGULAR_RATIO = 1e-6


def check_singular(params, J, what="configuration"):
    """Raise SingularConfigurationError where |det J| falls below 1e-6 of home."""
    _check_det_ratio(np.abs(np.linalg.det(J)) / params.home_det, what)


def _check_det_ratio(ratio, what="configuration"):
    if (ratio < SINGULAR_RATIO).any():   # an array's or a numpy scalar's .any(): no np.any overhead
        raise SingularConfigurationError(
            f"singular {what}: |det J| is {np.min(ratio):.2e} of its home value (< {SINGULAR_RATIO})")


def check_stroke(params, lengths):
    """Raise StrokeError naming the first leg whose length is outside home + stroke."""
    lengths = np.asarray(lengths, dtype=float)
    low, high = params.home_lengths + params.stroke[0], params.home_lengths + params.stroke[1]
    bad = np.argwhere((lengths < low) | (lengths > high) | ~np.isfinite(lengths))
    if bad.size:
        idx = tuple(bad[0])
        leg = idx[-1]
        raise StrokeError(f"leg {leg + 1} length {lengths[idx]:.6f} m outside its stroke "
                          f"[{low[leg]:.6f}, {high[leg]:.6f}] m")


def forward_kinematics(params, lengths, guess=None, tol=1e-12, max_iter=50):
    """Pose (..., 6) whose leg lengths are ``lengths`` (..., 6), by Newton iteration.

    Starts from ``guess`` (default: the home pose). Raises UnreachablePoseError when
    Newton does not converge (the legs cannot meet) and SingularConfigurationError
    when it runs into a singular pose."""
    lengths = _state(lengths, "lengths")
    if np.any(lengths <= 0):
        raise UnreachablePoseError("leg lengths must be positive")
    pose = np.broadcast_to(params.home_pose if guess is None else _state(guess, "guess"),
                           lengths.shape).copy()
    for _ in range(max_iter):
        error = inverse_kinematics(params, pose) - lengths
        if np.max(np.abs(error)) < tol:
            return pose
        J = jacobian(params, pose)
        check_singular(params, J, "pose in forward kinematics")
        step = np.linalg.solve(_to_pose_jacobian(J, pose), error[..., None])[..., 0]
        pose -= step
        if not np.isfinite(pose).all() or np.max(np.abs(step[..., :3])) > 10.0:
            break
    raise UnreachablePoseError(
        f"forward kinematics did not converge in {max_iter} Newton steps "
        f"(max leg-length residual {np.max(np.abs(error)):.3e} m): lengths out of reach")




# --------------------------------------------------------------------------- dynamics
_FIDELITY_MODES = {  # fidelity -> (base motion kept, legs have mass)
    "full": (kane.BASE_FULL, True),
    "massless_legs": (kane.BASE_FULL, False),
    "base_gravity": (kane.BASE_GRAVITY, True),
    "no_base": (kane.BASE_NONE, True),
}


def fidelity_mode(fidelity):
    """(base motion the kernel keeps, legs have mass) of a fidelity level, or an error
    naming the choices."""
    if fidelity not in _FIDELITY_MODES:
        raise InvalidInputError(f"unknown fidelity {fidelity!r}; choose one of {FIDELITIES}")
    return _FIDELITY_MODES[fidelity]


_ONE_STATE = (6,)
_F64 = np.dtype(np.float64)
_NO_BASE = np.zeros(6)   # a base argument left at 0, for a single state
_NO_BASE.flags.writeable = False


def _omitted(x):
    """Whether a base argument is left at 0: no base motion of that kind."""
    if type(x) is int or type(x) is float:   # np.ndim of a Python number costs ~1 us
        return x == 0
    if type(x) is np.ndarray:
        return x.ndim == 0 and x == 0
    return np.ndim(x) == 0 and x == 0


def _flat(arrays, labels):
    """The states as float arrays, shape-checked, broadcast and flattened to (n, 6),
    and the broadcast shape: the general (batched) call."""
    arrays = [np.asarray(x, dtype=float) for x in arrays]
    for x, name in zip(arrays, labels):
        if x.ndim == 0 or x.shape[-1] != 6:
            raise InvalidInputError(f"{name} must have shape (..., 6), got {x.shape}")
    shape = arrays[0].shape
    if any(x.shape != shape for x in arrays):
        try:
            shape = np.broadcast_shapes(*(x.shape for x in arrays))
        except ValueError:
            raise InvalidInputError("arguments do not broadcast: " + ", ".join(
                f"{n} {x.shape}" for n, x in zip(labels, arrays))) from None
        arrays = [np.broadcast_to(x, shape) for x in arrays]
    return [np.ascontiguousarray(x).reshape(-1, 6) for x in arrays], shape


def _run(params, pose, rate, arg, base, fidelity, solve, twist_speeds=False, arg_name="pose_acc", terms=True):
    """Validate, broadcast and flatten the states, run the Kane kernel, reshape back:
    (out, DynamicsTerms), or out alone when not ``terms``.

    Written for the single-state call too (a controller calls it every step): float64
    (6,) arrays go to the kernel as they are, the kernel looks for NaN/inf in one pass
    (the argument is named from its bitmask), the singular check is a scalar compare for
    one state, and DynamicsTerms is built only when asked for."""
    base_mode, legs = fidelity_mode(fidelity)
    names = ("pose", "twist" if twist_speeds else "pose_rate", arg_name, "base_pose", "base_rate", "base_acc")
    given = [k for k, x in enumerate(base) if not _omitted(x)]
    if not given:
        base_mode = kane.BASE_NONE
    arrays = [pose, rate, arg, *(base[k] for k in given)]
    batch = None   # one (6,) state: the kernel's det comes back a scalar
    for x in arrays:
        if type(x) is not np.ndarray or x.dtype is not _F64 or x.shape != _ONE_STATE:
            arrays, shape = _flat(arrays, names[:3] + tuple(names[3 + k] for k in given))
            batch = shape[:-1]
            break
    no_base = _NO_BASE if batch is None else np.zeros(arrays[0].shape)
    full = [no_base] * 3
    for k, x in zip(given, arrays[3:]):
        full[k] = x
    bad, out, det, work = params.kernel.checked_run(*arrays[:3], *full, base_mode, legs, twist_speeds, solve,
                                                    batch)
    if bad:
        raise InvalidInputError(f"{', '.join(n for k, n in enumerate(names) if bad >> k & 1)} contains NaN or inf")
    if batch is None:   # one state: float arithmetic (the same IEEE operations), numpy's scalar type kept
        ratio = abs(det) / float(params.home_det)
        if ratio < SINGULAR_RATIO:
            _check_det_ratio(np.float64(ratio))
        if not terms:
            return out
        ratio, batch = np.float64(ratio), ()
    else:
        ratio = np.abs(det) / params.home_det
        _check_det_ratio(ratio)
        if not terms:
            return out
    return out, DynamicsTerms(*kane.HexapodKernel.terms(work, batch), ratio)


def inverse_dynamics(params, pose, pose_rate, pose_acc, base_pose=0, base_rate=0, base_acc=0,
                     fidelity="full"):
    """Leg forces (..., 6) [N] that produce the motion; positive extends the leg.

    ``pose`` [x, y, z, roll, pitch, yaw] of {P} in {B}, ``pose_rate``/``pose_acc`` its
    time derivatives; ``base_*`` the same for {B} in {W} (all 0 = fixed base). Batched
    over leading dimensions. Raises SingularConfigurationError at a singular pose."""
    return _run(params, pose, pose_rate, pose_acc, (base_pose, base_rate, base_acc), fidelity, kane.ID, terms=False)


def inverse_dynamics_terms(params, pose, pose_rate, pose_acc, base_pose=0, base_rate=0, base_acc=0,
                           fidelity="full"):
    """(leg forces, DynamicsTerms) from one kernel call: a controller gets its
    feedforward and the reference leg lengths and rates together."""
    return _run(params, pose, pose_rate, pose_acc, (base_pose, base_rate, base_acc), fidelity, kane.ID)


def forward_dynamics(params, pose, pose_rate, forces, base_pose=0, base_rate=0, base_acc=0,
                     fidelity="full"):
    """Pose accelerations (..., 6) (second derivatives of [x, y, z, roll, pitch, yaw])
    under leg forces ``forces`` (..., 6). Arguments as in inverse_dynamics."""
    return _run(params, pose, pose_rate, forces, (base_pose, base_rate, base_acc), fidelity,
                kane.FD, arg_name="forces", terms=False)


def dynamics_terms(params, pose, pose_rate, base_pose=0, base_rate=0, base_acc=0, fidelity="full",
                   twist_speeds=False):
    """M (mass matrix), h (bias: velocity, gravity and base terms), J and leg rates, so
    that M du/dt + h = J^T F with u = (v, w). ``pose_rate`` is the twist u itself when
    ``twist_speeds``."""
    return _run(params, pose, pose_rate, np.zeros(6), (base_pose, base_rate, base_acc), fidelity,
                kane.TERMS, twist_speeds)[1]


class StateInverseDynamics(kane.StateInverseDynamicsCall):
    """Inverse dynamics of one state at a time into preallocated buffers, for a
    controller that calls it every step: no broadcasting and no per-argument checks (the
    caller checks its inputs for NaN/inf once), and the C pointers of input arrays the
    caller passes again kept. Called with pose, pose_rate, pose_acc, base_pose,
    base_rate, base_acc (float arrays (6,)), returns the forces, leg lengths and leg
    rates, each (1, 6) (buffers, overwritten next call). Still raises
    SingularConfigurationError at a singular pose."""

    def __init__(self, params, fidelity="full"):
        self.params = params
        self.base_mode, self.legs = fidelity_mode(fidelity)
        self.forces, self.leg_lengths, self.leg_rates = np.empty((1, 6)), np.empty((1, 6)), np.empty((1, 6))
        super().__init__(params.kernel, self.base_mode, self.legs, (self.forces, self.leg_lengths, self.leg_rates),
                         SINGULAR_RATIO * params.home_det)

    def singular(self, det):
        _check_det_ratio(np.array([abs(det) / self.params.home_det]))


def twist_from_rates(pose, pose_rate):
    """(v, w) (..., 6) of {P} relative to {B} from the pose and its RPY-angle rates."""
    return np.concatenate([pose_rate[..., :3], angular_velocity(pose[..., 3:6], pose_rate[..., 3:6])], -1)


def rates_from_twist(pose, twist):
    """Pose rates (RPY-angle rates) from the twist (v, w)."""
    rpy_rate = np.linalg.solve(rpy_rate_matrix(pose[..., 3:6]), twist[..., 3:, None])[..., 0]
    return np.concatenate([twist[..., :3], rpy_rate], axis=-1)
