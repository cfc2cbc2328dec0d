"""Where methods fail (studies.stability): the co-simulation's communication-step limit,
the explicit integrators' step limit on the stiff closed loop, convergence orders inside
the safe region, and refusal at a singular pose."""
import math

import numpy as np
import pytest

from controller.design import closed_loop_stable, max_stable_step
from plant import integrators
from plant.errors import ConvergenceError, SingularConfigurationError
from plant.hexapod.model import HOME_POSE, StewartParams, forward_dynamics, inverse_dynamics
from plant.hexapod.ode import HexapodODE
from studies.stability import (
    FAILED,
    GAINS,
    OFFSET,
    PARAMS,
    SMALL_SCALES,
    SMALL_STEPS,
    STABLE,
    UNSTABLE,
    ClosedLoopODE,
    CoSim,
    classify,
    closed_loop_matrix,
    cosim_convergence,
    observed_integrator_limit,
    orders,
    plant_convergence,
    predicted,
    predicted_integrator_limit,
    scaled,
    spurious_fixed_point,
    sweep,
)

SINGULAR_POSE = np.r_[HOME_POSE[:5], np.pi / 2]   # yaw 90 deg: the legs' Jacobian is singular


@pytest.fixture(scope="module")
def cosim(fmus):
    return CoSim(paths=fmus)


@pytest.fixture(scope="module")
def step_limit():
    return max_stable_step(PARAMS, GAINS)


# ------------------------------------------------------------------ co-simulation step
def test_the_default_design_predicts_a_step_limit_of_about_3_4_ms(step_limit):
    assert 3.0e-3 < step_limit < 3.8e-3


def test_comm_step_beyond_the_predicted_limit_is_unstable_in_co_simulation(cosim, step_limit):
    h = 1.3 * step_limit
    assert not closed_loop_stable(PARAMS, GAINS, h)[0]
    out = cosim.run(h, duration=1.0)
    assert out.verdict == UNSTABLE, out
    assert out.error.max() > 10 * out.error[0]          # the error grows ...
    assert out.saturated                                # ... until the force limit caps it


def test_comm_step_inside_the_predicted_limit_is_stable_in_co_simulation(cosim, step_limit):
    h = 0.7 * step_limit
    assert closed_loop_stable(PARAMS, GAINS, h)[0]
    out = cosim.run(h, duration=1.0)
    assert out.verdict == STABLE, out
    assert out.error[-1] < 1e-3 * out.error[0] and not out.saturated


@pytest.mark.parametrize("k, h", [(0.177, 1e-3), (0.25, 8e-3)], ids=["below the gain limit", "beyond the step limit"])
def test_a_slowly_unstable_loop_grows_at_the_predicted_rate(cosim, k, h):
    """Unsaturated growth: the observed rate of the error's envelope is ln(rho) / h."""
    stable, radius = predicted(h, k)
    assert not stable
    out = cosim.run(h, k, duration=2.0)
    assert out.verdict == UNSTABLE and not out.saturated
    assert out.rate == pytest.approx(math.log(radius) / h, rel=0.3)


def test_a_refused_step_is_classified_as_a_failed_run(cosim):
    out = cosim.run(1e-3, offset=SINGULAR_POSE - HOME_POSE, duration=0.01)
    assert out.verdict == FAILED
    assert "SingularConfigurationError" in out.message and "plant" in out.message


def test_a_coarse_sweep_agrees_with_the_prediction(cosim):
    study = sweep(steps=[1e-3, 8e-3], scales=[0.125, 1.0], cosim=cosim, refine=0)
    assert study.verdicts.tolist() == [[UNSTABLE, UNSTABLE], [STABLE, UNSTABLE]]
    assert study.agreement == 1.0


@pytest.mark.slow
def test_the_default_sweep_agrees_with_the_prediction(cosim):
    study = sweep(SMALL_STEPS, SMALL_SCALES, cosim=cosim, refine=5)
    assert study.agreement >= 0.95
    for k, h_pred, good, bad in study.step_limits:
        if np.isfinite(bad):
            assert good / 1.05 < h_pred < bad * 1.05, (k, h_pred, good, bad)


# ------------------------------------------------------------- explicit integrators
def test_the_linearised_closed_loop_is_the_jacobian_of_the_monolithic_ode():
    ode = ClosedLoopODE()
    z = ode.initial_state(np.zeros(6))
    assert np.abs(ode.rhs(0.0, z)).max() < 1e-9                  # at rest at home
    eps = np.r_[np.full(6, 1e-7), np.full(6, 1e-6), np.full(6, 1e-9)]
    jac = np.column_stack([(ode.rhs(0.0, z + e) - ode.rhs(0.0, z - e)) / (2 * e.sum()) for e in np.diag(eps)])
    mine = np.sort_complex(np.linalg.eigvals(jac))
    predicted_eigs = np.sort_complex(np.linalg.eigvals(closed_loop_matrix()))
    np.testing.assert_allclose(mine, predicted_eigs, atol=1e-3 * np.abs(predicted_eigs).max())


def test_predicted_step_limits_are_those_of_the_stiffest_eigenvalue():
    euler, lam = predicted_integrator_limit("euler")
    rk4, lam4 = predicted_integrator_limit("rk4")
    assert lam.imag == 0 and lam == lam4 and lam.real < -200        # -kd/m of the lightest mode
    assert euler == pytest.approx(2 / -lam.real, rel=1e-6)
    assert rk4 == pytest.approx(2.785293563 / -lam.real, rel=1e-6)  # RK4 meets the real axis at -2.785


@pytest.mark.parametrize("method", ["euler", "rk4"])
def test_explicit_integrator_beyond_its_limit_raises_and_inside_runs(method):
    limit = predicted_integrator_limit(method)[0]
    ode = ClosedLoopODE()
    with pytest.raises(ConvergenceError, match=f"{method} diverged"):
        ode.simulate(method, 1.3 * limit, 2.0)
    t, error, _ = ode.simulate(method, 0.7 * limit, 2.0)
    assert np.isfinite(error).all() and error[-1] < 1e-3 * error[0]


@pytest.mark.parametrize("method", ["euler", "rk4"])
def test_the_observed_integrator_limit_brackets_the_prediction(method):
    good, bad = observed_integrator_limit(method, iterations=7)
    assert good / 1.01 < predicted_integrator_limit(method)[0] < bad * 1.01


def test_rk4_just_beyond_its_limit_can_settle_on_a_spurious_fixed_point_without_an_error():
    """A failure no finiteness check sees: at low gain, RK4 4 % beyond its limit neither
    blows up nor raises; it settles on a fixed point of the RK4 map far from the
    equilibrium (cm off, heave rate of m/s while the pose stays put). The study's
    classifier flags it (the error grew), the integrator does not."""
    ghost = spurious_fixed_point(k=0.25, factor=1.04)
    assert ghost["change"] < 1e-9                       # steady ...
    assert ghost["leg_error"] > 0.01 and abs(ghost["heave_rate"]) > 1.0 and ghost["residual"] > 1.0  # ... and wrong
    ode = ClosedLoopODE(scaled(GAINS, 0.25))
    t, error, _ = ode.simulate("rk4", ghost["step"], 300 * ghost["step"])
    assert classify(t, error)[0] == UNSTABLE


def test_integrators_advance_reports_divergence_as_an_error_not_nan():
    """plant.integrators.advance on the linearised loop, many substeps beyond the limit:
    the state overflows, and advance raises instead of returning inf/NaN."""
    A = closed_loop_matrix()
    x0 = np.r_[OFFSET, np.zeros(12)]
    limit = predicted_integrator_limit("euler")[0]
    with np.errstate(over="ignore", invalid="ignore"):
        with pytest.raises(ConvergenceError, match="no longer finite"):
            integrators.advance("euler", lambda t, x: A @ x, 0.0, x0, 2000 * 1.3 * limit, 1.3 * limit)
    x = integrators.advance("euler", lambda t, x: A @ x, 0.0, x0, 2.0, 0.7 * limit)
    assert np.isfinite(x).all() and np.abs(x[:6]).max() < 1e-3 * np.abs(OFFSET).max()


# ------------------------------------------------------------------ convergence orders
def test_plant_rk4_converges_at_order_4():
    steps, errors = plant_convergence("rk4", (0.1, 0.05, 0.025, 0.0125))
    p = orders(steps, errors)
    assert np.all((p > 3.6) & (p < 4.4)), (errors, p)          # ~16x per halving


def test_plant_euler_converges_at_order_1():
    steps, errors = plant_convergence("euler", (0.02, 0.01, 0.005, 0.0025))
    p = orders(steps, errors)
    assert np.all((p > 0.9) & (p < 1.2)), (errors, p)


def test_co_simulation_converges_at_order_1_to_the_monolithic_loop(cosim):
    """ZOH + one step of delay: the error against the continuous closed loop halves with h."""
    steps, errors = cosim_convergence(cosim, (1e-3, 5e-4, 2.5e-4))
    p = orders(steps, errors)
    assert np.all((p > 0.9) & (p < 1.15)), (errors, p)
    assert errors[0] < 0.05 * np.abs(OFFSET).max()             # and it is small at 1 ms


# ---------------------------------------------------------------------- singular pose
@pytest.mark.parametrize("yaw_off", [0.0, 1e-7, -1e-7], ids=["at", "just below", "just above"])
def test_plant_refuses_a_singular_pose_with_a_clear_error(yaw_off):
    params = StewartParams.paper(stroke=(-10.0, 10.0))       # so the stroke check does not fire first
    pose = SINGULAR_POSE + np.r_[np.zeros(5), yaw_off]
    ode = HexapodODE(params, moving_base=False)
    ode.set_inputs(0.0, np.zeros(6))
    with pytest.raises(SingularConfigurationError, match="singular"):
        ode.advance(np.r_[pose, np.zeros(6)], 1e-3)
    with pytest.raises(SingularConfigurationError, match="singular"):
        forward_dynamics(params, pose, np.zeros(6), np.zeros(6))
    with pytest.raises(SingularConfigurationError, match="singular"):
        inverse_dynamics(params, pose, np.zeros(6), np.zeros(6))


def test_the_monolithic_loop_refuses_a_singular_reference():
    with pytest.raises(SingularConfigurationError):
        ClosedLoopODE(reference=SINGULAR_POSE)
