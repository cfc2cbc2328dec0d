"""The FMUs under fmpy: validation, agreement with the plant called directly, state
save/restore, several instances in one process, outputs in initialization mode, and
failure through FMI status."""
import re

import numpy as np
import pytest
from fmpy import read_model_description, simulate_fmu
from fmpy.validation import validate_fmu

from fmu_src.catalogue import SCRIPTS
from fmu_src.hexapod_plant_fmu import STROKE_RANGE
from fmu_src.operating_point import STATIC_LEG_FORCES
from plant.hexapod.model import HOME_POSE, StewartParams, inverse_dynamics
from plant.hexapod.ode import HexapodODE
from plant.telescope import model as telescope
from scenarios.cosim.fmi import FmuError, Instance, RealPort
from tests.fmu_helpers import INIT_PARAMETERS, OPENED, open_fmu, output_starts

PARAMS = StewartParams.paper()
STATIC = inverse_dynamics(PARAMS, HOME_POSE, np.zeros(6), np.zeros(6))


def vec(instance, name, n=6):
    return RealPort(instance, [f"{name}[{i + 1}]" for i in range(n)]).read().copy()


def set_vec(instance, name, values):
    RealPort(instance, [f"{name}[{i + 1}]" for i in range(len(values))]).write(values)


def test_every_fmu_validates_and_has_units(fmus):
    for path in fmus.values():
        assert validate_fmu(str(path)) == []
        md = read_model_description(path)
        reals = [v for v in md.modelVariables if v.type == "Real"]
        assert all(v.description for v in md.modelVariables)
        assert all(v.unit for v in reals), [v.name for v in reals if not v.unit]


def test_plant_fmu_matches_the_plant_called_directly(fmus):
    """simulate_fmu with a force step against HexapodODE stepped by hand: same numbers."""
    forces = STATIC + np.array([300.0, -200.0, 100.0, 0.0, 50.0, -400.0])
    base = np.array([0.0, 0.0, 0.0, 0.3, 0.0, 0.2])
    start = {f"leg_force[{i + 1}]": forces[i] for i in range(6)}
    start.update({f"base_pose[{i + 1}]": base[i] for i in range(6)})
    result = simulate_fmu(fmus["hexapod_plant_fmu"], stop_time=0.2, output_interval=1e-3,
                          start_values=start, output=[f"pose[{i + 1}]" for i in range(6)])
    ode = HexapodODE(PARAMS)
    x = np.r_[HOME_POSE, np.zeros(6)]
    for k in range(200):
        ode.set_inputs(k * 1e-3, forces, base)
        ode.advance(x, 1e-3)
    fmu_pose = np.array(list(result[-1])[1:])
    np.testing.assert_allclose(fmu_pose, x[:6], rtol=0, atol=1e-12)
    assert np.abs(fmu_pose - HOME_POSE).max() > 1e-5   # it did move


def test_state_save_restore_replays_bit_identically(fmus):
    plant = open_fmu(fmus["hexapod_plant_fmu"], moving_base=0)
    set_vec(plant, "leg_force", STATIC + 500.0)
    for k in range(20):
        plant.do_step(k * 1e-3, 1e-3)
    saved = plant.fmu.getFMUState()
    first = []
    for k in range(20, 40):
        plant.do_step(k * 1e-3, 1e-3)
        first.append(vec(plant, "pose"))
    plant.fmu.setFMUState(saved)
    for k in range(20, 40):
        plant.do_step(k * 1e-3, 1e-3)
        np.testing.assert_array_equal(vec(plant, "pose"), first[k - 20])
    plant.fmu.freeFMUState(saved)


def test_several_fmus_and_two_instances_in_one_process(fmus):
    a = open_fmu(fmus["hexapod_plant_fmu"], "a", moving_base=0)
    b = open_fmu(fmus["hexapod_plant_fmu"], "b", moving_base=0)
    source = open_fmu(fmus["telescope_fmu"], "source")
    set_vec(a, "leg_force", STATIC + 1000.0)
    set_vec(b, "leg_force", STATIC)
    for k in range(10):
        for s in (a, b, source):
            s.do_step(k * 1e-3, 1e-3)
    assert np.abs(vec(a, "pose") - HOME_POSE).max() > 1e-6       # pushed
    np.testing.assert_allclose(vec(b, "pose"), HOME_POSE, atol=1e-9)  # held at rest
    assert vec(source, "axis", 2)[1] > np.radians(29.0)


def test_telescope_fmu_matches_the_module(fmus):
    result = simulate_fmu(fmus["telescope_fmu"], stop_time=20.0, output_interval=0.5,
                          output=["base_rate[4]", "base_acc[6]", "reference_pose[3]"])
    params = telescope.TelescopeParams.tianma()
    axes = telescope.slew(params, (0.0, np.radians(30)), (np.radians(90), np.radians(60)), result["time"])
    _, rate, acc = telescope.base_motion(params, axes)
    ref, _, _ = telescope.reference_pose(params, axes)
    np.testing.assert_allclose(result["base_rate[4]"], rate[:, 3], atol=1e-15)
    np.testing.assert_allclose(result["base_acc[6]"], acc[:, 5], atol=1e-15)
    np.testing.assert_allclose(result["reference_pose[3]"], ref[:, 2], atol=1e-15)


def _failing_step(slave, forces, steps=100, h=1e-3):
    """Step until the FMU refuses; return the error. A failed FMU keeps refusing."""
    set_vec(slave, "leg_force", forces)
    with pytest.raises(FmuError) as first:
        for k in range(steps):
            slave.do_step(k * h, h)
    with pytest.raises(FmuError, match="refusing doStep"):
        slave.do_step(steps * h, h)
    return str(first.value)


@pytest.mark.parametrize("start, forces, h, message", [
    ({}, np.r_[np.nan, STATIC[1:]], 1e-3, "leg forces input contains NaN"),
    ({"stroke": 0.01}, STATIC + 4e4, 1e-3, r"StrokeError.*leg \d length"),
    ({"integrator": 1, "max_step": 0.05, "stroke": STROKE_RANGE[1]}, STATIC + 1e9, 0.05, "diverged|singular"),
], ids=["nan input", "leg past its stroke", "runaway platform inside the longest stroke"])
def test_failures_end_the_step_with_fmi_status_and_a_message(fmus, start, forces, h, message):
    slave = open_fmu(fmus["hexapod_plant_fmu"], moving_base=0, **start)
    error = _failing_step(slave, forces, h=h)
    assert "doStep" in error and "t = " in error
    assert re.search(message, error), error


def test_singular_initial_pose_is_refused(fmus):
    """At initialization (the shim in front of pythonfmu answers fmi2Error there; freeing the instance after is
    safe)."""
    singular = np.r_[HOME_POSE[:5], np.pi / 2]
    with pytest.raises(FmuError, match="exitInitializationMode") as error:
        open_fmu(fmus["hexapod_plant_fmu"], moving_base=0, stroke=STROKE_RANGE[1],
                 **{f"initial_pose[{i + 1}]": singular[i] for i in range(6)})
    assert re.search("(SingularConfigurationError|StrokeError) in initialization", str(error.value)), error.value


def test_controller_reports_saturation_in_its_log(fmus):
    controller = open_fmu(fmus["leg_controller_fmu"], force_limit=1000.0)
    set_vec(controller, "leg_length", PARAMS.home_lengths - 0.01)   # 10 mm short: saturates
    for k in range(3):
        controller.do_step(k * 1e-3, 1e-3)
    assert np.all(np.abs(vec(controller, "leg_force")) == 1000.0)
    warnings = [line for line in controller.log if "saturated" in line]
    assert len(warnings) == 1 and warnings[0].startswith("[WARNING]") and "legs 1, 2, 3, 4, 5, 6" in warnings[0]


def test_plant_fmu_integrators_agree_to_their_order(fmus):
    """The same force step through RK4, Radau (implicit, adaptive) and explicit Euler:
    RK4 and Radau agree far below Euler's first-order error."""
    forces = STATIC + np.array([300.0, -200.0, 100.0, 0.0, 50.0, -400.0])
    start = {f"leg_force[{i + 1}]": forces[i] for i in range(6)}
    poses = {}
    for index, name in enumerate(("rk4", "euler", "radau")):
        result = simulate_fmu(fmus["hexapod_plant_fmu"], stop_time=0.1, output_interval=1e-3,
                              start_values={**start, "moving_base": 0, "integrator": index},
                              output=[f"pose[{i + 1}]" for i in range(6)])
        poses[name] = np.array(list(result[-1])[1:])
    rk4_vs_radau = np.abs(poses["rk4"] - poses["radau"]).max()
    euler_vs_radau = np.abs(poses["euler"] - poses["radau"]).max()
    assert rk4_vs_radau < 1e-9 and euler_vs_radau > 1e3 * rk4_vs_radau, (rk4_vs_radau, euler_vs_radau)


def _in_initialization_mode(path, parameters, shift):
    """(outputs read in initialization mode after setting ``parameters`` and every Real
    input to its start value + shift * (1 + k % 5) (k its position), the same outputs
    read again after setting every input to start + 2 shift, the outputs right after
    fmi2ExitInitializationMode)."""
    inst = Instance(path, "init")
    OPENED.append(inst)
    inputs = [v for v in inst.md.modelVariables if v.causality == "input" and v.type == "Real"]
    outputs = [v for v in inst.md.modelVariables if v.causality == "output"]
    assert all(v.initial == "calculated" and v.start is None for v in outputs)   # fmu_src/slave.py to_xml
    outputs = [v.name for v in outputs]
    read = lambda: np.array([inst.get_real(n) for n in outputs])
    inst.call("setupExperiment", startTime=0.0)
    inst.call("enterInitializationMode")
    for name, value in parameters.items():
        inst.set(name, value)
    for k, v in enumerate(inputs):
        inst.set(v.name, float(v.start) + shift * (1 + k % 5))
    first = read()
    for v in inputs:
        inst.set(v.name, float(v.start) + 2 * shift)
    second = read()
    inst.call("exitInitializationMode")
    return first, second, read()


@pytest.mark.parametrize("script", SCRIPTS)
def test_outputs_read_in_initialization_mode_are_computed_as_the_native_fmus_compute_them(fmus, native, script):
    """An importer that propagates values during initialization (libcosim) reads the
    outputs between fmi2EnterInitializationMode and fmi2ExitInitializationMode: the
    pythonfmu FMU answers what the native FMU answers there (its own C layer,
    fmu_src/native/fmi2_layer.c), follows inputs set after a read, and ends
    initialization on the same outputs it gave."""
    parameters = INIT_PARAMETERS.get(script, {})
    python = _in_initialization_mode(fmus[script], parameters, 1e-3)
    theirs = _in_initialization_mode(native[script], parameters, 1e-3)
    for ours, native_values in zip(python, theirs):
        np.testing.assert_allclose(ours, native_values, rtol=1e-13, atol=1e-13)
    first, second, after_exit = python
    start = np.array(output_starts(fmus[script]))
    assert np.array_equal(second, after_exit)      # the last inputs set are the ones initialization used
    moved = first != start
    assert moved.any()   # computed, not the values before initialization
    worst = np.max(np.abs(python[0] - theirs[0]) / np.maximum(np.abs(theirs[0]), 1e-300))
    print(f"{script}: {len(first)} outputs in initialization mode, {np.sum(moved)} away from their "
          f"start values; python vs native: largest relative difference {worst:.3g}")


@pytest.mark.parametrize("implementation", ["python", "native"])
def test_an_earlier_initialization_mode_evaluation_leaves_no_state_behind(fmus, native, implementation):
    """The plant evaluated in initialization mode with an actuator bandwidth (the motor
    forces become states), then set back to none: the FMU state it ends initialization
    with is, byte for byte, the one of a plant initialized without the detour."""
    forces = inverse_dynamics(StewartParams.paper(), HOME_POSE, np.zeros(6), np.zeros(6))

    def initialize(inst, detour):
        inst.set("moving_base", 0)
        for k, f in enumerate(forces):
            inst.set(f"leg_force[{k + 1}]", f)
        if detour:
            inst.set("actuator_bandwidth", 50.0)
            assert inst.get_real("leg_force_actual[1]") == pytest.approx(forces[0])
            inst.set("actuator_bandwidth", 0.0)

    with_detour, without = _states_with_and_without_a_detour(
        (fmus if implementation == "python" else native)["hexapod_plant_fmu"], initialize)
    assert with_detour == without


def _states_with_and_without_a_detour(path, initialize, after_exit=lambda inst: None):
    """The serialized FMU states of two HexapodPlant instances of ``path``, each set up by
    ``initialize(inst, detour)`` in initialization mode, with the detour and without;
    ``after_exit(inst)`` runs on each after exitInitializationMode."""
    blobs = []
    for detour in (True, False):
        inst = Instance(path, f"detour{detour}")
        OPENED.append(inst)
        inst.call("setupExperiment", startTime=0.0)
        inst.call("enterInitializationMode")
        initialize(inst, detour)
        inst.call("exitInitializationMode")
        after_exit(inst)
        blobs.append(bytes(inst.fmu.serializeFMUstate(inst.fmu.getFMUstate())))
    return blobs


@pytest.mark.parametrize("implementation", ["python", "native"])
def test_an_initialization_mode_evaluation_leaves_the_inputs_as_they_were_set(fmus, native, implementation):
    """start_equilibrium writes the holding forces into the leg_force input at
    initialization; a read in initialization mode that evaluated it left them written
    (fuzz.c, HexapodPlant seed 2: a replay of the same sets without the read read the start
    forces). Evaluated with start_equilibrium 1 against a wind load (forces hundreds of N
    off the calm ones), then set back to 0: the input reads the calm start forces it was
    set to, before and after exit, and the FMU state is, byte for byte, the one of a plant
    initialized without the detour."""
    names = [f"leg_force[{k}]" for k in range(1, 7)]

    def initialize(inst, detour):
        inst.set("platform_wrench[1]", 1219.0)
        if detour:
            inst.set("start_equilibrium", 1)
            held = inst.get_real("leg_force_actual[1]")
            assert abs(held - STATIC_LEG_FORCES[0]) > 100.0   # the evaluation held the wind
            assert [inst.get_real(n) for n in names] == list(STATIC_LEG_FORCES)
            inst.set("start_equilibrium", 0)

    def after_exit(inst):
        assert [inst.get_real(n) for n in names] == list(STATIC_LEG_FORCES)

    with_detour, without = _states_with_and_without_a_detour(
        (fmus if implementation == "python" else native)["hexapod_plant_fmu"], initialize, after_exit)
    assert with_detour == without
