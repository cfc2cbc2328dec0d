"""Hexapod plant: kinematics and Kane dynamics against independent truths
(finite differences, energy written from scratch, statics by virtual work, equivalences
of base motions). The Newton-Euler cross-check lives in test_stewart_truth.py."""
import numpy as np
import pytest

from plant.errors import InvalidInputError, SingularConfigurationError, UnreachablePoseError
from plant.hexapod import model as stewart
from plant.hexapod.model import HOME_POSE, S_BAND_POSE, StewartParams
from plant.rotations import rpy_matrix
from plant.trajectory import quintic

PARAMS = StewartParams.paper()
RNG = np.random.default_rng(2)


def random_states(n, rng=RNG):
    pose = HOME_POSE + rng.uniform(-1, 1, (n, 6)) * [0.05, 0.05, 0.05, 0.03, 0.03, 0.03]
    rate = rng.uniform(-1, 1, (n, 6)) * [0.1, 0.1, 0.1, 0.3, 0.3, 0.3]
    acc = rng.uniform(-1, 1, (n, 6)) * [1, 1, 1, 3, 3, 3]
    return pose, rate, acc


def random_base(n, rng=RNG):
    pose = rng.uniform(-1, 1, (n, 6)) * [30, 30, 30, 1.2, 1.2, 3.0]
    return pose, rng.uniform(-1, 1, (n, 6)) * 2.0, rng.uniform(-1, 1, (n, 6)) * 3.0


# ---------------------------------------------------------------------------- geometry
def test_paper_geometry_is_mirror_symmetric_and_home_lengths_equal():
    B, a = PARAMS.base_joints, PARAMS.platform_joints
    mirror = np.array([-1.0, 1.0, 1.0])
    for i, j in ((0, 1), (2, 5), (3, 4)):
        np.testing.assert_allclose(B[i] * mirror, B[j], atol=1e-12)
        np.testing.assert_allclose(a[i] * mirror, a[j], atol=1e-12)
    assert np.ptp(PARAMS.home_lengths) < 1e-12


def test_jacobian_matches_finite_differences_of_leg_lengths():
    pose, _, _ = random_states(20)
    Jp = stewart.pose_jacobian(PARAMS, pose)
    h = 1e-6
    for k in range(6):
        dp = np.zeros(6)
        dp[k] = h
        fd = (stewart.inverse_kinematics(PARAMS, pose + dp)
              - stewart.inverse_kinematics(PARAMS, pose - dp)) / (2 * h)
        np.testing.assert_allclose(Jp[..., k], fd, atol=1e-8)


def test_forward_kinematics_inverts_inverse_kinematics_batched():
    pose, _, _ = random_states(200)
    lengths = stewart.inverse_kinematics(PARAMS, pose)
    np.testing.assert_allclose(stewart.forward_kinematics(PARAMS, lengths), pose, atol=1e-10)


# ---------------------------------------------------------------------------- dynamics
@pytest.mark.parametrize("fidelity", stewart.FIDELITIES)
def test_forward_dynamics_inverts_inverse_dynamics(fidelity):
    pose, rate, acc = random_states(300)
    base = random_base(300)
    forces = stewart.inverse_dynamics(PARAMS, pose, rate, acc, *base, fidelity=fidelity)
    back = stewart.forward_dynamics(PARAMS, pose, rate, forces, *base, fidelity=fidelity)
    np.testing.assert_allclose(back, acc, atol=1e-9)


def _body_energy(params, pose, rate):
    """Kinetic + potential energy written from scratch, body by body (fixed base)."""
    R = rpy_matrix(pose[3:])
    h = 1e-7   # angular velocity from dR/dt: skew(w) = dR/dt R^T
    dR = (rpy_matrix(pose[3:] + h * rate[3:]) - rpy_matrix(pose[3:] - h * rate[3:])) / (2 * h)
    W = dR @ R.T
    w = np.array([W[2, 1], W[0, 2], W[1, 0]])
    Ip = R @ np.diag(params.platform_inertia) @ R.T
    g = params.gravity
    energy = 0.5 * params.platform_mass * rate[:3] @ rate[:3] + 0.5 * w @ Ip @ w \
        + params.platform_mass * g * pose[2]
    for Bi, ai in zip(params.base_joints, params.platform_joints):
        q, qd = pose[:3] + R @ ai, rate[:3] + np.cross(w, R @ ai)
        length = np.linalg.norm(q - Bi)
        s = (q - Bi) / length
        ld = s @ qd
        sd = (qd - ld * s) / length
        wl = np.cross(s, sd)
        c_pos, c_vel = Bi + params.cylinder_com * s, params.cylinder_com * sd
        r_pos, r_vel = Bi + (length - params.rod_com) * s, ld * s + (length - params.rod_com) * sd
        for m, inertia, pos, vel in ((params.cylinder_mass, params.cylinder_inertia, c_pos, c_vel),
                                     (params.rod_mass, params.rod_inertia, r_pos, r_vel)):
            I = inertia[0] * np.outer(s, s) + inertia[1] * (np.eye(3) - np.outer(s, s))
            energy += 0.5 * m * vel @ vel + 0.5 * wl @ I @ wl + m * g * pos[2]
    return energy


def test_power_balance_along_a_fixed_base_trajectory():
    T = 2.0
    t = np.linspace(0.2, 1.8, 9)
    h = 1e-4
    stencil = np.array([-2, -1, 1, 2]) * h
    weights = np.array([1, -8, 8, -1]) / (12 * h)
    target = S_BAND_POSE + [0.02, -0.03, 0.04, 0.02, -0.01, 0.03]
    pose, rate, acc = quintic(HOME_POSE, target, T, t)
    forces = stewart.inverse_dynamics(PARAMS, pose, rate, acc)
    power = np.sum(forces * (stewart.jacobian(PARAMS, pose)
                             @ stewart.twist_from_rates(pose, rate)[..., None])[..., 0], axis=-1)
    for k, tk in enumerate(t):
        p, r, _ = quintic(HOME_POSE, target, T, tk + stencil)
        dE = weights @ np.array([_body_energy(PARAMS, p[i], r[i]) for i in range(4)])
        assert power[k] == pytest.approx(dE, rel=1e-6, abs=1e-3)


def _potential(params, pose):
    return _body_energy(params, pose, np.zeros(6))


def test_static_equilibrium_by_virtual_work():
    pose, _, _ = random_states(5)
    h = 1e-6
    for p in pose:
        forces = stewart.inverse_dynamics(PARAMS, p, np.zeros(6), np.zeros(6))
        grad = np.array([(_potential(PARAMS, p + h * e) - _potential(PARAMS, p - h * e)) / (2 * h)
                         for e in np.eye(6)])
        # virtual work: sum F dl = dV  for any virtual pose change
        np.testing.assert_allclose(forces @ stewart.pose_jacobian(PARAMS, p), grad, rtol=1e-6, atol=1e-3)


def test_base_in_uniform_translation_changes_nothing():
    pose, rate, acc = random_states(50)
    base_pose = np.zeros((50, 6))
    base_pose[:, :3] = RNG.uniform(-40, 40, (50, 3))
    base_rate = np.zeros((50, 6))
    base_rate[:, :3] = RNG.uniform(-10, 10, (50, 3))
    fixed = stewart.inverse_dynamics(PARAMS, pose, rate, acc)
    moving = stewart.inverse_dynamics(PARAMS, pose, rate, acc, base_pose, base_rate, np.zeros(6))
    np.testing.assert_allclose(moving, fixed, rtol=1e-12, atol=1e-8)


def test_vertical_base_acceleration_equals_heavier_gravity():
    pose, rate, acc = random_states(50)
    base_acc = np.array([0, 0, 2.5, 0, 0, 0])
    moving = stewart.inverse_dynamics(PARAMS, pose, rate, acc, np.zeros(6), np.zeros(6), base_acc)
    heavier = StewartParams.paper(gravity=PARAMS.gravity + 2.5)
    np.testing.assert_allclose(moving, stewart.inverse_dynamics(heavier, pose, rate, acc), rtol=1e-12)


def test_fidelity_levels_drop_what_they_say():
    pose, rate, acc = random_states(40)
    base_pose, base_rate, base_acc = random_base(40)
    run = lambda fidelity, *base, params=PARAMS: stewart.inverse_dynamics(
        params, pose, rate, acc, *base, fidelity=fidelity)
    massless = StewartParams.paper(cylinder_mass=0.0, rod_mass=0.0, cylinder_inertia=np.zeros(3),
                                   rod_inertia=np.zeros(3))
    np.testing.assert_allclose(run("massless_legs", base_pose, base_rate, base_acc),
                               run("full", base_pose, base_rate, base_acc, params=massless), rtol=1e-10)
    np.testing.assert_allclose(run("base_gravity", base_pose, base_rate, base_acc),
                               run("full", base_pose, np.zeros(6), np.zeros(6)), rtol=1e-10)
    np.testing.assert_allclose(run("no_base", base_pose, base_rate, base_acc), run("full"), rtol=1e-12)
    assert np.abs(run("full", base_pose, base_rate, base_acc) - run("full")).max() > 1e3


def test_mass_matrix_is_symmetric_positive_and_gives_kinetic_energy():
    pose, rate, _ = random_states(10)
    terms = stewart.dynamics_terms(PARAMS, pose, rate)
    M = terms.mass
    np.testing.assert_allclose(M, np.swapaxes(M, -1, -2), atol=1e-9)
    assert np.all(np.linalg.eigvalsh(M) > 0)
    u = stewart.twist_from_rates(pose, rate)
    kinetic = 0.5 * np.einsum("ni,nij,nj->n", u, M, u)
    potential = np.array([_potential(PARAMS, p) for p in pose])
    total = np.array([_body_energy(PARAMS, p, r) for p, r in zip(pose, rate)])
    np.testing.assert_allclose(kinetic + potential, total, rtol=1e-9)


def test_batching_matches_single_calls():
    pose, rate, acc = random_states(7)
    base = random_base(7)
    batched = stewart.inverse_dynamics(PARAMS, pose.reshape(7, 1, 6), rate.reshape(7, 1, 6),
                                       acc.reshape(7, 1, 6), *(b.reshape(7, 1, 6) for b in base))
    assert batched.shape == (7, 1, 6)
    for k in range(7):
        single = stewart.inverse_dynamics(PARAMS, pose[k], rate[k], acc[k], *(b[k] for b in base))
        np.testing.assert_allclose(batched[k, 0], single, rtol=1e-13)


def _same(a, b):
    """Equal bit for bit, of the same type and shape (tuples compared field by field)."""
    if isinstance(a, tuple):
        assert type(a) is type(b) and len(a) == len(b)
        for x, y in zip(a, b):
            _same(x, y)
        return
    assert type(a) is type(b) and np.shape(a) == np.shape(b)
    np.testing.assert_array_equal(a, b)


def _lists(*args):
    """The arguments as nested lists: the general path (conversion, shape checks) is taken."""
    return [a.tolist() if isinstance(a, np.ndarray) else a for a in args]


BASE_KINDS = ("moving", "tilted only", "rate only", "fixed")


def _base(kind, b, k):
    """One state's base arguments of a kind: arrays, or 0 where the base motion is left out."""
    pose, rate, acc = (x[k] for x in b)
    return {"moving": (pose, rate, acc), "tilted only": (pose, 0, 0), "rate only": (0, rate, 0.0),
            "fixed": (0, 0, 0)}[kind]


@pytest.mark.parametrize("fidelity", stewart.FIDELITIES)
@pytest.mark.parametrize("kind", BASE_KINDS)
def test_single_state_calls_equal_the_batched_path_bit_for_bit(fidelity, kind):
    """A (6,) float64 call (the fast path) returns what the same state gives as a row of
    a batch and as lists (the general path), bit for bit and of the same types."""
    n = 5
    pose, rate, acc = random_states(n)
    base = random_base(n)
    forces = RNG.uniform(-8e3, 8e3, (n, 6))
    batch_base = [b if isinstance(one, np.ndarray) else 0 for b, one in zip(base, _base(kind, base, 0))]
    batched_id = stewart.inverse_dynamics_terms(PARAMS, pose, rate, acc, *batch_base, fidelity=fidelity)
    batched_fd = stewart.forward_dynamics(PARAMS, pose, rate, forces, *batch_base, fidelity=fidelity)
    for k in range(n):
        b = _base(kind, base, k)
        one = (pose[k], rate[k], acc[k], *b)
        forces_one = stewart.inverse_dynamics_terms(PARAMS, *one, fidelity=fidelity)
        _same(forces_one, stewart.inverse_dynamics_terms(PARAMS, *_lists(*one), fidelity=fidelity))
        assert isinstance(forces_one[1].det_ratio, np.float64)
        np.testing.assert_array_equal(forces_one[0], batched_id[0][k])
        for field, whole in zip(forces_one[1], batched_id[1]):
            np.testing.assert_array_equal(field, whole[k])
        _same(stewart.inverse_dynamics(PARAMS, *one, fidelity=fidelity), forces_one[0])
        fd = stewart.forward_dynamics(PARAMS, pose[k], rate[k], forces[k], *b, fidelity=fidelity)
        _same(fd, stewart.forward_dynamics(PARAMS, *_lists(pose[k], rate[k], forces[k], *b), fidelity=fidelity))
        np.testing.assert_array_equal(fd, batched_fd[k])
        for twist in (False, True):
            terms = stewart.dynamics_terms(PARAMS, pose[k], rate[k], *b, fidelity=fidelity, twist_speeds=twist)
            _same(terms, stewart.dynamics_terms(PARAMS, *_lists(pose[k], rate[k], *b), fidelity=fidelity,
                                                twist_speeds=twist))


def _outcome(call):
    try:
        return call()
    except (InvalidInputError, SingularConfigurationError) as err:
        return type(err), str(err)


@pytest.mark.parametrize("bad", [(0,), (1,), (2,), (3,), (4,), (5,), (1, 5), (0, 2, 3)])
def test_single_state_nan_and_inf_are_named_as_on_the_general_path(bad):
    """NaN or inf in any one argument, or several, names exactly those arguments, on the
    fast path as on the general one, for every public call."""
    pose, rate, acc = (x[0] for x in random_states(1))
    base = [x[0] for x in random_base(1)]
    args = [pose, rate, acc, *base]
    for i, k in enumerate(bad):
        args[k] = args[k].copy()
        args[k][(2 * i + k) % 6] = (np.nan, np.inf, -np.inf)[(i + k) % 3]
    for call, names in (
            (stewart.inverse_dynamics, ("pose", "pose_rate", "pose_acc")),
            (stewart.forward_dynamics, ("pose", "pose_rate", "forces")),
            (stewart.inverse_dynamics_terms, ("pose", "pose_rate", "pose_acc"))):
        expected = ", ".join((*names, "base_pose", "base_rate", "base_acc")[k] for k in sorted(bad))
        fast = _outcome(lambda: call(PARAMS, *args))
        assert fast == (InvalidInputError, f"{expected} contains NaN or inf")
        assert _outcome(lambda: call(PARAMS, *_lists(*args))) == fast
    if not set(bad) & {2}:   # dynamics_terms takes no third argument
        drop = [a for k, a in enumerate(args) if k != 2]
        names = ("pose", "twist", "base_pose", "base_rate", "base_acc")
        expected = ", ".join(names[k - (k > 2)] for k in sorted(bad))
        fast = _outcome(lambda: stewart.dynamics_terms(PARAMS, *drop, twist_speeds=True))
        assert fast == (InvalidInputError, f"{expected} contains NaN or inf")
        assert _outcome(lambda: stewart.dynamics_terms(PARAMS, *_lists(*drop), twist_speeds=True)) == fast


def test_single_state_shape_and_singular_errors_equal_the_general_path():
    """A wrong shape, arrays that do not broadcast and a singular pose: the same errors
    and messages from (6,) float64 arrays as from lists and from a batch."""
    z = np.zeros(6)
    cases = [(SINGULAR_POSE, z, z), (HOME_POSE, np.zeros(5), z), (HOME_POSE, z, np.zeros((2, 6)), np.zeros((3, 6))),
             (np.stack([HOME_POSE, SINGULAR_POSE]), z, z)]
    for args in cases:
        for call in (stewart.inverse_dynamics, stewart.forward_dynamics, stewart.inverse_dynamics_terms):
            fast = _outcome(lambda: call(PARAMS, *args))
            assert isinstance(fast, tuple) and fast[0] in (InvalidInputError, SingularConfigurationError)
            assert _outcome(lambda: call(PARAMS, *_lists(*args))) == fast
    assert _outcome(lambda: stewart.inverse_dynamics(PARAMS, SINGULAR_POSE, z, z)) == _outcome(
        lambda: stewart.inverse_dynamics(PARAMS, SINGULAR_POSE[None], z, z))


def test_state_inverse_dynamics_equals_the_public_call_and_follows_refilled_arrays():
    """The controller's entry point keeps the pointers of arrays passed again: refilled
    in place they give the new state's results; strided views and lists give the same;
    all bit for bit equal to inverse_dynamics_terms."""
    n = 6
    pose, rate, acc = random_states(n)
    base = random_base(n)
    for fidelity in stewart.FIDELITIES:
        sid = stewart.StateInverseDynamics(PARAMS, fidelity)
        held = [np.empty(6) for _ in range(6)]
        strided = np.empty((6, 12))
        expected = [stewart.inverse_dynamics_terms(PARAMS, pose[k], rate[k], acc[k], *(b[k] for b in base),
                                                   fidelity=fidelity) for k in range(n)]
        for variant in ("held", "views", "strided", "lists"):
            for k, (forces, terms) in enumerate(expected):
                state = (pose[k], rate[k], acc[k], *(b[k] for b in base))
                for a, x in zip(held, state):   # the same six arrays every step, refilled
                    a[:] = x
                strided[:, ::2] = np.stack(state)
                args = {"held": held, "views": state, "strided": list(strided[:, ::2]), "lists": _lists(*state)}
                out = sid(*args[variant])
                np.testing.assert_array_equal(out[0][0], forces)
                np.testing.assert_array_equal(out[1][0], terms.leg_lengths)
                np.testing.assert_array_equal(out[2][0], terms.leg_rates)
    with pytest.raises(SingularConfigurationError, match="singular configuration"):
        sid(SINGULAR_POSE, *held[1:])
    with pytest.raises(InvalidInputError, match="pose_rate must have shape"):
        sid(HOME_POSE, np.zeros(5), *held[2:])


# ---------------------------------------------------------------------------- bad input
SINGULAR_POSE = np.r_[HOME_POSE[:5], np.pi / 2]   # platform turned 90 deg: legs coplanar pairs


@pytest.mark.parametrize("bad, message", [
    (np.full(6, np.nan), "NaN"), (np.r_[HOME_POSE[:5], np.inf], "NaN or inf"), (np.zeros(5), "shape"),
])
def test_bad_pose_is_named(bad, message):
    with pytest.raises(InvalidInputError, match=message):
        stewart.inverse_dynamics(PARAMS, bad, np.zeros(6), np.zeros(6))


def test_singular_pose_raises_in_dynamics_and_kinematics():
    with pytest.raises(SingularConfigurationError, match="singular"):
        stewart.inverse_dynamics(PARAMS, SINGULAR_POSE, np.zeros(6), np.zeros(6))
    with pytest.raises(SingularConfigurationError, match="singular"):
        stewart.forward_dynamics(PARAMS, SINGULAR_POSE, np.zeros(6), np.zeros(6))
    with pytest.raises(SingularConfigurationError):
        stewart.check_singular(PARAMS, stewart.jacobian(PARAMS, SINGULAR_POSE))


def test_unreachable_lengths_raise():
    with pytest.raises(UnreachablePoseError, match="did not converge|out of reach"):
        stewart.forward_kinematics(PARAMS, np.array([1.0, 1.0, 1.0, 10.0, 10.0, 10.0]))
    with pytest.raises(UnreachablePoseError, match="positive"):
        stewart.forward_kinematics(PARAMS, -np.ones(6))


def test_unknown_fidelity_and_stroke_are_named():
    with pytest.raises(InvalidInputError, match="fidelity"):
        stewart.inverse_dynamics(PARAMS, HOME_POSE, np.zeros(6), np.zeros(6), fidelity="fast")
    lengths = PARAMS.home_lengths.copy()
    lengths[3] += 0.2
    with pytest.raises(stewart.StrokeError, match="leg 4"):
        stewart.check_stroke(PARAMS, lengths)
