"""The disturbance observer (controller/c/observer.c) against closed-form responses."""
import numpy as np
import pytest

from controller.observer import observer_start, observer_update

ZETA = 1 / np.sqrt(2)


def q_step(bandwidth, t):
    """Step response of Q(s) = w^2 / (s^2 + 2 zeta w s + w^2), zeta = 1/sqrt(2), closed form."""
    w = 2 * np.pi * bandwidth
    wd = w * np.sqrt(1 - ZETA ** 2)
    return 1 - np.exp(-ZETA * w * t) * (np.cos(wd * t) + ZETA / np.sqrt(1 - ZETA ** 2) * np.sin(wd * t))


def run(bandwidth, mass, gaps, errors, h):
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
