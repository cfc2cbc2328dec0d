"""Mechanism 1 of Shen et al. 2024 against the paper's printed numbers, finite differences,
and an independent Lagrange model written here (closed-form circle intersections,
complex-step velocities, 8th-order finite differences of the mass matrix)."""
import numpy as np
import pytest

from plant.mechanism3t import model as m3t
from plant.mechanism3t.model import MM, Mechanism3TParams

P = Mechanism3TParams.paper()
RHO_REF = np.array(m3t.PAPER_REFERENCE_RHO_MM) * MM
FD8 = np.array([1 / 280, -4 / 105, 1 / 5, -4 / 5, 0, 4 / 5, -1 / 5, 4 / 105, -1 / 280])


def fd8(f, h):
    """8th-order central derivative at 0 of f(s)."""
    return sum(c * f(k * h) for c, k in zip(FD8, range(-4, 5)) if c) / h


def random_rho(rng, n, spread=0.03):
    """Actuator samples around the paper's configuration (all reachable and regular in mode +1)."""
    return RHO_REF + rng.uniform(-spread, spread, (n, 3))


# ------------------------------------------------------------------ paper numbers

def test_single_loop_paper_check():
    p = m3t.single_loop_forward(P, 110 * MM, -135.27 * MM, np.radians(120)) / MM
    np.testing.assert_allclose(p[:, :2], [[110, 16.73]] * 2, atol=1e-9)
    assert abs(p[0, 2] - 458.85) <= 0.005 and abs(p[1, 2] - 162.20) <= 0.005
    sol = m3t.single_loop_inverse(P, np.array([110, 16.73, 458.85]) * MM)
    np.testing.assert_allclose(sol[:, :2] / MM, [[110, -135.27]] * 2, atol=1e-9)
    assert np.allclose(sorted(np.degrees(sol[:, 2])), [113.29, 120.00], atol=0.005)


def test_mechanism1_paper_check():
    p = m3t.forward_position(P, RHO_REF) / MM
    assert p.shape == (1, 3)
    assert np.allclose(p[0], [94.25, 7.64, 408.2234], atol=5e-5, rtol=0)
    y_A3 = m3t.inverse_position(P, np.array([94.25, 7.64, 408.2234]) * MM)[:, 2] / MM
    assert abs(y_A3[0] + 47.68) <= 0.005 and abs(y_A3[1] - 62.9599) <= 5e-5
    np.testing.assert_allclose(m3t.inverse_position(P, p[0] * MM)[0], RHO_REF, atol=1e-12)


def test_table1_is_about_o_and_own_inertias_are_physical():
    """Each derived own inertia fits inside its link (0 < I <= m (L/2)^2); the raw Table 1 values do not."""
    lengths = dict(b1c1=P.l2, c1d1=P.l3, b2c2=P.l2, c2d2=P.l3, b3c3=P.l4, d3e3=P.l6)
    for name, axis in m3t.SWING_AXIS.items():
        bound = getattr(P, "m_" + name) * (lengths[name] / 2) ** 2
        assert 0 < getattr(P, "i_" + name) <= bound
        assert m3t.PAPER_INERTIA_AT_O[name][axis] * m3t.KG_MM2 > 5 * bound


# ------------------------------------------------------------------ positions

def test_forward_of_inverse_is_identity_for_every_branch():
    rng = np.random.default_rng(1)
    done = 0
    while done < 2000:
        p = rng.uniform([-0.1, -0.32, P.l1 + P.l5], [0.38, 0.45, P.l1 + P.l5 + P.l4])
        try:
            branches = m3t.inverse_position(P, p)
        except m3t.UnreachableError:
            continue
        for rho in branches:
            assert np.min(np.linalg.norm(m3t.forward_position(P, rho) - p, axis=1)) < 1e-10
        done += 1


def test_single_loop_round_trip():
    rng = np.random.default_rng(6)
    done = 0
    while done < 1000:
        p = rng.uniform([-0.1, -0.3, 0.0], [0.66, 0.44, 0.5])
        try:
            branches = m3t.single_loop_inverse(P, p)
        except m3t.UnreachableError:
            continue
        for x_A2, y_A1, theta in branches:
            assert np.min(np.linalg.norm(m3t.single_loop_forward(P, x_A2, y_A1, theta) - p, axis=1)) < 1e-10
        done += 1


def test_inverse_of_forward_contains_the_input():
    rng = np.random.default_rng(2)
    for rho in RHO_REF + rng.uniform(-0.15, 0.15, (1500, 3)):
        try:
            points = m3t.forward_position(P, rho)
        except m3t.UnreachableError:
            continue
        for p in points:
            assert np.min(np.linalg.norm(m3t.inverse_position(P, p) - rho, axis=1)) < 1e-10


def test_assembly_mode_picks_nearest_branch():
    rho = np.array([0.05, 0.0, 0.05])
    points = m3t.forward_position(P, rho)
    assert len(points) == 2
    for mode, p in zip((1, -1), points):
        assert m3t.assembly_mode(P, rho, p + 1e-4) == mode
        np.testing.assert_array_equal(m3t.forward_branch(P, rho, mode), p)


# ------------------------------------------------------------------ velocity, acceleration

def test_velocity_and_jacobians_against_finite_differences():
    rng = np.random.default_rng(3)
    rho = random_rho(rng, 200)
    rho_dot = rng.uniform(-1, 1, rho.shape)
    v = m3t.velocity(P, rho, rho_dot)
    v_fd = fd8(lambda s: m3t.forward_branch(P, rho + s * rho_dot), 1e-3)
    np.testing.assert_allclose(v, v_fd, rtol=0, atol=1e-9 * np.abs(v).max())
    j_o, j_i = m3t.jacobians(P, rho)
    np.testing.assert_allclose(np.linalg.solve(j_o, (j_i @ rho_dot[..., None]))[..., 0], v, atol=1e-12)


def test_acceleration_against_finite_differences():
    rng = np.random.default_rng(4)
    rho = random_rho(rng, 200)
    rho_dot, rho_ddot = rng.uniform(-1, 1, rho.shape), rng.uniform(-10, 10, rho.shape)
    a = m3t.acceleration(P, rho, rho_dot, rho_ddot)
    a_fd = fd8(lambda s: m3t.velocity(P, rho + s * rho_dot + s * s / 2 * rho_ddot, rho_dot + s * rho_ddot), 1e-4)
    np.testing.assert_allclose(a, a_fd, rtol=0, atol=1e-8 * np.abs(a).max())


# ------------------------------------------------------------------ independent Lagrange model

def _knee(base, target, l_in, l_out, knee):
    """Knee of a planar 2R limb by circle intersection; complex-step safe. base/target: (u, w) pairs;
    knee = -1 puts it on the clockwise side of base -> target."""
    du, dw = target[0] - base[0], target[1] - base[1]
    r2 = du * du + dw * dw
    along = (l_in ** 2 - l_out ** 2 + r2) / (2 * r2)
    across = -knee * np.sqrt(l_in ** 2 / r2 - along ** 2)
    return base[0] + along * du + across * dw, base[1] + along * dw - across * du


def _parts(rho):
    """(mass, own inertia, centre, link vector, swing axis) of every body, mode +1; complex-step safe."""
    x_A2, y_A1, y_A3 = rho
    x, y = x_A2, y_A1 + P.d
    c = (P.e - P.a - x + np.sqrt(P.l6 ** 2 - (y - y_A3) ** 2)) / P.l4
    z = P.l1 + P.l5 + P.l4 * np.sqrt(1 - c * c)
    b1, d1 = np.array([P.a, y_A1, P.l1]), np.array([x, y_A1, z])
    c1x, c1z = _knee((P.a, P.l1), (x, z), P.l2, P.l3, P.knee_1)
    c1 = np.array([c1x, y_A1, c1z])
    b2, d2 = np.array([x_A2, P.b, P.l1]), np.array([x, y + P.d, z])
    c2y, c2z = _knee((P.b, P.l1), (y + P.d, z), P.l2, P.l3, P.knee_2)
    c2 = np.array([x_A2, c2y, c2z])
    b3 = np.array([-P.a, y_A3, P.l1])
    c3 = b3 + P.l4 * np.array([-c, 0, np.sqrt(1 - c * c)])
    d3, e3 = c3 + [0, 0, P.l5], np.array([x - P.e, y, z])
    ex, ey, ez = np.eye(3)
    zero = np.zeros(3)
    return [(P.m_slider, 0, np.array([x_A2, P.b, 0]), zero, ez), (P.m_slider, 0, np.array([P.a, y_A1, 0]), zero, ez),
            (P.m_slider, 0, np.array([-P.a, y_A3, 0]), zero, ez),
            (P.m_b1c1, P.i_b1c1, (b1 + c1) / 2, c1 - b1, ey), (P.m_c1d1, P.i_c1d1, (c1 + d1) / 2, d1 - c1, ey),
            (P.m_b2c2, P.i_b2c2, (b2 + c2) / 2, c2 - b2, ex), (P.m_c2d2, P.i_c2d2, (c2 + d2) / 2, d2 - c2, ex),
            (P.m_b3c3, P.i_b3c3, (b3 + c3) / 2, c3 - b3, ey), (P.m_c3d3, 0, (c3 + d3) / 2, zero, ez),
            (P.m_d3e3, P.i_d3e3, (d3 + e3) / 2, e3 - d3, ez),
            (P.m_platform + P.m_payload, 0, np.array([x, y, z]), zero, ez)]


def _mass_matrix_and_gravity(rho, h=1e-30):
    """M(rho) = Hessian of T in rho_dot and G = dV/drho, from complex-step velocities."""
    base = _parts(rho.astype(complex))
    steps = [_parts(rho + 1j * h * e) for e in np.eye(3)]
    mass, gravity = np.zeros((3, 3)), np.zeros(3)
    for k, (m, inertia, centre, link, axis) in enumerate(base):
        jac = np.array([s[k][2].imag / h for s in steps]).T
        link_rates = [s[k][3].imag / h for s in steps]
        link = link.real
        jac_w = np.array([np.cross(link, r) @ axis for r in link_rates]) / max(link @ link, 1e-300)
        mass += m * jac.T @ jac + inertia * np.outer(jac_w, jac_w)
        gravity += m * P.g * jac[2]
    return mass, gravity


def lagrange_forces(rho, rho_dot, rho_ddot, h=5e-4):
    """d/dt dT/drho_dot - dT/drho + dV/drho with T = rho_dot^T M rho_dot / 2."""
    mass, gravity = _mass_matrix_and_gravity(rho)
    d_mass = [fd8(lambda s: _mass_matrix_and_gravity(rho + s * e)[0], h) for e in np.eye(3)]
    m_dot = sum(rd * dm for rd, dm in zip(rho_dot, d_mass))
    return mass @ rho_ddot + m_dot @ rho_dot - 0.5 * np.array([rho_dot @ dm @ rho_dot for dm in d_mass]) + gravity


def test_independent_model_matches_plant_geometry():
    """Same assembly: the plant's energy at rest is the independent model's potential."""
    potential = sum(m * P.g * c[2].real for m, _, c, _, _ in _parts(RHO_REF.astype(complex)))
    assert np.isclose(m3t.energy(P, RHO_REF, np.zeros(3))[1], potential, rtol=1e-14)


def test_slider_forces_match_lagrange():
    rng = np.random.default_rng(5)
    rho = random_rho(rng, 12)
    rho_dot, rho_ddot = rng.uniform(-1, 1, rho.shape), rng.uniform(-10, 10, rho.shape)
    forces = m3t.slider_forces(P, rho, rho_dot, rho_ddot)
    for f, r, rd, rdd in zip(forces, rho, rho_dot, rho_ddot):
        truth = lagrange_forces(r, rd, rdd)
        assert np.max(np.abs(f - truth)) <= 1e-8 * np.max(np.abs(truth))


def test_power_balance_along_trajectory():
    amplitude, omega, phase = np.array([0.02, 0.03, 0.025]), 3.0, np.array([0.0, 1.0, 2.0])
    t = np.linspace(0, 2, 41)[:, None]

    def rho(t):
        return RHO_REF + amplitude * np.sin(omega * t + phase)

    def rho_dot(t):
        return amplitude * omega * np.cos(omega * t + phase)

    power = np.sum(m3t.slider_forces(P, rho(t), rho_dot(t), -omega ** 2 * (rho(t) - RHO_REF)) * rho_dot(t), axis=-1)
    e_dot = fd8(lambda s: sum(m3t.energy(P, rho(t + s), rho_dot(t + s))), 1e-3)
    assert np.max(np.abs(power - e_dot)) <= 1e-8 * np.max(np.abs(power))


def test_paper_example_trajectory_and_forces():
    history = m3t.paper_example(P)
    s = 0.010 * np.sin(0.5 * history.t)[:, None]
    np.testing.assert_allclose(history.rho, RHO_REF + s, atol=1e-15)
    for k in (0, 70, 150, 333):
        truth = lagrange_forces(history.rho[k], 0.005 * np.cos(0.5 * history.t[k]) * np.ones(3),
                                -0.25 * s[k] * np.ones(3))
        assert np.max(np.abs(history.forces[k] - truth)) <= 1e-8 * np.max(np.abs(truth))
    assert history.peak == np.abs(history.forces).max() and history.peak_slider == "x_A2"


# ------------------------------------------------------------------ singularities, workspace

def test_singularity_classification():
    assert m3t.singularity(P, RHO_REF).kind == "regular"
    w_zero = np.array([0.1, -P.d, -P.l6])  # |y_A1 + d - y_A3| = l6: E3 and C3 share x
    report = m3t.singularity(P, w_zero)
    assert report.kind == "output" and report.theta_margin < 1e-12 and abs(report.det_jo) < 1e-12
    v_zero = np.array([0.05, -P.d, 0.0])  # y = y_A3: D3E3 along x, the two eq. 12 branches merge
    assert m3t.singularity(P, v_zero).kind == "input"
    assert abs(m3t.velocity(P, v_zero, [0, 0, 1.0])[2]) < 1e-15  # y_A3 cannot move the platform
    near = m3t.singularity(P, np.array([0.1, -P.d, -P.l6 + 1e-4]))
    assert near.kind == "regular" and 0 < near.theta_margin < 0.1


def test_workspace_points_are_reachable_within_ranges():
    ws = m3t.workspace(P, step=0.02)
    paper = m3t.workspace(P, step=0.02, passive_limbs=False)
    assert 0 < ws.volume < paper.volume
    lo, hi = np.array(P.rho_min), np.array(P.rho_max)
    for p in ws.points[::25]:
        rho = m3t.inverse_position(P, p)
        assert np.any(np.all((rho >= lo) & (rho <= hi), axis=1))


# ------------------------------------------------------------------ bad input

@pytest.mark.parametrize("rho, condition", [
    ([0.0, 0.0, 0.4], "eq. 10-11"),
    ([0.5, 0.0, 0.152], "eq. 11"),
    ([-0.3, -0.152, 0.0], "limb I"),
    ([0.05, 0.6, 0.752], "limb II"),
])
def test_unreachable_input_names_the_condition(rho, condition):
    with pytest.raises(m3t.UnreachableError, match=condition):
        m3t.forward_position(P, rho)


def test_unreachable_point_names_the_condition():
    with pytest.raises(m3t.UnreachableError, match="eq. 12: arcsin"):
        m3t.inverse_position(P, [0.1, 0.0, 0.2])
    with pytest.raises(m3t.UnreachableError, match="eq. 12: l6"):
        m3t.inverse_position(P, [0.5, 0.0, 0.3])
    with pytest.raises(m3t.UnreachableError, match="eq. 8"):
        m3t.single_loop_inverse(P, [-0.5, 0.0, 0.3])
    with pytest.raises(m3t.UnreachableError, match="eq. 7"):
        m3t.single_loop_forward(P, -0.5, 0.0, 0.0)


def test_singular_configuration_raises():
    w_zero = np.array([0.1, -P.d, -P.l6])
    for call in (lambda: m3t.velocity(P, w_zero, np.ones(3)),
                 lambda: m3t.slider_forces(P, w_zero, np.zeros(3), np.zeros(3))):
        with pytest.raises(m3t.SingularConfigurationError, match="E3 and C3 share x"):
            call()


def test_bad_input_raises():
    with pytest.raises(m3t.InvalidInputError):
        m3t.forward_position(P, [np.nan, 0, 0])
    with pytest.raises(m3t.InvalidInputError):
        m3t.inverse_position(P, [0, np.inf, 0.3])
    with pytest.raises(m3t.InvalidInputError):
        m3t.slider_forces(P, RHO_REF, [0, np.nan, 0], np.zeros(3))
    with pytest.raises(m3t.InvalidInputError):
        m3t.single_loop_forward(P, 0.1, 0.0, np.nan)
    with pytest.raises(m3t.InvalidInputError, match="shape"):
        m3t.forward_position(P, [0.1, 0.0])
    with pytest.raises(m3t.InvalidInputError, match="mode"):
        m3t.velocity(P, RHO_REF, np.ones(3), mode=0)


# ------------------------------------------------------------------ compiled single-state kernel

def _outcome(call):
    """('ok', value) or (error type, message) of a call, to compare two implementations."""
    try:
        return "ok", call()
    except m3t.InvalidInputError as error:   # before PlantError's other subclasses: none overlap
        return type(error), str(error)
    except (m3t.UnreachableError, m3t.SingularConfigurationError) as error:
        return type(error), str(error)


def test_compiled_kernel_equals_the_numpy_model():
    """plant.mechanism3t.kernel (one state, compiled) against the batched numpy reference:
    O', M, bias, slider_forces and forward_dynamics to 1e-12 relative on random reachable
    states of both assembly modes, and the same error (type and message) elsewhere."""
    from plant.mechanism3t import kernel
    rng = np.random.default_rng(11)
    compared = {1: 0, -1: 0}
    inverse = []   # every eq. 12 branch of random O' (both assembly modes)
    while len(inverse) < 600:
        p = rng.uniform([-0.1, -0.32, P.l1 + P.l5], [0.38, 0.45, P.l1 + P.l5 + P.l4])
        try:
            inverse.extend(m3t.inverse_position(P, p))
        except m3t.UnreachableError:
            pass
    rho_all = np.r_[RHO_REF + rng.uniform(-0.03, 0.03, (200, 3)), np.array(inverse),
                    rng.uniform([-0.3, -0.5, -0.5], [0.4, 0.5, 0.5], (300, 3))]
    for rho in rho_all:
        rho_dot, rho_ddot, forces = rng.normal(0, 0.3, 3), rng.normal(0, 3.0, 3), rng.normal(0, 100.0, 3)
        for mode in (1, -1):
            ref = _outcome(lambda: (m3t.forward_branch(P, rho, mode), *m3t.dynamics_terms(P, rho, rho_dot, mode)))
            got = _outcome(lambda: kernel.dynamics_terms(P, rho, rho_dot, mode))
            assert ref[0] == got[0] and (ref[0] == "ok" or ref[1] == got[1]), (rho, mode, ref, got)
            if ref[0] != "ok":
                # forward_branch alone raises only the unreachable conditions; every call agrees
                for numpy_call, compiled_call in (
                        (m3t.slider_forces, kernel.slider_forces), (m3t.forward_dynamics, kernel.forward_dynamics)):
                    args = (rho, rho_dot, rho_ddot if numpy_call is m3t.slider_forces else forces)
                    a = _outcome(lambda: numpy_call(P, *args, mode))
                    b = _outcome(lambda: compiled_call(P, *args, mode))
                    assert a[0] == b[0] and a[1] == b[1], (rho, mode, a, b)
                continue
            (p, mass, bias), (mass_k, bias_k, p_k) = ref[1], got[1]
            compared[mode] += 1
            np.testing.assert_allclose(p_k, p, rtol=1e-15, atol=0)
            np.testing.assert_allclose(mass_k, mass, rtol=0, atol=1e-12 * np.abs(mass).max())
            np.testing.assert_allclose(bias_k, bias, rtol=0, atol=1e-12 * np.abs(bias).max())
            f = m3t.slider_forces(P, rho, rho_dot, rho_ddot, mode)
            np.testing.assert_allclose(kernel.slider_forces(P, rho, rho_dot, rho_ddot, mode), f,
                                       rtol=0, atol=1e-12 * np.abs(f).max())
            # the solve: 1e-12 relative unless M is ill-conditioned (near a singularity), where
            # any two solvers differ by ~cond(M) eps; its residual is small in any case
            a = m3t.forward_dynamics(P, rho, rho_dot, forces, mode)
            a_k = kernel.forward_dynamics(P, rho, rho_dot, forces, mode)
            rel = max(1e-12, 10 * np.finfo(float).eps * np.linalg.cond(mass))
            np.testing.assert_allclose(a_k, a, rtol=0, atol=rel * np.abs(a).max())
            np.testing.assert_allclose(mass @ a_k + bias, forces, rtol=0,
                                       atol=1e-12 * (np.abs(mass).max() * np.abs(a_k).max() + np.abs(bias).max()))
            np.testing.assert_allclose(kernel.forward_branch(P, rho, mode), p, rtol=1e-15, atol=0)
    assert compared[1] >= 300 and compared[-1] >= 200, compared


def test_compiled_kernel_raises_the_named_errors():
    from plant.mechanism3t import kernel
    cases = [np.array(rho) for rho in ([0.0, 0.0, 0.4], [0.5, 0.0, 0.152], [-0.3, -0.152, 0.0], [0.05, 0.6, 0.752],
                                       [0.1, -P.d, -P.l6])]
    # next to sin theta = 0 (theta -> 0 at x_A2 = e - a + l6 - l4 = 0 with y_A3 = y_A1 + d)
    cases += [np.array([x, 0.0, P.d]) for x in np.linspace(-3e-16, 3e-16, 13)]
    kinds = set()
    for rho in cases:
        for mode in (1, -1):
            for numpy_call, compiled_call, extra in (
                    (m3t.slider_forces, kernel.slider_forces, np.zeros(3)),
                    (m3t.forward_dynamics, kernel.forward_dynamics, np.zeros(3)),
                    (lambda P_, r, rd, e, m: m3t.forward_branch(P_, r, m),
                     lambda P_, r, rd, e, m: kernel.forward_branch(P_, r, m), None)):
                a = _outcome(lambda: numpy_call(P, rho, np.zeros(3), extra, mode))
                b = _outcome(lambda: compiled_call(P, rho, np.zeros(3), extra, mode))
                assert a[0] == b[0], (rho, mode, a, b)
                if a[0] == "ok":
                    np.testing.assert_allclose(b[1], a[1], rtol=1e-12, atol=1e-12)
                else:
                    assert a[1] == b[1]
                    kinds.add(a[1].split(":")[0][:20])
    assert len(kinds) >= 4, kinds   # D3E3, arccos, limb I, limb II, output singularities
    for bad in ([np.nan, 0, 0], np.zeros(3), np.zeros(3)), (RHO_REF, [0, np.inf, 0], np.zeros(3)), \
               (RHO_REF, np.zeros(3), [np.nan, 0, 0]):
        a, b = _outcome(lambda: m3t.slider_forces(P, *bad)), _outcome(lambda: kernel.slider_forces(P, *bad))
        assert a == b and a[0] is m3t.InvalidInputError, (a, b)
    a = _outcome(lambda: m3t.forward_dynamics(P, RHO_REF, np.zeros(3), [np.nan, 0, 0]))
    assert a == _outcome(lambda: kernel.forward_dynamics(P, RHO_REF, np.zeros(3), [np.nan, 0, 0]))
    with pytest.raises(m3t.InvalidInputError, match="mode"):
        kernel.slider_forces(P, RHO_REF, np.zeros(3), np.zeros(3), mode=0)
