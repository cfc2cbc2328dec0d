"""The disturbance observer (controller/c/observer.c) against closed-form responses."""
import numpy as np
import pytest

from controller.design import leg_mass_matrix
from controller.observer import observer_mass_matrix, observer_start, observer_update
from plant.hexapod.model import StewartParams

ZETA = 1 / np.sqrt(2)


def q_step(bandwidth, t):
    """Step response of Q(s) = w^2 / (s^2 + 2 zeta w s + w^2), zeta = 1/sqrt(2), closed form."""
    w = 2 * np.pi * bandwidth
    wd = w * np.sqrt(1 - ZETA ** 2)
    return 1 - np.exp(-ZETA * w * t) * (np.cos(wd * t) + ZETA / np.sqrt(1 - ZETA ** 2) * np.sin(wd * t))


def run(bandwidth, mass, gaps, errors, h):
    """Estimates of every step; ``mass`` a scalar (on the diagonal) or the (n, n) matrix."""
    mass = np.asarray(mass, dtype=float)
    mass = mass * np.eye(errors.shape[1]) if mass.ndim == 0 else mass
    state, out = observer_start(errors[0]), []
    for gap, error in zip(gaps, errors):
        estimate, state = observer_update(bandwidth, mass, state, gap, error, h)
        out.append(estimate)
    return np.array(out)


@pytest.mark.parametrize("h", [1e-3, 2e-4])
def test_force_gap_step_follows_q_exactly(h):
    """A step of the force gap held from sample 0: the estimate at sample k is Q's step
    response at t = k h to rounding (zero-order hold is exact for a held input)."""
    n, f = 400, np.array([250.0, -80.0])
    est = run(12.0, 2000.0, np.tile(f, (n, 1)), np.zeros((n, 2)), h)
    t = np.arange(n) * h
    assert np.allclose(est, np.outer(q_step(12.0, t), f), rtol=0, atol=1e-9 * 250)


def test_step_wind_on_a_free_mass_is_estimated_through_q():
    """A pure mass m pushed by a step force F from t = 0, no actuator force, no model force:
    l = F t^2 / (2 m). The observer, told the right mass, estimates F through Q, 1.5 steps
    late (the second difference is centred one step back, its input acts one step later);
    told a wrong mass, it is off by the mass ratio."""
    m, F, bw, h, n = 2600.0, 400.0, 10.0, 1e-4, 3000
    t = np.arange(n) * h
    lengths = (F * t ** 2 / (2 * m))[:, None]
    est = run(bw, m, np.zeros((n, 1)), lengths, h)[:, 0]
    truth = F * q_step(bw, np.maximum(t - 1.5 * h, 0))
    assert np.abs(est - truth).max() < 1e-4 * F
    assert est[-1] == pytest.approx(F, rel=1e-3)
    wrong = run(bw, 0.5 * m, np.zeros((n, 1)), lengths, h)[:, 0]
    assert wrong[-1] == pytest.approx(0.5 * F, rel=1e-3)


def test_discrete_q_is_python_controls_zero_order_hold():
    """The filter against python-control's c2d(Q, h, "zoh") of the continuous Q (an
    independent discretisation): for any held gap sequence the estimate of step k is the
    sampled filter's output after the inputs of steps 0..k-1, to rounding."""
    import control
    bw, h, n = 31.0, 1e-3, 300
    w = 2 * np.pi * bw
    q = control.c2d(control.ss([[0, 1], [-w * w, -2 * ZETA * w]], [[0], [w * w]], [[1, 0]], 0), h, "zoh")
    gaps = np.random.default_rng(3).normal(0, 1e3, n)
    truth = control.forced_response(q, T=np.arange(n) * h, U=gaps).outputs
    est = run(bw, 2000.0, gaps[:, None], np.zeros((n, 1)), h)[:, 0]
    assert np.abs(est - truth).max() < 1e-9 * np.abs(truth).max()


def test_leg_space_mass_keeps_the_models_modes_at_the_mean_diagonal():
    """observer_mass_matrix: scalar -> mass I; leg_space -> the model plus a shift of its
    diagonal: same off-diagonal terms, eigenvalues all moved by mass - mean diagonal."""
    model = leg_mass_matrix(StewartParams.paper())
    assert np.array_equal(observer_mass_matrix(2000.0, model, False), 2000.0 * np.eye(6))
    m = observer_mass_matrix(2606.0, model, True)
    assert np.trace(m) / 6 == pytest.approx(2606.0, rel=1e-14)
    assert np.array_equal(m - np.diag(np.diag(m)), model - np.diag(np.diag(model)))
    shift = 2606.0 - np.trace(model) / 6
    assert np.allclose(np.linalg.eigvalsh(m), np.linalg.eigvalsh(model) + shift, rtol=1e-12)


def test_leg_space_matrix_estimates_a_constant_leg_force_on_the_plants_own_mass():
    """Six coupled legs, the plant the hexapod's exact leg-space mass at home plus 758 kg
    reflected per leg, pushed by a constant external leg force F from rest (no actuator, no
    noise): l = M^-1 F t^2 / 2. Told M (leg_space, mean diagonal M's), the observer estimates
    F on every leg through Q, 1.5 steps late, to 1e-4 of its size; told one scalar (the
    mean diagonal, the old way) it is off by (m I M^-1 - I) F: tens of percent on a leg."""
    plant = leg_mass_matrix(StewartParams.paper()) + 758.0 * np.eye(6)
    force = np.array([400.0, -250.0, 120.0, 300.0, -500.0, 80.0])
    bw, h, n = 20.0, 1e-4, 3000
    t = np.arange(n) * h
    lengths = np.outer(t ** 2 / 2, np.linalg.solve(plant, force))
    mean = np.trace(plant) / 6
    est = run(bw, observer_mass_matrix(mean, plant - 758.0 * np.eye(6), True), np.zeros((n, 6)), lengths, h)
    truth = np.outer(q_step(bw, np.maximum(t - 1.5 * h, 0)), force)
    assert np.abs(est - truth).max() < 1e-4 * np.abs(force).max()
    assert np.allclose(est[-1], force, rtol=1e-3)
    scalar = run(bw, mean, np.zeros((n, 6)), lengths, h)[-1]
    assert np.allclose(scalar, mean * np.linalg.solve(plant, force), rtol=1e-3)
    assert np.abs(scalar - force).max() > 0.1 * np.abs(force).max()


def test_more_legs_than_the_kernel_holds_are_refused_by_name():
    """The kernel's kept constants hold a 6 x 6 mass matrix: 7 legs are refused before the call."""
    with pytest.raises(ValueError, match="1 to 6 legs, got 7"):
        observer_update(10.0, np.eye(7), observer_start(np.zeros(7)), np.zeros(7), np.zeros(7), 1e-3)
