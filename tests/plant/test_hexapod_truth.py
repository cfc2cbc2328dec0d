"""Kane's-method hexapod (plant/hexapod/model.py) against an independent
Newton-Euler reference (tests/plant/newton_euler.py).

The reference rebuilds geometry and masses from the spec, computes absolute
world-frame kinematics by automatic differentiation and solves the 78
Newton-Euler equations of the 13 bodies with explicit joint reactions.
"""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from tests.plant import newton_euler as ne

HOME = np.array([0.0, 0.0, -2.6815, 0.0, 0.0, 0.0])
N_FIXED = 200
N_MOVING = 200
RTOL = 1e-8          # relative to the largest |F_i| of the state


# --------------------------------------------------------------------------
# random states
# --------------------------------------------------------------------------
def platform_states(rng, n):
    pose = HOME + np.c_[rng.uniform(-0.05, 0.05, (n, 3)),
                        np.deg2rad(rng.uniform(-2.0, 2.0, (n, 3)))]
    rate = np.c_[rng.uniform(-0.1, 0.1, (n, 3)), rng.uniform(-0.5, 0.5, (n, 3))]
    acc = np.c_[rng.uniform(-1.0, 1.0, (n, 3)), rng.uniform(-5.0, 5.0, (n, 3))]
    return pose, rate, acc


def base_states(rng, n):
    direction = rng.normal(size=(n, 3))
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    pos = direction * rng.uniform(20.0, 40.0, (n, 1))          # |p_B| ~ 30 m
    ang = np.c_[rng.uniform(-1.3, 1.3, n),                     # roll (elevation)
                rng.uniform(-1.0, 1.0, n),                     # pitch
                rng.uniform(-np.pi, np.pi, n)]                 # yaw (azimuth)
    pose = np.c_[pos, ang]
    rate = np.c_[rng.uniform(-2.0, 2.0, (n, 3)), rng.uniform(-1.0, 1.0, (n, 3))]
    acc = np.c_[rng.uniform(-3.0, 3.0, (n, 3)), rng.uniform(-3.0, 3.0, (n, 3))]
    return pose, rate, acc


@pytest.fixture(scope="module")
def fixed_case():
    rng = np.random.default_rng(20180705)
    pose, rate, acc = platform_states(rng, N_FIXED)
    ref = ne.inverse_dynamics(pose, rate, acc)
    return pose, rate, acc, ref


@pytest.fixture(scope="module")
def moving_case():
    rng = np.random.default_rng(65)
    pose, rate, acc = platform_states(rng, N_MOVING)
    bpose, brate, bacc = base_states(rng, N_MOVING)
    ref = ne.inverse_dynamics(pose, rate, acc, bpose, brate, bacc)
    return pose, rate, acc, bpose, brate, bacc, ref


def max_rel_err(F, ref):
    scale = np.max(np.abs(ref), axis=-1)
    return np.max(np.abs(F - ref).max(axis=-1) / scale)


# --------------------------------------------------------------------------
# self-checks of the reference (do not need plant/)
# --------------------------------------------------------------------------
def test_reference_power_balance_fixed_base(fixed_case):
    """Fixed base: actuator power sum F_i l_dot_i = d(T + V)/dt."""
    pose, rate, acc, _ = fixed_case
    for k in range(0, N_FIXED, 10):
        F, res, x, kin = ne.inverse_dynamics_single(pose[k], rate[k], acc[k],
                                                    return_residual=True)
        assert res < 1e-12
        P = sum(F[i] * kin["legs"][i]["l_dot"] for i in range(6))
        dE = ne.energy_rate(kin)
        assert abs(P - dE) <= 1e-9 * (np.abs(F).max() * 0.1 + abs(dE))


def test_reference_power_balance_moving_base(moving_case):
    """Moving base: actuator power + power of the U-joint reactions (the base
    does work) = d(T + V)/dt, all in {W}."""
    pose, rate, acc, bp, br, ba, _ = moving_case
    for k in range(0, N_MOVING, 10):
        F, res, x, kin = ne.inverse_dynamics_single(pose[k], rate[k], acc[k], bp[k],
                                                    br[k], ba[k], return_residual=True)
        assert res < 1e-12
        P = sum(F[i] * kin["legs"][i]["l_dot"] for i in range(6)) + ne.base_power(x, kin)
        dE = ne.energy_rate(kin)
        scale = np.abs(x).max() * 100.0   # |reaction| x |velocity| (~100 m/s)
        assert abs(P - dE) <= 1e-10 * scale


def test_reference_statics_virtual_work():
    """At rest, J^T F = dV/dq (virtual work; V = potential energy of all
    bodies), J = dl/dq, both by central differences in the pose."""
    pose = HOME + np.array([0.02, -0.03, 0.01, 0.01, -0.02, 0.015])
    F = ne.inverse_dynamics_single(pose, np.zeros(6), np.zeros(6))
    t = ne.PAPER
    g = t.gravity

    def lengths_and_V(q):
        kin = ne.world_kinematics(q, np.zeros(6), np.zeros(6))
        V = t.platform_mass * g * kin["platform"]["r"][2]
        V += sum(t.cylinder_mass * g * leg["cyl"]["r"][2]
                 + t.rod_mass * g * leg["rod"]["r"][2] for leg in kin["legs"])
        return np.array([leg["l"] for leg in kin["legs"]]), V

    h = 1e-5
    J = np.zeros((6, 6))
    dV = np.zeros(6)
    for j in range(6):
        e = np.zeros(6)
        e[j] = h
        lp, Vp = lengths_and_V(pose + e)
        lm, Vm = lengths_and_V(pose - e)
        J[:, j] = (lp - lm) / (2 * h)
        dV[j] = (Vp - Vm) / (2 * h)
    np.testing.assert_allclose(J.T @ F, dV, rtol=0, atol=1e-5 * np.abs(dV).max())


# --------------------------------------------------------------------------
# plant/hexapod/model.py against the reference
# --------------------------------------------------------------------------
@pytest.fixture(scope="module")
def stewart():
    return pytest.importorskip("plant.hexapod.model")


@pytest.fixture(scope="module")
def params(stewart):
    return stewart.StewartParams.paper()


def test_tables_match_spec(params):
    t = ne.PAPER
    assert params.d == pytest.approx(t.d, abs=0)
    np.testing.assert_allclose(np.asarray(params.base_joints), t.base_joints,
                               rtol=0, atol=1e-12)
    t_d = dataclasses.replace(t, d=float(params.d))
    np.testing.assert_allclose(np.asarray(params.platform_joints), t_d.platform_joints,
                               rtol=0, atol=1e-12)
    assert params.platform_mass == pytest.approx(t.platform_mass, rel=1e-15)
    I_p = np.asarray(params.platform_inertia, dtype=float)
    if I_p.shape == (3,):          # principal moments about the axes of {P}
        I_p = np.diag(I_p)
    np.testing.assert_allclose(I_p, t.platform_inertia, rtol=1e-15, atol=0)
    assert params.cylinder_mass == pytest.approx(t.cylinder_mass, rel=1e-15)
    assert params.cylinder_com == pytest.approx(t.cylinder_com, rel=1e-15)
    np.testing.assert_allclose(np.asarray(params.cylinder_inertia), t.cylinder_inertia,
                               rtol=1e-15, atol=0)
    assert params.rod_mass == pytest.approx(t.rod_mass, rel=1e-15)
    assert params.rod_com == pytest.approx(t.rod_com, rel=1e-15)
    np.testing.assert_allclose(np.asarray(params.rod_inertia), t.rod_inertia,
                               rtol=1e-15, atol=0)
    assert params.gravity == pytest.approx(9.8, rel=1e-15)


def test_fixed_base_batched(stewart, params, fixed_case):
    pose, rate, acc, ref = fixed_case
    F = np.asarray(stewart.inverse_dynamics(params, pose, rate, acc))
    assert F.shape == (N_FIXED, 6)
    err = max_rel_err(F, ref)
    print(f"fixed base: max relative error {err:.2e}")
    assert err < RTOL


def test_fixed_base_single_state(stewart, params, fixed_case):
    pose, rate, acc, ref = fixed_case
    for k in (0, 7):
        F = np.asarray(stewart.inverse_dynamics(params, pose[k], rate[k], acc[k]))
        assert F.shape == (6,)
        assert max_rel_err(F, ref[k]) < RTOL
    # explicit zero base arguments give the same as the defaults
    F0 = np.asarray(stewart.inverse_dynamics(params, pose[0], rate[0], acc[0],
                                             np.zeros(6), np.zeros(6), np.zeros(6)))
    assert max_rel_err(F0, ref[0]) < RTOL


def test_fixed_base_2d_batch(stewart, params, fixed_case):
    pose, rate, acc, ref = fixed_case
    sh = (4, 5, 6)
    F = np.asarray(stewart.inverse_dynamics(params, pose[:20].reshape(sh),
                                            rate[:20].reshape(sh), acc[:20].reshape(sh)))
    assert F.shape == sh
    assert max_rel_err(F.reshape(20, 6), ref[:20]) < RTOL


def test_moving_base_batched(stewart, params, moving_case):
    pose, rate, acc, bp, br, ba, ref = moving_case
    F = np.asarray(stewart.inverse_dynamics(params, pose, rate, acc, bp, br, ba))
    assert F.shape == (N_MOVING, 6)
    err = max_rel_err(F, ref)
    print(f"moving base: max relative error {err:.2e}")
    assert err < RTOL


def test_moving_base_single_state(stewart, params, moving_case):
    pose, rate, acc, bp, br, ba, ref = moving_case
    for k in (0, 3, 11):
        F = np.asarray(stewart.inverse_dynamics(params, pose[k], rate[k], acc[k],
                                                bp[k], br[k], ba[k]))
        assert F.shape == (6,)
        assert max_rel_err(F, ref[k]) < RTOL


def test_moving_base_paper_scenario_shape(stewart, params):
    """Base at the world origin, elevation/azimuth rotation only (the paper's
    moving-base scenario kind), batch of platform states with one base state
    broadcast by the caller."""
    rng = np.random.default_rng(3)
    pose, rate, acc = platform_states(rng, 30)
    bp = np.tile([0.0, 0.0, 0.0, np.deg2rad(30.0), 0.0, np.deg2rad(20.0)], (30, 1))
    br = np.tile([0.0, 0.0, 0.0, 0.2, 0.0, 0.15], (30, 1))
    ba = np.tile([0.0, 0.0, 0.0, -0.1, 0.0, 0.05], (30, 1))
    ref = ne.inverse_dynamics(pose, rate, acc, bp, br, ba)
    F = np.asarray(stewart.inverse_dynamics(params, pose, rate, acc, bp, br, ba))
    assert max_rel_err(F, ref) < RTOL


def test_base_translation_acceleration_is_gravity_change(stewart, params, fixed_case):
    """A purely translating base with acceleration a_z is the fixed base with
    gravity g + a_z (plant against itself, and against the reference)."""
    pose, rate, acc, _ = fixed_case
    n = 20
    az = 2.5
    ba = np.tile([0.0, 0.0, az, 0.0, 0.0, 0.0], (n, 1))
    bv = np.tile([1.0, -2.0, 3.0, 0.0, 0.0, 0.0], (n, 1))
    F_move = np.asarray(stewart.inverse_dynamics(params, pose[:n], rate[:n], acc[:n],
                                                 np.zeros((n, 6)), bv, ba))
    heavy = dataclasses.replace(params, gravity=params.gravity + az)
    F_heavy = np.asarray(stewart.inverse_dynamics(heavy, pose[:n], rate[:n], acc[:n]))
    assert max_rel_err(F_move, F_heavy) < RTOL
    ref = ne.inverse_dynamics(pose[:n], rate[:n], acc[:n],
                              gravity_w=[0.0, 0.0, -(9.8 + az)])
    assert max_rel_err(F_heavy, ref) < RTOL


def test_forward_dynamics_inverts_reference(stewart, params, fixed_case, moving_case):
    """forward_dynamics(reference forces) returns the prescribed pose_acc."""
    pose, rate, acc, ref = fixed_case
    n = 40
    qdd = np.asarray(stewart.forward_dynamics(params, pose[:n], rate[:n], ref[:n]))
    assert qdd.shape == (n, 6)
    np.testing.assert_allclose(qdd, acc[:n], rtol=0, atol=1e-7 * np.abs(acc).max())
    pose, rate, acc, bp, br, ba, ref = moving_case
    qdd = np.asarray(stewart.forward_dynamics(params, pose[:n], rate[:n], ref[:n],
                                              bp[:n], br[:n], ba[:n]))
    np.testing.assert_allclose(qdd, acc[:n], rtol=0, atol=1e-7 * np.abs(acc).max())


@pytest.mark.parametrize("n", [6, 7])
def test_single_pose_broadcast_against_base_batch(stewart, params, moving_case, n):
    """One platform state held while the base runs through n states: the leading
    dimensions of pose and base_* broadcast. n = 6 matters: a leg axis (length 6)
    must not be confused with a batch axis of length 6."""
    pose, rate, acc, bp, br, ba, _ = moving_case
    F = np.asarray(stewart.inverse_dynamics(params, pose[0], rate[0], acc[0],
                                            bp[:n], br[:n], ba[:n]))
    assert F.shape == (n, 6)
    tile = lambda x: np.tile(x, (n, 1))
    ref = ne.inverse_dynamics(tile(pose[0]), tile(rate[0]), tile(acc[0]), bp[:n], br[:n], ba[:n])
    assert max_rel_err(F, ref) < RTOL
