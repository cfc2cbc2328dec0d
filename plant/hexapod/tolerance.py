"""Geometric tolerances of the hexapod: what errors in its geometry do to the platform's pose.

The controller commands a pose X; it drives each leg to the length the *nominal* inverse
kinematics gives, l_c = IK(X). The real hexapod differs from the nominal one by its inputs
(``geometric_inputs``, named, each with a unit and a tolerance):

=====================  ====  ===========================================================
``leg_offset_i``        m     the leg's real length at home minus the nominal home length l0
``leg_scale_i``         1     the length encoder's scale error: real travel = (1 + k) x read
``homing_i``            m     the homing reference's error, in travel read by the encoder
``base_joint_i_c``      m     B_i's position error, component c = x, y, z in {B}
``platform_joint_i_c``  m     a_i's position error, component c in {P}
=====================  ====  ===========================================================

so a leg commanded to l_c is really  l = l0 + leg_offset + (1 + leg_scale) (l_c - l0 + homing),
and the real pose solves the perturbed geometry's forward kinematics with these lengths: the
pose error is that pose minus X. To first order ``leg_offset_i`` and ``homing_i`` act alike
(their columns of the sensitivity are equal): the pose tells only their sum, which is what a
calibration can identify; they differ at second order (the scale acts on the homing error).

Everything is batched numpy over samples, each with its own geometry: Newton's iterations on
all samples at once (chunks of ``CHUNK``), no Python loop per sample. The kinematics is
plant.hexapod.model's (its leg vectors and Jacobians take a batch of joint positions).

``sensitivity`` is the analytic Jacobian of the pose error with respect to every input at the
nominal geometry; ``linear_indices`` the first-order variance and Sobol indices it gives for
independent uniform inputs. ``sobol_indices`` estimates Sobol indices of any function with SALib
(Saltelli sampling, bootstrap confidence intervals); ``pose_error_sobol`` runs it on the pose
errors. SALib comes with the ``tolerance`` extra and is imported only there.
"""
from typing import NamedTuple

import numpy as np

from plant.errors import InvalidInputError, UnreachablePoseError
from plant.hexapod.model import _legs, _state, _to_pose_jacobian, _twist_jacobian, inverse_kinematics, pose_jacobian

CHUNK = 50_000   # samples per Newton batch: (CHUNK, 6, 6) Jacobians, ~14 MB
COMPONENTS = ("x", "y", "z")
LEG_GROUPS = ("leg_offset", "leg_scale", "homing")
POSE_NAMES = ("x", "y", "z", "roll", "pitch", "yaw")
POSE_UNITS = ("m", "m", "m", "rad", "rad", "rad")


class GeometricInput(NamedTuple):
    """One uncertain input: its name, unit and tolerance (a uniform deviation in +-tolerance)."""

    name: str
    unit: str
    tolerance: float


def geometric_inputs(leg_offset=1e-4, leg_scale=1e-4, homing=2e-5, base_joint=2e-4, platform_joint=2e-4):
    """The 54 inputs in the order a sample's columns take: leg_offset, leg_scale, homing (6 each,
    legs 1-6), base_joint and platform_joint (6 x 3 each, leg-major, x y z). Default tolerances:
    0.1 mm, 100 ppm, 20 um, 0.2 mm, 0.2 mm; a scalar per group."""
    tolerances = dict(leg_offset=leg_offset, leg_scale=leg_scale, homing=homing, base_joint=base_joint,
                      platform_joint=platform_joint)
    for name, value in tolerances.items():
        if not (isinstance(value, (int, float)) and np.isfinite(value) and value >= 0):
            raise InvalidInputError(f"tolerance {name} must be a finite number >= 0, got {value!r}")
    inputs = [GeometricInput(f"{group}_{i}", "1" if group == "leg_scale" else "m", float(tolerances[group]))
              for group in LEG_GROUPS for i in range(1, 7)]
    inputs += [GeometricInput(f"{group}_{i}_{c}", "m", float(tolerances[group]))
               for group in ("base_joint", "platform_joint") for i in range(1, 7) for c in COMPONENTS]
    return tuple(inputs)


N_INPUTS = len(geometric_inputs())


class Geometry(NamedTuple):
    """Joint positions of a batch of hexapods (n, 6, 3), as StewartParams holds one: the
    kinematics of plant.hexapod.model takes either."""

    base_joints: np.ndarray
    platform_joints: np.ndarray


class Perturbed(NamedTuple):
    """A batch of real hexapods: their joints and their legs' length errors (n, 6) each."""

    geometry: Geometry
    leg_offset: np.ndarray
    leg_scale: np.ndarray
    homing: np.ndarray


def perturb(params, samples):
    """The real hexapods of ``samples`` (n, 54): deviations of the inputs, in their order and units."""
    samples = _state(samples, "samples", N_INPUTS).reshape(-1, N_INPUTS)
    legs = samples[:, :18].reshape(-1, 3, 6)
    joints = samples[:, 18:].reshape(-1, 2, 6, 3)
    geometry = Geometry(params.base_joints + joints[:, 0], params.platform_joints + joints[:, 1])
    return Perturbed(geometry, legs[:, 0], legs[:, 1], legs[:, 2])


def real_lengths(params, perturbed, commanded):
    """Leg lengths (n, 6) the real legs take when driven to ``commanded`` (nominal) lengths."""
    home = params.home_lengths
    return home + perturbed.leg_offset + (1 + perturbed.leg_scale) * (commanded - home + perturbed.homing)


def forward_kinematics(geometry, lengths, guess, tol=1e-13, max_iter=20, first=0):
    """Poses (n, 6) of the hexapods ``geometry`` whose legs have ``lengths`` (n, 6), by Newton's
    iterations on all at once from ``guess`` ((6,) or (n, 6)). Raises UnreachablePoseError naming
    the worst sample (counted from ``first``) when the legs cannot meet (no convergence, or a
    singular pose on the way)."""
    pose = np.array(np.broadcast_to(guess, lengths.shape))
    for _ in range(max_iter):
        _, rho, length, s = _legs(geometry, pose)
        error = length[..., 0] - lengths
        worst = np.max(np.abs(error))
        if worst < tol:
            return pose
        jacobian = _to_pose_jacobian(_twist_jacobian(rho, s), pose)
        try:
            step = np.linalg.solve(jacobian, error[..., None])[..., 0]
        except np.linalg.LinAlgError:
            break
        pose -= step
        if not np.isfinite(pose).all() or np.max(np.abs(step[..., :3])) > 10.0:   # diverging
            break
    bad = np.argmax(np.where(np.isfinite(error), np.abs(error), np.inf).max(axis=-1))
    raise UnreachablePoseError(f"forward kinematics of sample {first + bad} found no pose: Newton's iterations "
                               f"diverged or stalled within {max_iter} steps (its leg-length residual "
                               f"{np.max(np.abs(error[bad])):.3e} m): its legs cannot meet")


def pose_errors(params, pose, samples, chunk=CHUNK):
    """Pose errors (n, 6) [m, m, m, rad, rad, rad]: the real pose minus the commanded ``pose`` (6,)
    of each sample (n, 54) of the inputs."""
    pose = _state(pose, "pose")
    if pose.shape != (6,):
        raise InvalidInputError(f"pose must be one pose of shape (6,), got {pose.shape}")
    samples = _state(samples, "samples", N_INPUTS).reshape(-1, N_INPUTS)
    commanded = inverse_kinematics(params, pose)
    out = np.empty((len(samples), 6))
    for start in range(0, len(samples), chunk):
        real = perturb(params, samples[start:start + chunk])
        lengths = real_lengths(params, real, commanded)
        out[start:start + chunk] = forward_kinematics(real.geometry, lengths, pose, first=start) - pose

    return out


def sensitivity(params, pose):
    """d(pose error)/d(input) (6, 54) at the nominal geometry, analytically: the closure
    |p + R (a_i + da_i) - (B_i + dB_i)| = l_i(inputs) differentiated, solved through the
    pose Jacobian."""
    pose = _state(pose, "pose")
    R, _, _, s = _legs(params, pose)
    travel = inverse_kinematics(params, pose) - params.home_lengths
    eye = np.eye(6)
    columns = np.concatenate([
        eye, eye * travel, eye,                                            # d(real length)/d(leg inputs)
        (eye[:, :, None] * s[None]).reshape(6, 18),                          # -dl/dB_i = +s_i
        -(eye[:, :, None] * (s @ R)[None]).reshape(6, 18),                   # -dl/da_i = -R^T s_i
    ], axis=1)
    return np.linalg.solve(pose_jacobian(params, pose), columns)


def linear_indices(params, pose, inputs):
    """First-order model of independent inputs uniform in +-tolerance: (variances (6,) of the
    pose error's components, first-order Sobol indices (6, 54)), from ``sensitivity``."""
    tol = np.array([i.tolerance for i in inputs])
    parts = sensitivity(params, pose) ** 2 * (tol ** 2 / 3)
    variance = parts.sum(axis=1)
    return variance, parts / variance[:, None]


class SobolIndices(NamedTuple):
    """Sobol indices of each output (rows) for each input (columns), with the half-widths of
    their bootstrap confidence intervals at ``confidence``."""

    names: tuple
    first: np.ndarray
    first_conf: np.ndarray
    total: np.ndarray
    total_conf: np.ndarray
    confidence: float
    evaluations: int


def sobol_indices(function, names, bounds, n=1024, seed=0, resamples=500, confidence=0.95):
    """Sobol first-order and total indices of ``function`` (samples (N, d) -> outputs (N,) or
    (N, k)) for independent inputs uniform within ``bounds`` (d pairs), by SALib: Saltelli's
    sampling (n (d + 2) evaluations, ``n`` a power of 2) and bootstrap intervals."""
    try:
        from SALib.analyze import sobol as analyze
        from SALib.sample import sobol as sample
    except ImportError:
        raise ModuleNotFoundError("Sobol indices need SALib: pip install 'movingbase[tolerance]'") from None
    if n < 2 or n & (n - 1):
        raise InvalidInputError(f"n must be a power of 2 (Saltelli's sampling), got {n}")
    bounds = [[float(lo), float(hi)] for lo, hi in bounds]
    if len(bounds) != len(names) or any(not lo < hi for lo, hi in bounds):
        raise InvalidInputError(f"bounds must be {len(names)} pairs (low, high) with low < high")
    problem = {"num_vars": len(names), "names": list(names), "bounds": bounds}
    x = sample.sample(problem, n, calc_second_order=False, seed=seed)
    y = np.asarray(function(x), dtype=float).reshape(len(x), -1)
    found = [analyze.analyze(problem, column, calc_second_order=False, num_resamples=resamples,
                             conf_level=confidence, seed=seed) for column in y.T]
    keys = ("S1", "S1_conf", "ST", "ST_conf")
    return SobolIndices(tuple(names), *(np.array([f[key] for f in found]) for key in keys), confidence, len(x))


def pose_error_sobol(params, pose, inputs=None, n=1024, seed=0, resamples=500, confidence=0.95):
    """``sobol_indices`` of the pose error's six components (rows: x, y, z, roll, pitch, yaw)
    over ``inputs`` (default ``geometric_inputs()``), each uniform in +-tolerance."""
    inputs = geometric_inputs() if inputs is None else tuple(inputs)
    if len(inputs) != N_INPUTS:
        raise InvalidInputError(f"inputs must be the {N_INPUTS} of geometric_inputs(), got {len(inputs)}")
    if any(i.tolerance <= 0 for i in inputs):
        raise InvalidInputError("every input needs a tolerance > 0 for Sobol indices: "
                                + ", ".join(i.name for i in inputs if i.tolerance <= 0))
    return sobol_indices(lambda x: pose_errors(params, pose, x), [i.name for i in inputs],
                         [(-i.tolerance, i.tolerance) for i in inputs], n, seed, resamples, confidence)
