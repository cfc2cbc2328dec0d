"""The C kernel's RK4 step (mb_hexapod_advance_actuated, which computes the base's terms once
for the two middle stages, as they share a time) against the same RK4 assembled here from
four separate mb_hexapod_rhs_actuated calls, each computing its base afresh: equal bit for
bit, over every base mode, actuator variant, wrench and substep count."""
import numpy as np
import pytest

from plant.hexapod import kernel as kane
from plant.hexapod.model import HOME_POSE, StewartParams

PARAMS = StewartParams.paper()
ACTUATORS = {   # [bandwidth, reflected_mass, coulomb, viscous, friction_velocity, force_limit]
    "ideal": [0, 0, 0, 0, 0, 0],
    "lag": [40.0, 0, 0, 0, 0, 0],
    "friction, limit": [0, 0, 50.0, 200.0, 1e-3, 2500.0],
    "all": [25.0, 4.5, 20.0, 100.0, 2e-3, 0],
}


def rk4_by_stages(k, act, x, inputs, t0, h, substeps, base_mode):
    """x after ``substeps`` RK4 steps over [t0, t0 + h] and the smallest |det J| met, as
    mb_hexapod_advance_actuated's loop takes them (same expressions in the same order)."""
    command, base0 = inputs[0], inputs[1:4]
    wrench = inputs[4] if inputs[4].any() else None
    x = x.copy()
    dt, dmin = h / substeps, np.inf

    def rhs(state, t):
        dx = np.empty(len(x))
        d = k.rhs_actuated(act, state, command, wrench, base0, t0, t, base_mode, True, dx)
        return dx, d

    for n in range(substeps):
        t = t0 + n * dt
        k1, d1 = rhs(x, t)
        k2, d2 = rhs(x + 0.5 * dt * k1, t + 0.5 * dt)
        k3, d3 = rhs(x + 0.5 * dt * k2, t + 0.5 * dt)
        k4, d4 = rhs(x + dt * k3, t + dt)
        dmin = min(dmin, d1, d2, d3, d4)
        x = x + dt / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
    return x, dmin


@pytest.mark.parametrize("base_mode", [kane.BASE_NONE, kane.BASE_GRAVITY, kane.BASE_FULL])
@pytest.mark.parametrize("actuator", ACTUATORS)
@pytest.mark.parametrize("substeps", [1, 3])
def test_advance_equals_rk4_of_separate_evaluations(base_mode, actuator, substeps):
    rng = np.random.default_rng(7 + base_mode + 10 * substeps)
    act = np.array(ACTUATORS[actuator], dtype=float)
    k = PARAMS.kernel
    bounds = np.array([np.zeros(6), np.full(6, 1e3)])
    for _ in range(20):
        nx = 18 if act[0] > 0 else 12
        x = np.r_[HOME_POSE + rng.uniform(-0.04, 0.04, 6), rng.uniform(-0.5, 0.5, 6), rng.uniform(-3e3, 3e3, 6)][:nx]
        inputs = np.array([rng.uniform(-3e3, 3e3, 6),
                           np.r_[rng.uniform(-30, 30, 3), rng.uniform(-1.3, 1.3, 3)],
                           rng.uniform(-2, 2, 6), rng.uniform(-3, 3, 6),
                           rng.uniform(-100, 100, 6) * (actuator == "all")])
        t0, h = rng.uniform(0, 100), 2e-3
        expected, dmin = rk4_by_stages(k, act, x, inputs, t0, h, substeps, base_mode)
        got, outputs = x.copy(), np.zeros((4, 6))
        det, status = k.advance_actuated(True, substeps, act, got, inputs, t0, h, base_mode, True, bounds, outputs)
        assert status == kane.OK
        assert got.tobytes() == expected.tobytes()
        assert det == dmin
