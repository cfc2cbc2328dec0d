"""Bad parameters and inputs given to the FMUs (issue 10), each with exactly that input:
the declared ranges in the model description, the message at initialization naming
parameter, value and range, and what a host reads after a discarded step."""
import ctypes
import math
import re
import zipfile

import numpy as np
import pytest
from fmpy import read_model_description
from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import fmi2DoStepStatus, fmi2LastSuccessfulTime, fmi2Status

from fmu_src.catalogue import SCRIPTS
from plant.hexapod.model import HOME_POSE, StewartParams, inverse_dynamics
from scenarios.cosim.fmi import FmuError, Instance, RealPort
from tests.fmu_helpers import BAD_INIT, OPENED, open_fmu

STATIC = inverse_dynamics(StewartParams.paper(), HOME_POSE, np.zeros(6), np.zeros(6))
DISCARD, ERROR, FATAL = 2, 3, 4


def _parameters(path):
    return [v for v in read_model_description(path).modelVariables if v.causality == "parameter"]


@pytest.mark.parametrize("script", SCRIPTS)
def test_every_parameter_declares_a_range_that_holds_its_default(fmus, script):
    """FMI min/max on every scalar parameter (other tools read them), and the default
    inside; an enumeration's max is its last label's index, read back from its description."""
    for v in _parameters(fmus[script]):
        if v.type == "String":   # a path (the telescope's replay_table): no range to declare
            continue
        assert v.min is not None or v.max is not None, v.name
        start = float(v.start)
        assert (v.min is None or float(v.min) <= start) and (v.max is None or start <= float(v.max)), v.name
        labels = re.findall(r"(\d+) \w+", v.description.split(":", 1)[-1]) if v.type in ("Integer",
                                                                                         "Enumeration") else []
        if labels and v.name not in ("moving_base", "mode"):
            assert (int(v.min), int(v.max)) == (0, int(labels[-1])), (v.name, v.description)


def _refused_at_init(path, **values):
    """The FmuError of an instance initialised with ``values`` (it must fail there)."""
    with pytest.raises(FmuError, match="failed in exitInitializationMode") as error:
        open_fmu(path, **values)
    return str(error.value)


@pytest.mark.parametrize("script, name, value, text", [
    ("telescope_fmu", "target_elevation", math.radians(95.0),
     "target_elevation = 1.65806 rad (95 deg) is outside its valid range [0, 1.5708] rad ([0, 90] deg)"),
    ("telescope_fmu", "target_elevation", math.radians(1e300),
     "target_elevation = 1.74533e+298 rad (1e+300 deg) is outside its valid range [0, 1.5708] rad"),
    ("leg_controller_fmu", "force_limit", 0.0, "force_limit = 0 N is outside its valid range >= 1e-09 N"),
    ("leg_controller_fmu", "force_limit", -100.0, "force_limit = -100 N is outside its valid range >= 1e-09 N"),
    ("leg_controller_fmu", "kp", -1.0, "kp = -1 N/m is outside its valid range >= 0 N/m"),
    ("slider_controller_fmu", "kd", -5.0, "kd = -5 N.s/m is outside its valid range >= 0 N.s/m"),
    ("hexapod_plant_fmu", "max_step", 0.0, "max_step = 0 s is outside its valid range >= 1e-09 s"),
    ("mechanism3t_plant_fmu", "max_step", -1e-3, "max_step = -0.001 s is outside its valid range >= 1e-09 s"),
    ("hexapod_plant_fmu", "stroke", 1e-6, "stroke = 1e-06 m is outside its valid range [0.001, 3.11993] m"),
    ("hexapod_plant_fmu", "fidelity", 4, "fidelity = 4 is outside its valid range [0, 3]"),
    ("hexapod_plant_fmu", "stroke", math.nan, "stroke = nan m is outside its valid range"),
    ("telescope_fmu", "el_rate_max", 0.0, "el_rate_max = 0 rad/s (0 deg/s) is outside its valid range >= 1e-12 rad/s"),
    ("mechanism3t_plant_fmu", "mode", 0, "mode = 0 is not one of -1, 1"),
    ("slider_controller_fmu", "mode", 2, "mode = 2 is outside its valid range [-1, 1]"),
], ids=["elevation 95 deg", "elevation 1e300 deg", "force limit 0", "force limit < 0", "negative kp",
        "negative kd", "max_step 0", "max_step < 0", "1 um stroke", "fidelity past the last", "nan stroke",
        "zero rate limit", "mode 0", "mode 2"])
def test_out_of_range_parameter_is_refused_at_initialization_naming_it(fmus, script, name, value, text):
    error = _refused_at_init(fmus[script], **{name: value})
    assert f"InvalidInputError in initialization: parameter {text}" in error, error


def test_the_declared_range_is_the_one_checked(fmus):
    """The edges of the declared stroke range are accepted, just past them refused."""
    stroke = next(v for v in _parameters(fmus["hexapod_plant_fmu"]) if v.name == "stroke")
    low, high = float(stroke.min), float(stroke.max)
    for edge in (low, high):
        open_fmu(fmus["hexapod_plant_fmu"], "edge", stroke=edge).terminate()
    for past in (np.nextafter(low, 0.0), np.nextafter(high, np.inf)):
        assert "parameter stroke" in _refused_at_init(fmus["hexapod_plant_fmu"], stroke=past)


@pytest.mark.parametrize("script, name", [("leg_controller_fmu", "leg_length[3]"),
                                           ("hexapod_plant_fmu", "base_acc[6]"),
                                           ("slider_controller_fmu", "slider_rate[1]"),
                                           ("mechanism3t_plant_fmu", "slider_force[2]")])
@pytest.mark.parametrize("value", [math.nan, math.inf], ids=["nan", "inf"])
def test_non_finite_input_at_initialization_fails_there(fmus, script, name, value):
    """Refused by fmi2ExitInitializationMode (fmi2Error), not by the first doStep; the failed instance still answers
    doStep (refusing) and is freed safely,
    and a new instance in the same process works."""
    error = _refused_at_init(fmus[script], **{name: value})
    assert f"input {name} = {value} at initialization: inputs must be finite" in error, error
    again = open_fmu(fmus[script], "again")
    again.do_step(0.0, 1e-3)


def test_a_failed_initialization_leaves_an_instance_that_refuses_steps(fmus):
    from scenarios.cosim.fmi import Instance
    from tests.fmu_helpers import OPENED
    instance = Instance(fmus["hexapod_plant_fmu"], "failed")
    OPENED.append(instance)
    with pytest.raises(FmuError):
        instance.initialize(0.0, {"max_step": 0.0})
    status = instance.raw("fmi2DoStep")(instance.fmu.component, 0.0, 1e-3, 1)
    assert status == 2 and "refusing doStep at t=0 s after: InvalidInputError in initialization" in instance.log[-1]


def test_after_a_discarded_step_the_outputs_hold_the_last_accepted_state(fmus):
    """Issue 10 saw leg length 3.556 m and leg rate 865 m/s after a Discard: now the
    outputs equal those read after the last accepted step, at LastSuccessfulTime."""
    plant = open_fmu(fmus["hexapod_plant_fmu"], moving_base=0, stroke=0.01,
                     **{f"leg_force[{i + 1}]": STATIC[i] for i in range(6)})
    names = [f"{n}[{i + 1}]" for n in ("leg_length", "leg_rate", "pose", "pose_rate") for i in range(6)]
    port, force = RealPort(plant, names), RealPort(plant, ["leg_force[1]"])
    force.write([STATIC[0] + 1e6])
    h, accepted = 1e-3, None
    with pytest.raises(FmuError, match="StrokeError"):
        for k in range(100):
            plant.do_step(k * h, h)
            accepted, t_accepted = port.read().copy(), (k + 1) * h
    assert accepted is not None and np.abs(accepted[:6] - StewartParams.paper().home_lengths).max() <= 0.01
    np.testing.assert_array_equal(port.read(), accepted)
    assert plant.fmu.getRealStatus(fmi2LastSuccessfulTime) == pytest.approx(t_accepted, abs=1e-12)


def test_after_a_discarded_controller_step_the_integral_is_not_advanced(fmus):
    """A controller step refused for a NaN measurement leaves forces and integral as the
    last accepted step left them."""
    ctrl = open_fmu(fmus["slider_controller_fmu"])
    names = [f"{n}[{i + 1}]" for n in ("slider_force", "integral", "reference_position") for i in range(3)]
    port = RealPort(ctrl, names)
    for k in range(5):
        ctrl.do_step(k * 1e-3, 1e-3)
    accepted = port.read().copy()
    assert np.abs(accepted[3:6]).max() > 0   # the integral moved
    RealPort(ctrl, ["slider_rate[2]"]).write([math.nan])
    with pytest.raises(FmuError, match="NaN or inf"):
        ctrl.do_step(5e-3, 1e-3)
    np.testing.assert_array_equal(port.read(), accepted)


def test_a_joint_condition_on_valid_parameters_is_refused_at_initialization(fmus):
    """Each value inside its range, together impossible: a source 95 deg south of the
    zenith at culmination never rises (sidereal profile); the FMU says so at init."""
    latitude = next(float(v.start) for v in _parameters(fmus["telescope_fmu"]) if v.name == "latitude")
    error = _refused_at_init(fmus["telescope_fmu"], profile=1, declination=latitude - math.radians(95.0))
    assert "InvalidInputError in initialization: the source is below the horizon" in error, error


def _initialized(path, name, value):
    """(instance, the FMICallException fmpy raised from exitInitializationMode) with
    ``name`` set to ``value`` in initialization mode, through fmpy's FMU2Slave itself."""
    instance = Instance(path, "bad")
    OPENED.append(instance)
    instance.fmu.setupExperiment(startTime=0.0)
    instance.fmu.enterInitializationMode()
    instance.set(name, value)
    with pytest.raises(FMICallException) as error:
        instance.fmu.exitInitializationMode()
    return instance, error.value


@pytest.mark.parametrize("script", SCRIPTS)
@pytest.mark.parametrize("case", ["nan", "inf", "out of range"])
def test_fmpy_sees_fmi2_error_from_a_failed_initialization(fmus, script, case):
    """fmpy's FMICallException carries status 3 (fmi2Error, not 4 fmi2Fatal: the shim in
    front of pythonfmu's wrapper), the log's last line says what is wrong, and the
    instance stays usable: doStep answers Discard, terminate and free are safe."""
    if case == "out of range":
        name, value, text = BAD_INIT[script][2:]
        text = f"parameter {text}"
    else:
        name, text = BAD_INIT[script][:2]
        value = math.nan if case == "nan" else math.inf
        text = text.format(value)
    instance, error = _initialized(fmus[script], name, value)
    assert (error.function, error.status) == ("fmi2ExitInitializationMode", ERROR)
    assert instance.log[-1].startswith("[ERROR] InvalidInputError in initialization: ") and text in instance.log[-1]
    assert not any("Fatal" in line or line.startswith("[FATAL]") for line in instance.log), instance.log
    assert instance.raw("fmi2DoStep")(instance.fmu.component, 0.0, 1e-3, 1) == DISCARD
    assert "refusing doStep at t=0 s after: InvalidInputError in initialization" in instance.log[-1]
    instance.terminate()


def _unshimmed(fmu, folder):
    """A copy of ``fmu`` whose binaries/linux64/<id>.so is pythonfmu's wrapper itself (the
    FMU as pythonfmu built it, before the shim)."""
    identifier = read_model_description(str(fmu)).coSimulation.modelIdentifier
    copy = folder / fmu.name
    with zipfile.ZipFile(fmu) as z, zipfile.ZipFile(copy, "w") as out:
        for item in z.namelist():
            if item == f"binaries/linux64/{identifier}.so":
                continue
            data = z.read(item)
            out.writestr(item.replace(".pythonfmu.so", ".so"), data)
    return copy


def _trace(path):
    """Statuses and answers of one discarded-step run of the plant and one failed
    initialization: what the host reads after a Discard (fmi2GetRealStatus for the last
    successful time, fmi2GetStatus) and the status of the failure."""
    plant = open_fmu(path, "trace", moving_base=0, stroke=0.01, **{f"leg_force[{i + 1}]": STATIC[i] for i in range(6)})
    RealPort(plant, ["leg_force[1]"]).write([STATIC[0] + 1e6])
    steps = [plant.raw("fmi2DoStep")(plant.fmu.component, k * 1e-3, 1e-3, 1) for k in range(12)]
    value = fmi2Status()
    get_status = plant.raw("fmi2GetStatus")(plant.fmu.component, fmi2DoStepStatus, ctypes.byref(value))
    trace = {"doStep": steps, "lastSuccessfulTime": plant.fmu.getRealStatus(fmi2LastSuccessfulTime),
             "getStatus": (get_status, plant.log[-1])}
    plant.terminate()
    _, error = _initialized(path, "max_step", 0.0)
    trace["exitInitializationMode"] = error.status
    return trace


def test_the_shim_changes_only_the_failed_initialization_status_and_last_time(fmus, tmp_path):
    """The same calls through the shim and on pythonfmu's wrapper directly: the same
    statuses and answers (doStep up to the Discard and the refused ones after it), except
    fmi2ExitInitializationMode's failure (Error instead of Fatal),
    fmi2GetRealStatus(fmi2LastSuccessfulTime) after refused steps (the shim answers the end
    of the last accepted step, the wrapper the start of the latest refused one: it moves on
    as the host keeps stepping) and fmi2GetStatus, which the wrapper does not support and
    the shim answers itself (fmi2OK: no step pending)."""
    shimmed = _trace(fmus["hexapod_plant_fmu"])
    direct = _trace(_unshimmed(fmus["hexapod_plant_fmu"], tmp_path))
    assert (direct.pop("exitInitializationMode"), shimmed.pop("exitInitializationMode")) == (FATAL, ERROR)
    accepted = shimmed["doStep"].index(DISCARD)          # steps 0 .. accepted-1 were accepted
    assert accepted > 0 and set(shimmed["doStep"][accepted:]) == {DISCARD}
    assert shimmed.pop("lastSuccessfulTime") == (accepted - 1) * 1e-3 + 1e-3
    assert direct.pop("lastSuccessfulTime") == pytest.approx((len(direct["doStep"]) - 1) * 1e-3)
    assert direct.pop("getStatus") == (ERROR, "[ERROR] FMI function not supported: fmi2GetStatus")
    assert shimmed.pop("getStatus")[0] == 0
    assert shimmed == direct
