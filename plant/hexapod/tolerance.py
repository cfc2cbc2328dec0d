"""Geometric tolerances of the hexapod: what errors in its geometry do to the platform's pose.

The controller commands a pose X; it drives each leg to the length the *nominal* inverse
kinematics gives, l_c = IK(X). The real hexapod differs from the nominal one by its inputs
(``INPUT_NAMES``, in ``GROUPS``, each with a unit):

========================  ====  ===========================================================
``leg_offset_i``          m     the leg's real length at home minus the nominal home length l0
``leg_scale_i``           1     the length encoder's scale error: real travel = (1 + k) x read
``homing_i``              m     the homing reference's error, in travel read by the encoder
``base_joint_i_c``        m     B_i's position error, component c = x, y, z in {B}
``platform_joint_i_c``    m     a_i's position error, component c in {P}
``base_clearance_i``      m     the play of leg i's base joint (its magnitude: |deviation|)
``platform_clearance_i``  m     the play of leg i's platform joint
========================  ====  ===========================================================

so a leg commanded to l_c is really  l = l0 + leg_offset + (1 + leg_scale) (l_c - l0 + homing) + play,
and the real pose solves the perturbed geometry's forward kinematics with these lengths: the
pose error is that pose minus X. To first order ``leg_offset_i`` and ``homing_i`` act alike
(their columns of the sensitivity are equal): the pose tells only their sum, which is what a
calibration can identify; they differ at second order (the scale acts on the homing error).

Joint clearance (ASSUMED model): each joint is a spherical gap of play c = |deviation|; the leg
is loaded along its axis (a two-force member: the legs' own weight bends the load a little,
left out), so the load presses each joint's pin against its socket along the leg: compression
(a leg force > 0, which extends the leg) lengthens the leg by c_base + c_platform, tension
shortens it by as much. The load is the static leg force under gravity at the commanded pose
with the base tilted by the telescope's elevation (roll = 90 deg - E, as plant.telescope's
base_motion; ``load_signs``), from the kit's inverse dynamics: the legs go from tension at the
zenith to mixed signs near the horizon, so the elevation range matters. Near a force's zero
crossing the real joint would float within its play; the model takes the sign.

The batch runs in C (plant/c/tolerance.c: Newton per sample, each with its own commanded pose
and geometry), in chunks of ``CHUNK`` samples whose static leg forces the batched kernel gives.

``sensitivity`` is the analytic Jacobian of the pose error with respect to every input at the
nominal geometry; ``linear_indices`` the first-order variance and Sobol indices it gives for
independent inputs. ``sobol_indices`` estimates Sobol indices of any function with SALib
(Saltelli sampling, bootstrap confidence intervals, inputs singly or in groups);
``pose_error_sobol`` runs it on the pose errors. SALib is a dependency of the kit (``movingbase
budget`` is a main command) and is imported only there.
"""
from typing import NamedTuple

import numpy as np

from plant._kernel import ffi, lib
from plant.errors import InvalidInputError, UnreachablePoseError
from plant.hexapod.model import _legs, _state, inverse_dynamics, inverse_kinematics, pose_jacobian

CHUNK = 50_000   # samples per kernel call: their static leg forces need 97 doubles each
COMPONENTS = ("x", "y", "z")
LEG_GROUPS = ("leg_offset", "leg_scale", "homing")
JOINT_GROUPS = ("base_joint", "platform_joint")
CLEARANCE_GROUPS = ("base_clearance", "platform_clearance")
ZENITH = np.pi / 2
INPUT_NAMES = tuple([f"{g}_{i}" for g in LEG_GROUPS for i in range(1, 7)]
                    + [f"{g}_{i}_{c}" for g in JOINT_GROUPS for i in range(1, 7) for c in COMPONENTS]
                    + [f"{g}_{i}" for g in CLEARANCE_GROUPS for i in range(1, 7)])
N_INPUTS = len(INPUT_NAMES)   # 66
GROUPS = {g: tuple(k for k, name in enumerate(INPUT_NAMES) if name.startswith(g + "_"))
          for g in LEG_GROUPS + JOINT_GROUPS + CLEARANCE_GROUPS}   # group -> its columns
UNITS = {g: "1" if g == "leg_scale" else "m" for g in GROUPS}
CLEARANCE = slice(54, 66)
POSE_NAMES = ("x", "y", "z", "roll", "pitch", "yaw")
POSE_UNITS = ("m", "m", "m", "rad", "rad", "rad")


class GeometricInput(NamedTuple):
    """One uncertain input: its name, unit and tolerance (a uniform deviation in +-tolerance)."""

    name: str
    unit: str
    tolerance: float


def geometric_inputs(leg_offset=1e-4, leg_scale=1e-4, homing=2e-5, base_joint=2e-4, platform_joint=2e-4,
                     base_clearance=1e-5, platform_clearance=1e-5):
    """The 66 inputs in the order a sample's columns take (INPUT_NAMES), each with a tolerance
    of its group (a scalar per group). Defaults: 0.1 mm, 100 ppm, 20 um, 0.2 mm, 0.2 mm, 10 um,
    10 um."""
    tolerances = dict(leg_offset=leg_offset, leg_scale=leg_scale, homing=homing, base_joint=base_joint,
                      platform_joint=platform_joint, base_clearance=base_clearance,
                      platform_clearance=platform_clearance)
    for name, value in tolerances.items():
        if not (isinstance(value, (int, float)) and np.isfinite(value) and value >= 0):
            raise InvalidInputError(f"tolerance {name} must be a finite number >= 0, got {value!r}")
    return tuple(GeometricInput(INPUT_NAMES[k], UNITS[g], float(tolerances[g])) for g in GROUPS for k in GROUPS[g])


def base_tilt(elevation):
    """Base poses (n, 6) of the telescope at ``elevation`` (n,) [rad]: roll = 90 deg - E."""
    tilt = np.zeros((len(elevation), 6))
    tilt[:, 3] = np.pi / 2 - elevation
    return tilt


def load_signs(params, poses, elevation):
    """+1 (compression) or -1 (tension) per leg (n, 6): the sign of the static leg force at the
    commanded ``poses`` (n, 6) under gravity, the base tilted by ``elevation`` (n,) [rad]."""
    still = np.zeros_like(poses)
    forces = inverse_dynamics(params, poses, still, still, base_tilt(elevation), still, still)
    return np.where(forces >= 0, 1.0, -1.0)


def _batch(pose, elevation, n):
    """The commanded poses (n, 6) and elevations (n,) of n samples from one or n of each."""
    pose = _state(pose, "pose")
    if pose.shape not in ((6,), (n, 6)):
        raise InvalidInputError(f"pose must be one pose (6,) or one per sample ({n}, 6), got {pose.shape}")
    elevation = np.asarray(elevation, dtype=float)
    if elevation.shape not in ((), (n,)) or not np.all((elevation >= 0) & (elevation <= np.pi / 2)):
        said = f", from {np.min(elevation):.4g} to {np.max(elevation):.4g} rad" if elevation.size else ""
        raise InvalidInputError(f"elevation must be one or {n} angles in [0, pi/2] rad, got shape "
                                f"{elevation.shape}{said}")
    return np.ascontiguousarray(np.broadcast_to(pose, (n, 6))), np.broadcast_to(elevation, (n,))


def pose_errors(params, pose, samples, elevation=ZENITH, chunk=CHUNK, tol=1e-13, max_iter=20):
    """Pose errors (n, 6) [m, m, m, rad, rad, rad]: the real pose minus the commanded one of each
    sample (n, 66) of the inputs (deviations, INPUT_NAMES' order and units). ``pose``: one
    commanded pose (6,) or one per sample (n, 6); ``elevation`` [rad]: one, or one per sample,
    in [0, pi/2] (it sets the joints' loads, so matters only with clearance). Raises
    UnreachablePoseError naming the first sample whose legs cannot meet (its ``sample``: the row)."""
    samples = np.ascontiguousarray(_state(samples, "samples", N_INPUTS).reshape(-1, N_INPUTS))
    n = len(samples)
    poses, elevation = _batch(pose, elevation, n)
    out = np.empty((n, 6))
    residual = ffi.new("double *")
    home = np.ascontiguousarray(params.home_lengths)
    joints = [ffi.from_buffer("double[]", np.ascontiguousarray(j, dtype=float))
              for j in (params.base_joints, params.platform_joints)]
    for start in range(0, n, chunk):
        rows = slice(start, start + chunk)
        play = ffi.NULL
        clearance = np.abs(samples[rows, CLEARANCE])
        if clearance.any():
            signs = load_signs(params, poses[rows], elevation[rows])
            play = ffi.from_buffer("double[]", np.ascontiguousarray(signs * (clearance[:, :6] + clearance[:, 6:])))
        bad = lib.mb_tolerance_pose_errors(
            len(out[rows]), *joints, ffi.from_buffer("double[]", home),
            ffi.from_buffer("double[]", samples[rows]), play, ffi.from_buffer("double[]", poses[rows]),
            tol, max_iter, ffi.from_buffer("double[]", out[rows]), residual)
        if bad >= 0:
            error = UnreachablePoseError(f"forward kinematics of sample {start + bad} found no pose: Newton's "
                                         f"iterations diverged or stalled within {max_iter} steps (its leg-length "
                                         f"residual {residual[0]:.3e} m): its legs cannot meet")
            error.sample = start + bad   # the row of ``samples``, for a caller that names its inputs
            raise error
    return out


def sensitivity(params, pose, elevation=ZENITH):
    """d(pose error)/d(input) (6, 66) at the nominal geometry, analytically: the closure
    |p + R (a_i + da_i) - (B_i + dB_i)| = l_i(inputs) differentiated, solved through the
    pose Jacobian. A clearance column is the derivative with respect to the play |deviation|."""
    pose = _state(pose, "pose")
    R, _, _, s = _legs(params, pose)
    travel = inverse_kinematics(params, pose) - params.home_lengths
    signs = np.diag(load_signs(params, pose[None], np.array([elevation]))[0])
    eye = np.eye(6)
    columns = np.concatenate([
        eye, eye * travel, eye,                                            # d(real length)/d(leg inputs)
        (eye[:, :, None] * s[None]).reshape(6, 18),                          # -dl/dB_i = +s_i
        -(eye[:, :, None] * (s @ R)[None]).reshape(6, 18),                   # -dl/da_i = -R^T s_i
        signs, signs,                                                      # the plays lengthen or shorten
    ], axis=1)
    return np.linalg.solve(pose_jacobian(params, pose), columns)


def linear_indices(params, pose, variances, elevation=ZENITH):
    """First-order model of independent inputs whose effects have ``variances`` (66,) (of the
    deviation; of the play |deviation| for a clearance): (variances (6,) of the pose error's
    components, first-order Sobol indices (6, 66)), from ``sensitivity``."""
    parts = sensitivity(params, pose, elevation) ** 2 * np.asarray(variances, dtype=float)
    variance = parts.sum(axis=1)
    return variance, parts / variance[:, None]


def uniform_variances(inputs):
    """The effect variances ``linear_indices`` takes of ``inputs`` uniform in +-tolerance: t^2/3,
    and t^2/12 for a clearance (its play |deviation| is uniform in [0, t])."""
    tol = np.array([i.tolerance for i in inputs])
    return tol ** 2 / np.where(np.arange(len(tol)) >= CLEARANCE.start, 12.0, 3.0)


class SobolIndices(NamedTuple):
    """Sobol indices of each output (rows) for each input or group (columns), with the
    half-widths of their bootstrap confidence intervals at ``confidence``."""

    names: tuple
    first: np.ndarray
    first_conf: np.ndarray
    total: np.ndarray
    total_conf: np.ndarray
    confidence: float
    evaluations: int


def sobol_indices(function, names, bounds, n=1024, seed=0, resamples=500, confidence=0.95, groups=None,
                  progress=None):
    """Sobol first-order and total indices of ``function`` (samples (N, d) -> outputs (N,) or
    (N, k)) for independent inputs uniform within ``bounds`` (d pairs), by SALib: Saltelli's
    sampling (n (d + 2) evaluations, ``n`` a power of 2; n (g + 2) with ``groups``, a group
    name per input, whose indices are then the groups') and bootstrap intervals. ``progress``
    (a callable taking the number of outputs analysed) is told as each output's bootstrap ends."""
    try:
        from SALib.analyze import sobol as analyze
        from SALib.sample import sobol as sample
    except ImportError:   # a dependency: only an environment built apart from pyproject.toml lacks it
        raise ModuleNotFoundError("Sobol indices need SALib, a dependency of the kit: pip install -c constraints.txt "
                                  "-e . in a clone, or pip install 'SALib>=1.6,<2'") from None
    if n < 2 or n & (n - 1):
        raise InvalidInputError(f"n must be a power of 2 (Saltelli's sampling), got {n}")
    bounds = [[float(lo), float(hi)] for lo, hi in bounds]
    if len(bounds) != len(names) or any(not lo < hi for lo, hi in bounds):
        raise InvalidInputError(f"bounds must be {len(names)} pairs (low, high) with low < high")
    problem = {"num_vars": len(names), "names": list(names), "bounds": bounds}
    if groups is not None:
        if len(groups) != len(names):
            raise InvalidInputError(f"groups must name a group for each of the {len(names)} inputs")
        problem["groups"] = list(groups)
    x = sample.sample(problem, n, calc_second_order=False, seed=seed)
    y = np.asarray(function(x), dtype=float).reshape(len(x), -1)
    found = []
    for column in y.T:
        found.append(analyze.analyze(problem, column, calc_second_order=False, num_resamples=resamples,
                                     conf_level=confidence, seed=seed))
        if progress:
            progress(1)
    keys = ("S1", "S1_conf", "ST", "ST_conf")
    labels = tuple(dict.fromkeys(groups)) if groups is not None else tuple(names)
    return SobolIndices(labels, *(np.array([f[key] for f in found]) for key in keys), confidence, len(x))


def pose_error_sobol(params, pose, inputs=None, n=1024, seed=0, resamples=500, confidence=0.95):
    """``sobol_indices`` of the pose error's six components (rows: x, y, z, roll, pitch, yaw)
    over ``inputs`` (default ``geometric_inputs()``), each uniform in +-tolerance, at the zenith."""
    inputs = geometric_inputs() if inputs is None else tuple(inputs)
    if len(inputs) != N_INPUTS:
        raise InvalidInputError(f"inputs must be the {N_INPUTS} of geometric_inputs(), got {len(inputs)}")
    if any(i.tolerance <= 0 for i in inputs):
        raise InvalidInputError("every input needs a tolerance > 0 for Sobol indices: "
                                + ", ".join(i.name for i in inputs if i.tolerance <= 0))
    return sobol_indices(lambda x: pose_errors(params, pose, x), [i.name for i in inputs],
                         [(-i.tolerance, i.tolerance) for i in inputs], n, seed, resamples, confidence)
