"""The geometric tolerance pipeline (plant/hexapod/tolerance.py, its C kernel plant/c/tolerance.c)
against independent truths: a numpy Newton solve of the same model (the second method), the
exact inverse kinematics of each perturbed geometry, statics for the joints' loads, central
differences of the nonlinear pose error, Monte Carlo variances, and the Ishigami function's
known Sobol indices."""
import dataclasses

import numpy as np
import pytest

from plant.errors import InvalidInputError, UnreachablePoseError
from plant.hexapod import tolerance as tl
from plant.hexapod.model import (
    HOME_POSE,
    S_BAND_POSE,
    StewartParams,
    _legs,
    _to_pose_jacobian,
    _twist_jacobian,
    inverse_kinematics,
    jacobian,
)

TILTED = HOME_POSE + [0.05, -0.04, 0.06, 0.03, -0.02, 0.04]


@pytest.fixture(scope="module")
def params():
    return StewartParams.paper(d=0.2)


def tolerances(inputs):
    return np.array([i.tolerance for i in inputs])


def perturbed(params, sample):
    """The real hexapod of one sample (66,): a StewartParams with its joints, and its legs' errors."""
    joints = sample[18:54].reshape(2, 6, 3)
    geometry = dataclasses.replace(params, base_joints=params.base_joints + joints[0],
                                   platform_joints=params.platform_joints + joints[1])
    return geometry, sample[:6], sample[6:12], sample[12:18]


def numpy_pose_errors(params, poses, samples, signs):
    """The model written again in numpy, one sample at a time: the real legs' lengths, then Newton
    on the perturbed geometry (the second method for the C kernel)."""
    out = []
    for pose, sample, sign in zip(poses, samples, signs):
        geometry, offset, scale, homing = perturbed(params, sample)
        play = sign * (np.abs(sample[54:60]) + np.abs(sample[60:66]))
        home = params.home_lengths
        lengths = home + offset + (1 + scale) * (inverse_kinematics(params, pose) - home + homing) + play
        x = pose.copy()
        for _ in range(20):
            _, rho, length, s = _legs(geometry, x)
            error = length[:, 0] - lengths
            if np.max(np.abs(error)) < 1e-13:
                break
            x -= np.linalg.solve(_to_pose_jacobian(_twist_jacobian(rho, s), x), error)
        out.append(x - pose)
    return np.array(out)


def workspace(n, seed):
    """n commanded poses about home (+-50 mm, +-0.05 rad) and elevations in [0, 90] deg."""
    rng = np.random.default_rng(seed)
    poses = HOME_POSE + rng.uniform(-1, 1, (n, 6)) * [0.05, 0.05, 0.05, 0.05, 0.05, 0.05]
    return poses, rng.uniform(0, np.pi / 2, n)


def test_inputs_are_named_with_units():
    inputs = tl.geometric_inputs()
    assert len(inputs) == tl.N_INPUTS == 66 and len({i.name for i in inputs}) == 66
    assert inputs[6] == ("leg_scale_1", "1", 1e-4) and inputs[18] == ("base_joint_1_x", "m", 2e-4)
    assert inputs[53] == ("platform_joint_6_z", "m", 2e-4) and inputs[-1] == ("platform_clearance_6", "m", 1e-5)
    assert [inputs[k].name for k in tl.GROUPS["base_clearance"]] == [f"base_clearance_{i}" for i in range(1, 7)]


def test_kernel_equals_the_numpy_solve(params):
    """Each sample its own pose, elevation and geometry (mm-sized errors, clearance included): the
    C kernel's pose errors are the numpy Newton solve's to 1e-12 (m and rad)."""
    poses, elevation = workspace(40, 11)
    samples = np.random.default_rng(5).uniform(-1, 1, (40, 66)) * 2e-3
    errors = tl.pose_errors(params, poses, samples, elevation)
    signs = tl.load_signs(params, poses, elevation)
    assert 0 < np.mean(signs > 0) < 1   # both tension and compression met
    reference = numpy_pose_errors(params, poses, samples, signs)
    assert np.max(np.abs(errors[:, :3])) > 1e-3
    assert np.max(np.abs(errors - reference)) < 1e-12


@pytest.mark.parametrize("pose", [S_BAND_POSE, TILTED], ids=["s_band", "tilted"])
def test_round_trip_through_the_exact_inverse_kinematics(params, pose):
    """Samples of 5 mm / 1 % errors: the solved real pose, put through the inverse kinematics of a
    StewartParams with that sample's joints, gives the real legs' lengths to 1e-12 m."""
    inputs = tl.geometric_inputs(5e-3, 1e-2, 5e-3, 5e-3, 5e-3, 0.0, 0.0)
    samples = np.random.default_rng(7).uniform(-1, 1, (8, 66)) * tolerances(inputs)
    errors = tl.pose_errors(params, pose, samples)
    assert np.max(np.abs(errors[:, :3])) > 1e-3   # far from the nominal pose: a real test
    commanded = inverse_kinematics(params, pose)
    home = params.home_lengths
    for sample, error in zip(samples, errors):
        geometry, offset, scale, homing = perturbed(params, sample)
        lengths = home + offset + (1 + scale) * (commanded - home + homing)
        assert np.max(np.abs(inverse_kinematics(geometry, pose + error) - lengths)) < 1e-12


@pytest.mark.parametrize("elevation", [0.0, 0.3, 0.8, np.pi / 2])
def test_joint_loads_are_the_statics_of_the_hanging_platform(elevation):
    """Massless legs: the load signs are those of the leg forces F with J^T F balancing the
    platform's weight, tilted by the elevation (statics, not the kernel); at the zenith the
    platform hangs from six legs in tension."""
    params = StewartParams.paper(cylinder_mass=0.0, rod_mass=0.0, cylinder_inertia=np.zeros(3),
                                 rod_inertia=np.zeros(3))
    poses, _ = workspace(20, 3)
    tilt = np.pi / 2 - elevation   # roll of the base: gravity in {B} is R_x(tilt)^T (0, 0, -g)
    weight = params.platform_mass * params.gravity * np.array([0.0, -np.sin(tilt), -np.cos(tilt)])
    for pose in poses:
        R = _legs(params, pose)[0]
        wrench = np.concatenate([weight, np.cross(R @ np.zeros(3), weight)])   # o_P is the mass centre
        forces = np.linalg.solve(jacobian(params, pose).T, -wrench)
        signs = tl.load_signs(params, pose[None], np.array([elevation]))[0]
        sure = np.abs(forces) > 1.0
        assert np.array_equal(signs[sure], np.sign(forces[sure]))
        if elevation == np.pi / 2:
            assert np.all(signs == -1)


def test_clearance_matters_with_elevation(params):
    """The same plays give another pose error at another elevation: the loads change sign."""
    sample = np.zeros(66)
    sample[tl.CLEARANCE] = 2e-5
    zenith, horizon = (tl.pose_errors(params, HOME_POSE, sample, e)[0] for e in (np.pi / 2, 0.0))
    assert abs(zenith[2] - horizon[2]) > 1e-6 and abs(zenith[2]) > 1e-5
    assert np.array_equal(tl.pose_errors(params, HOME_POSE, -sample)[0], zenith)   # the play is |deviation|


def test_nominal_geometry_has_no_error(params):
    assert np.max(np.abs(tl.pose_errors(params, TILTED, np.zeros((3, 66))))) < 1e-14


@pytest.mark.parametrize("pose", [S_BAND_POSE, TILTED], ids=["s_band", "tilted"])
def test_sensitivity_is_the_derivative_of_the_pose_error(params, pose):
    """The analytic Jacobian against central differences of the nonlinear pipeline, every input
    (a clearance's play |deviation| one-sided), at an elevation where the loads differ."""
    h, elevation = 1e-6, 0.2
    steps = h * np.eye(66)
    numeric = (tl.pose_errors(params, pose, steps, elevation) - tl.pose_errors(params, pose, -steps, elevation)).T
    numeric /= 2 * h
    numeric[:, tl.CLEARANCE] = tl.pose_errors(params, pose, steps[tl.CLEARANCE], elevation).T / h
    analytic = tl.sensitivity(params, pose, elevation)
    assert np.max(np.abs(analytic)) > 0.1
    assert np.max(np.abs(numeric[:, :54] - analytic[:, :54])) < 1e-8
    assert np.max(np.abs(numeric[:, 54:] - analytic[:, 54:])) < 1e-5


def test_first_order_variance_matches_monte_carlo(params):
    """Small tolerances: the sampled pose errors' variances are the first-order model's (to the
    sampling error), and what the first order misses shrinks as the square of the tolerances."""
    inputs = tl.geometric_inputs()
    variance, _ = tl.linear_indices(params, TILTED, tl.uniform_variances(inputs))
    samples = np.random.default_rng(3).uniform(-1, 1, (20_000, 66)) * tolerances(inputs)
    errors = tl.pose_errors(params, TILTED, samples)
    assert np.allclose(errors.var(axis=0) / variance, 1, atol=0.05)
    linear = np.concatenate([samples[:, :54], np.abs(samples[:, 54:])], axis=1) @ tl.sensitivity(params, TILTED).T
    missed = [np.max(np.abs(tl.pose_errors(params, TILTED, scale * samples[:500]) - scale * linear[:500]))
              for scale in (1, 10)]
    assert 80 < missed[1] / missed[0] < 120


def ishigami(x, a=7.0, b=0.1):
    return np.sin(x[:, 0]) + a * np.sin(x[:, 1]) ** 2 + b * x[:, 2] ** 4 * np.sin(x[:, 0])


def test_ishigami_indices_through_the_pipeline():
    """The known indices (a = 7, b = 0.1) lie within the pipeline's 99 % bootstrap intervals."""
    first, total = [0.3139, 0.4424, 0.0], [0.5576, 0.4424, 0.2437]
    found = tl.sobol_indices(ishigami, ["x1", "x2", "x3"], [(-np.pi, np.pi)] * 3, n=8192, seed=1,
                             confidence=0.99)
    assert found.evaluations == 8192 * 5
    assert np.all(np.abs(found.first[0] - first) <= found.first_conf[0])
    assert np.all(np.abs(found.total[0] - total) <= found.total_conf[0])
    assert np.max(found.first_conf) < 0.05


def test_pose_error_sobol_matches_first_order(params):
    """Small tolerances, a near-linear map: SALib's indices of the pose error are the analytic
    first-order ones (first within their 99 % intervals, total, which is sharper, within 0.005)."""
    inputs = tl.geometric_inputs()
    _, linear = tl.linear_indices(params, S_BAND_POSE, tl.uniform_variances(inputs))
    found = tl.pose_error_sobol(params, S_BAND_POSE, inputs, n=1024, seed=2, resamples=100, confidence=0.99)
    assert found.first.shape == (6, 66) and found.names == tuple(i.name for i in inputs)
    assert np.mean(np.abs(found.first - linear) <= found.first_conf) > 0.95
    assert np.max(np.abs(found.first - linear)) < 0.05
    assert np.max(np.abs(found.total - linear)) < 0.005


def test_bad_inputs_are_named(params):
    with pytest.raises(InvalidInputError, match=r"samples must have shape \(\.\.\., 66\)"):
        tl.pose_errors(params, S_BAND_POSE, np.zeros((2, 6)))
    with pytest.raises(InvalidInputError, match="pose must be one pose"):
        tl.pose_errors(params, np.zeros((2, 6)), np.zeros((3, 66)))
    with pytest.raises(InvalidInputError, match="elevation must be"):
        tl.pose_errors(params, HOME_POSE, np.zeros((3, 66)), elevation=2.0)
    with pytest.raises(InvalidInputError, match="tolerance homing"):
        tl.geometric_inputs(homing=-1e-5)
    with pytest.raises(InvalidInputError, match="power of 2"):
        tl.sobol_indices(ishigami, ["a", "b", "c"], [(0, 1)] * 3, n=1000)
    with pytest.raises(InvalidInputError, match="tolerance > 0.*leg_scale_1"):
        tl.pose_error_sobol(params, S_BAND_POSE, tl.geometric_inputs(leg_scale=0))
    far = np.zeros((3, 66))
    far[2, 0] = 10.0   # leg 1 of sample 2 is 10 m too long
    with pytest.raises(UnreachablePoseError, match="sample 2 found no pose"):
        tl.pose_errors(params, S_BAND_POSE, far, chunk=2)
