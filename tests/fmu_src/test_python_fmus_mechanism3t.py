"""The 3T mechanism FMUs (Mechanism3TPlant, SliderController): validation, the plant FMU
against the plant model integrated directly, the two FMUs in closed loop against the
paper example, the controller's default gains, and failures through FMI status. Also
the forward dynamics the plant FMU integrates, against slider_forces."""
import re

import control
import numpy as np
import pytest
from fmpy import read_model_description, simulate_fmu
from fmpy.validation import validate_fmu

from controller.design import _closed_loop_matrix, loop_margins, mode_loop
from controller.pid import PIDGains
from plant.errors import InvalidInputError
from plant.integrators import advance
from plant.mechanism3t import model as m3t
from scenarios.cosim.fmi import FmuError, RealPort
from tests.fmu_helpers import open_fmu

P = m3t.Mechanism3TParams.paper()
RHO_REF = np.array(m3t.PAPER_REFERENCE_RHO_MM) * m3t.MM
STATIC = m3t.slider_forces(P, RHO_REF, np.zeros(3), np.zeros(3))   # holds the paper configuration at rest
PLANT, CONTROLLER = "mechanism3t_plant_fmu", "slider_controller_fmu"


def names(variable):
    return [f"{variable}[{i + 1}]" for i in range(3)]


def vec(instance, variable):
    return RealPort(instance, names(variable)).read().copy()


def set_vec(instance, variable, values):
    RealPort(instance, names(variable)).write(values)


def linearised(rho=RHO_REF, step=1e-6):
    """Continuous StateSpace of the plant about rest at rho under its static forces:
    states (slider deviations, rates), inputs force deviations, outputs slider deviations."""
    forces = m3t.slider_forces(P, rho, np.zeros(3), np.zeros(3))
    x0 = np.r_[rho, np.zeros(3)]
    f = lambda x, u: np.r_[x[3:], m3t.forward_dynamics(P, x[:3], x[3:], forces + u)]
    A = np.column_stack([(f(x0 + step * e, 0) - f(x0 - step * e, 0)) / (2 * step) for e in np.eye(6)])
    B = np.column_stack([(f(x0, e) - f(x0, -e)) / 2 for e in np.eye(3)])
    return control.ss(A, B, np.eye(3, 6), 0)


# ------------------------------------------------------------------ plant additions

def test_forward_dynamics_inverts_slider_forces():
    rng = np.random.default_rng(3)
    rho = RHO_REF + rng.uniform(-0.03, 0.03, (40, 3))
    rho_dot, rho_ddot = rng.normal(0, 0.3, (40, 3)), rng.normal(0, 3.0, (40, 3))
    forces = m3t.slider_forces(P, rho, rho_dot, rho_ddot)
    mass, bias = m3t.dynamics_terms(P, rho, rho_dot)
    # M columns are slider_forces with unit accelerations minus the zero-acceleration forces
    columns = np.stack([m3t.slider_forces(P, rho, rho_dot, np.broadcast_to(e, rho.shape)) for e in np.eye(3)], -1)
    np.testing.assert_allclose(mass, columns - bias[..., None], rtol=0, atol=1e-10)
    np.testing.assert_allclose(bias, m3t.slider_forces(P, rho, rho_dot, np.zeros(3)), rtol=0, atol=1e-10)
    np.testing.assert_allclose(m3t.forward_dynamics(P, rho, rho_dot, forces), rho_ddot, rtol=0, atol=1e-10)
    np.testing.assert_allclose(mass, np.swapaxes(mass, -1, -2), atol=1e-12)
    assert np.linalg.eigvalsh(mass).min() > 10.0   # kg; the sliders alone weigh 4.53 kg
    np.testing.assert_allclose(m3t.mass_matrix(P, rho), mass, rtol=0, atol=1e-12)   # M does not depend on rates
    with pytest.raises(InvalidInputError, match="slider forces contains NaN"):
        m3t.forward_dynamics(P, RHO_REF, np.zeros(3), [np.nan, 0, 0])


def test_paper_motion_is_the_paper_example_motion():
    t = np.linspace(0, 10, 7)
    rho, rho_dot, rho_ddot = m3t.paper_motion(t)
    np.testing.assert_array_equal(rho, m3t.paper_example(t=t).rho)
    np.testing.assert_allclose(m3t.slider_forces(P, rho, rho_dot, rho_ddot), m3t.paper_example(t=t).forces, atol=1e-12)


# ------------------------------------------------------------------ FMUs

def test_both_fmus_validate_with_units_and_descriptions(fmus):
    for script in (PLANT, CONTROLLER):
        assert validate_fmu(str(fmus[script])) == []
        md = read_model_description(fmus[script])
        assert all(v.description for v in md.modelVariables)
        assert all(v.unit for v in md.modelVariables if v.type == "Real")


@pytest.mark.parametrize("integrator, method", [(0, "rk4"), (1, "euler")])
def test_plant_fmu_equals_direct_integration(fmus, integrator, method):
    """simulate_fmu with constant forces against plant.integrators.advance on forward_dynamics."""
    forces = STATIC + np.array([5.0, -3.0, 2.0])
    h, max_step, steps = 5e-3, 2.5e-3, 40
    start = {f"slider_force[{i + 1}]": forces[i] for i in range(3)}
    start.update(integrator=integrator, max_step=max_step)
    result = simulate_fmu(fmus[PLANT], stop_time=steps * h, output_interval=h, start_values=start,
                          output=names("slider_position") + names("slider_rate") + names("platform_position"))
    f = lambda t, x: np.r_[x[3:], m3t.forward_dynamics(P, x[:3], x[3:], forces)]
    x = np.r_[RHO_REF, np.zeros(3)]
    for k in range(steps):
        x = advance(method, f, k * h, x, h, max_step)
    last = np.array(list(result[-1])[1:])
    np.testing.assert_allclose(last[:6], x, rtol=0, atol=1e-12)
    np.testing.assert_allclose(last[6:], m3t.forward_branch(P, x[:3]), rtol=0, atol=1e-12)
    assert np.abs(x[:3] - RHO_REF).max() > 1e-3   # it did move (mm)


def test_compiled_advance_equals_plant_integrators():
    """The plant FMU's compiled RK4 / Euler (plant.mechanism3t.kernel.advance_fixed) against
    plant.integrators.advance on the same compiled right-hand side, and on the numpy model."""
    from plant.mechanism3t import kernel
    packed, forces = kernel.pack(P), STATIC + np.array([40.0, -30.0, 20.0])
    rhs = lambda t, x: kernel.rhs_kernel(packed, x, forces, 1)[1]
    numpy_rhs = lambda t, x: np.r_[x[3:], m3t.forward_dynamics(P, x[:3], x[3:], forces)]
    x0 = np.r_[RHO_REF, 0.01, -0.02, 0.03]
    for method in ("rk4", "euler"):
        for h, max_step in ((5e-3, 5e-3), (5e-3, 2e-3), (1e-2, 1e-3)):
            n = int(np.ceil(h / max_step - 1e-9))
            status, x = kernel.advance_fixed(packed, x0, forces, 1, method == "rk4", n, h / n)
            assert status == kernel.OK
            np.testing.assert_allclose(x, advance(method, rhs, 0.0, x0, h, max_step), rtol=0, atol=1e-15)
            np.testing.assert_allclose(x, advance(method, numpy_rhs, 0.0, x0, h, max_step), rtol=0, atol=1e-14)
    status, x = kernel.advance_fixed(packed, np.r_[RHO_REF, 0.0, 0.0, 0.0], np.array([np.nan, 0, 0]), 1, True, 1, 1e-3)
    assert status == kernel.BAD_FORCE


def test_plant_fmu_radau_equals_direct_integration(fmus):
    """integrator 2 (Radau through plant.integrators.advance on the compiled RHS) against
    Radau on the numpy model."""
    forces = STATIC + np.array([5.0, -3.0, 2.0])
    h, max_step, steps = 5e-3, 5e-3, 20
    start = {f"slider_force[{i + 1}]": forces[i] for i in range(3)}
    start.update(integrator=2, max_step=max_step)
    result = simulate_fmu(fmus[PLANT], stop_time=steps * h, output_interval=h, start_values=start,
                          output=names("slider_position") + names("slider_rate"))
    f = lambda t, x: np.r_[x[3:], m3t.forward_dynamics(P, x[:3], x[3:], forces)]
    x = np.r_[RHO_REF, np.zeros(3)]
    for k in range(steps):
        x = advance("radau", f, k * h, x, h, max_step)
    np.testing.assert_allclose(np.array(list(result[-1])[1:]), x, rtol=0, atol=1e-12)


def test_plant_state_save_restore_replays_bit_identically(fmus):
    plant = open_fmu(fmus[PLANT])
    set_vec(plant, "slider_force", STATIC + 20.0)
    for k in range(5):
        plant.do_step(k * 5e-3, 5e-3)
    saved = plant.fmu.getFMUState()
    first = []
    for k in range(5, 10):
        plant.do_step(k * 5e-3, 5e-3)
        first.append(vec(plant, "slider_position"))
    plant.fmu.setFMUState(saved)
    for k in range(5, 10):
        plant.do_step(k * 5e-3, 5e-3)
        np.testing.assert_array_equal(vec(plant, "slider_position"), first[k - 5])
    plant.fmu.freeFMUState(saved)
    plant.terminate()


def default_gains(path):
    """The controller's default gains, as its model description ships them."""
    start = {v.name: float(v.start) for v in read_model_description(path).modelVariables if v.start is not None}
    return PIDGains(*(start[k] for k in ("kp", "ki", "kd", "force_limit")))


def test_default_gains_are_well_damped(fmus):
    """The docstring's design checks: modal margins of the sampled loop at h = 1 ms and the
    damping of every pole of the linearised MIMO loop (gravity, coupling, ZOH, one step delay)."""
    gains = default_gains(fmus[CONTROLLER])
    for mass in np.linalg.eigvalsh(m3t.mass_matrix(P, RHO_REF)):
        _, phase_margin, gain_margin, _ = loop_margins(mode_loop(mass, gains, 1e-3))
        assert phase_margin >= 59 and 20 * np.log10(gain_margin) >= 20
    plant = linearised()
    for h, zeta_min in ((1e-3, 0.75), (2e-3, 0.75), (5e-3, 0.65)):
        z = np.linalg.eigvals(_closed_loop_matrix(plant, gains, h))
        s = np.log(z[np.abs(z) > 1e-9].astype(complex)) / h
        assert (-s.real / np.abs(s)).min() >= zeta_min, h


def test_closed_loop_tracks_the_paper_motion_and_forces(fmus):
    """Plant and controller stepped by hand (Jacobi, h = 2 ms, 3 s), plant starting at rest.

    Tolerances: the reference starts at 5 mm/s (amplitude x omega) while the plant is at rest,
    so the loop has a transient of a fraction of a millimetre that the integral removes with
    its slowest pole (0.29 Hz); afterwards the only mismatch is timing: under Jacobi the
    forces computed at t act over [t + h, t + 2h), 1.5 h late on average, so the PID part of
    the force must make up about 1.5 h |dF/dt| of the paper curve (0.035 N at h = 2 ms);
    twice that is allowed, 0.04 % of the 173.5 N peak. The position error that drives it is
    that force over kp (~4 um)."""
    h, steps = 2e-3, 1500
    plant, ctrl = open_fmu(fmus[PLANT], "plant"), open_fmu(fmus[CONTROLLER], "controller")
    plant_out = RealPort(plant, names("slider_position") + names("slider_rate"))
    plant_in = RealPort(plant, names("slider_force"))
    ctrl_in = RealPort(ctrl, names("slider_position") + names("slider_rate"))
    ctrl_out = RealPort(ctrl, names("slider_force") + names("reference_position") + names("feedforward_force"))
    t = np.arange(steps) * h
    measured, commanded = np.zeros((steps, 6)), np.zeros((steps, 9))
    for k in range(steps):
        measured[k] = plant_out.read()
        plant_in.write(ctrl_out.read()[:3])
        ctrl_in.write(measured[k])
        plant.do_step(t[k], h)
        ctrl.do_step(t[k], h)
        commanded[k] = ctrl_out.read()   # computed from the inputs at t[k]
    for instance in (plant, ctrl):
        instance.terminate()

    paper = m3t.paper_example(t=t)
    reference = m3t.paper_motion(t)[0]
    np.testing.assert_allclose(commanded[:, 3:6], reference, rtol=0, atol=1e-15)
    np.testing.assert_allclose(commanded[:, 6:], paper.forces, rtol=0, atol=1e-9)   # feedforward = paper curve
    error = np.abs(measured[:, :3] - reference)
    settled = t >= 1.5
    assert error.max() < 0.25e-3                      # transient from rest: < 2.5 % of the 10 mm amplitude
    assert error[settled].max() < 5e-6                # m
    rate_of_force = np.abs(np.gradient(paper.forces, t, axis=0)).max()
    force_error = np.abs(commanded[:, :3] - paper.forces)
    assert force_error[settled].max() < 2 * 1.5 * h * rate_of_force
    assert force_error[0:25].max() > 10 * force_error[settled].max()   # it did approach


def test_controller_without_feedforward_is_pid_only(fmus):
    ctrl = open_fmu(fmus[CONTROLLER], feedforward=0)
    set_vec(ctrl, "slider_position", RHO_REF - 1e-3)
    ctrl.do_step(0.0, 1e-3)
    np.testing.assert_array_equal(vec(ctrl, "feedforward_force"), np.zeros(3))
    g = default_gains(fmus[CONTROLLER])   # e = 1 mm, de = amplitude omega = 5 mm/s, integral h e
    np.testing.assert_allclose(vec(ctrl, "slider_force"), g.kp * 1e-3 + g.ki * 1e-6 + g.kd * 5e-3, rtol=1e-12)
    ctrl.terminate()


def _failing_step(slave, steps, h):
    """Step until the FMU refuses; return the error. A failed FMU keeps refusing."""
    with pytest.raises(FmuError) as first:
        for k in range(steps):
            slave.do_step(k * h, h)
    with pytest.raises(FmuError, match="refusing doStep"):
        slave.do_step(steps * h, h)
    slave.terminate()
    return str(first.value)


@pytest.mark.parametrize("values, forces, message", [
    ({}, [np.nan, 0.0, 0.0], r"InvalidInputError at t=0 s: slider forces contains NaN"),
    ({}, STATIC + [0.0, 0.0, 500.0], r"(SingularConfigurationError|UnreachableError) at t=0\.\d+ s"),
], ids=["nan force", "pushed out of reach"])
def test_plant_failures_end_the_step_with_a_message(fmus, values, forces, message):
    plant = open_fmu(fmus[PLANT], **values)
    set_vec(plant, "slider_force", forces)
    error = _failing_step(plant, steps=100, h=5e-3)
    assert "doStep" in error and re.search(message, error), error


@pytest.mark.parametrize("values, message", [
    ({"initial_position[3]": 0.3}, r"UnreachableError in initialization: .*D3E3 too short"),
    ({"mode": -1}, r"UnreachableError in initialization: .*eq. 11: arccos argument"),
], ids=["unreachable start", "no assembly in mode -1"])
def test_plant_refuses_a_start_it_cannot_assemble(fmus, values, message):
    """At fmi2ExitInitializationMode (the shim in front of pythonfmu answers fmi2Error there; freeing after is safe)."""
    with pytest.raises(FmuError, match="failed in exitInitializationMode") as error:
        open_fmu(fmus[PLANT], **values)
    assert re.search(message, str(error.value)), error.value


def test_controller_refuses_nan_measurements(fmus):
    ctrl = open_fmu(fmus[CONTROLLER])
    set_vec(ctrl, "slider_rate", [0.0, np.inf, 0.0])
    error = _failing_step(ctrl, steps=1, h=1e-3)
    assert "measured slider position/rate input contains NaN or inf" in error, error
