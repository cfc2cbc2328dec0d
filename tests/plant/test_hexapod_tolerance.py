"""The geometric tolerance pipeline (plant/hexapod/tolerance.py) against independent truths: the
exact inverse kinematics of each perturbed geometry, central differences of the nonlinear pose
error, Monte Carlo variances, and the Ishigami function's known Sobol indices."""
import dataclasses

import numpy as np
import pytest

from plant.errors import InvalidInputError, UnreachablePoseError
from plant.hexapod import tolerance as tl
from plant.hexapod.model import HOME_POSE, S_BAND_POSE, StewartParams, inverse_kinematics

TILTED = HOME_POSE + [0.05, -0.04, 0.06, 0.03, -0.02, 0.04]


@pytest.fixture(scope="module")
def params():
    return StewartParams.paper(d=0.2)


def tolerances(inputs):
    return np.array([i.tolerance for i in inputs])


def test_inputs_are_named_with_units():
    inputs = tl.geometric_inputs()
    assert len(inputs) == tl.N_INPUTS == 54 and len({i.name for i in inputs}) == 54
    assert inputs[6] == ("leg_scale_1", "1", 1e-4) and inputs[18] == ("base_joint_1_x", "m", 2e-4)
    assert inputs[-1] == ("platform_joint_6_z", "m", 2e-4)


@pytest.mark.parametrize("pose", [S_BAND_POSE, TILTED], ids=["s_band", "tilted"])
def test_round_trip_through_the_exact_inverse_kinematics(params, pose):
    """Samples of 5 mm / 1 % errors: the solved real pose, put through the inverse kinematics of a
    StewartParams with that sample's joints, gives the real legs' lengths to 1e-12 m."""
    inputs = tl.geometric_inputs(5e-3, 1e-2, 5e-3, 5e-3, 5e-3)
    samples = np.random.default_rng(7).uniform(-1, 1, (8, 54)) * tolerances(inputs)
    errors = tl.pose_errors(params, pose, samples)
    assert np.max(np.abs(errors[:, :3])) > 1e-3   # far from the nominal pose: a real test
    commanded = inverse_kinematics(params, pose)
    for sample, error in zip(samples, errors):
        real = tl.perturb(params, sample)
        geometry = dataclasses.replace(params, base_joints=real.geometry.base_joints[0],
                                       platform_joints=real.geometry.platform_joints[0])
        lengths = tl.real_lengths(params, real, commanded)[0]
        assert np.max(np.abs(inverse_kinematics(geometry, pose + error) - lengths)) < 1e-12


def test_nominal_geometry_has_no_error(params):
    assert np.max(np.abs(tl.pose_errors(params, TILTED, np.zeros((3, 54))))) < 1e-14


@pytest.mark.parametrize("pose", [S_BAND_POSE, TILTED], ids=["s_band", "tilted"])
def test_sensitivity_is_the_derivative_of_the_pose_error(params, pose):
    """The analytic Jacobian against central differences of the nonlinear pipeline, every input."""
    h = 1e-6
    steps = h * np.eye(54)
    numeric = (tl.pose_errors(params, pose, steps) - tl.pose_errors(params, pose, -steps)).T / (2 * h)
    analytic = tl.sensitivity(params, pose)
    assert np.max(np.abs(analytic)) > 0.1
    assert np.max(np.abs(numeric - analytic)) < 1e-8


def test_first_order_variance_matches_monte_carlo(params):
    """Small tolerances: the sampled pose errors' variances are the first-order model's (to the
    sampling error), and what the first order misses shrinks as the square of the tolerances."""
    inputs = tl.geometric_inputs()
    variance, _ = tl.linear_indices(params, TILTED, inputs)
    samples = np.random.default_rng(3).uniform(-1, 1, (20_000, 54)) * tolerances(inputs)
    errors = tl.pose_errors(params, TILTED, samples)
    assert np.allclose(errors.var(axis=0) / variance, 1, atol=0.05)
    linear = samples @ tl.sensitivity(params, TILTED).T
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
    _, linear = tl.linear_indices(params, S_BAND_POSE, inputs)
    found = tl.pose_error_sobol(params, S_BAND_POSE, inputs, n=1024, seed=2, resamples=100, confidence=0.99)
    assert found.first.shape == (6, 54) and found.names == tuple(i.name for i in inputs)
    assert np.mean(np.abs(found.first - linear) <= found.first_conf) > 0.95
    assert np.max(np.abs(found.first - linear)) < 0.05
    assert np.max(np.abs(found.total - linear)) < 0.005


def test_bad_inputs_are_named(params):
    with pytest.raises(InvalidInputError, match=r"samples must have shape \(\.\.\., 54\)"):
        tl.pose_errors(params, S_BAND_POSE, np.zeros((2, 6)))
    with pytest.raises(InvalidInputError, match="pose must be one pose"):
        tl.pose_errors(params, np.zeros((2, 6)), np.zeros(54))
    with pytest.raises(InvalidInputError, match="tolerance homing"):
        tl.geometric_inputs(homing=-1e-5)
    with pytest.raises(InvalidInputError, match="power of 2"):
        tl.sobol_indices(ishigami, ["a", "b", "c"], [(0, 1)] * 3, n=1000)
    with pytest.raises(InvalidInputError, match="tolerance > 0.*leg_scale_1"):
        tl.pose_error_sobol(params, S_BAND_POSE, tl.geometric_inputs(leg_scale=0))
    far = np.zeros((3, 54))
    far[2, 0] = 10.0   # leg 1 of sample 2 is 10 m too long
    with pytest.raises(UnreachablePoseError, match="sample 2 found no pose"):
        tl.pose_errors(params, S_BAND_POSE, far, chunk=2)
