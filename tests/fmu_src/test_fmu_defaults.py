"""Every FMU runs in a plain importer with nothing set: fmpy.simulate_fmu with no
arguments runs its DefaultExperiment (1 s at 1 ms), and the default start values hold
the mechanisms still (the truth: the plant's forward dynamics under forces from inverse
dynamics at the operating point, fmu_src/operating_point.py; with the old zero starts the
hexapod left its stroke at 0.184 s). Choice parameters are FMI Enumerations with the
scenario files' names, and every parameter declares a range."""
import subprocess
import sys
import xml.etree.ElementTree as ET
import zipfile

import numpy as np
import pytest
from fmpy import read_model_description, simulate_fmu
from fmpy.validation import validate_fmu

from fmu_src import operating_point as op
from fmu_src import python_build as builder
from plant.hexapod.model import HOME_POSE, StewartParams

NAMES = {"hexapod_plant_fmu": "HexapodPlant", "telescope_fmu": "Telescope", "leg_controller_fmu": "LegController",
         "mechanism3t_plant_fmu": "Mechanism3TPlant", "slider_controller_fmu": "SliderController",
         "leg_sensor_fmu": "LegSensor", "base_sensor_fmu": "BaseSensor", "wind_fmu": "Wind"}
CHOICES = {"HexapodPlant": {"fidelity": ("full", "massless_legs", "base_gravity", "no_base"),
                            "integrator": ("rk4", "euler", "radau")},
           "Telescope": {"profile": ("slew", "sidereal", "paper", "replay")},
           "LegController": {"feedforward": ("none", "fixed_base", "moving_base"),
                             "observer_model": ("scalar", "leg_space")},
           "Mechanism3TPlant": {"integrator": ("rk4", "euler", "radau")},
           "SliderController": {"feedforward": ("off", "on")},
           "BaseSensor": {"source": ("encoders", "imu")}, "Wind": {"spectrum": ("kaimal", "davenport")}}


@pytest.fixture(scope="module", params=["python", "native"])
def kit(request):
    return request.getfixturevalue("fmus" if request.param == "python" else "native")


def _vector(result, name, size):
    return np.array([result[f"{name}[{i}]"] for i in range(1, size + 1)]).T


@pytest.mark.parametrize("script", list(NAMES))
def test_every_fmu_runs_its_default_experiment_with_nothing_set(kit, script):
    path = kit[script]
    assert validate_fmu(str(path)) == []
    experiment = read_model_description(str(path)).defaultExperiment
    assert (float(experiment.startTime), float(experiment.stopTime), float(experiment.stepSize)) == (0.0, 1.0, 1e-3)
    result = simulate_fmu(str(path))
    assert len(result) == 1001 and result["time"][-1] == pytest.approx(1.0)
    for name in result.dtype.names:
        assert np.all(np.isfinite(result[name])), name


def test_the_hexapod_holds_still_at_home(kit):
    """Static leg forces on the tilted base: the platform stays at home (to 1e-12 m / rad)
    and the leg lengths at the home lengths; the same plant with zero forces falls."""
    result = simulate_fmu(str(kit["hexapod_plant_fmu"]))
    assert np.max(np.abs(_vector(result, "pose", 6) - HOME_POSE)) < 1e-12
    assert np.max(np.abs(_vector(result, "leg_length", 6) - StewartParams.paper().home_lengths)) < 1e-12
    falling = simulate_fmu(str(kit["hexapod_plant_fmu"]), stop_time=0.1,
                           start_values={f"leg_force[{i}]": 0.0 for i in range(1, 7)})
    assert np.max(np.abs(_vector(falling, "pose", 6)[-1, :3] - HOME_POSE[:3])) > 1e-3


def test_the_3t_mechanism_holds_still(kit):
    result = simulate_fmu(str(kit["mechanism3t_plant_fmu"]))
    assert np.max(np.abs(_vector(result, "slider_position", 3) - op.SLIDER_POSITION)) < 1e-12
    falling = simulate_fmu(str(kit["mechanism3t_plant_fmu"]), stop_time=0.1,
                           start_values={f"slider_force[{i}]": 0.0 for i in range(1, 4)})
    assert np.max(np.abs(_vector(falling, "slider_position", 3)[-1] - op.SLIDER_POSITION)) > 1e-3


def _starts(path, name, size):
    variables = {v.name: v for v in read_model_description(str(path)).modelVariables}
    return np.array([float(variables[f"{name}[{i}]"].start) for i in range(1, size + 1)])


def test_the_inputs_start_at_one_operating_point(kit):
    """Each FMU's inputs start where its neighbours' outputs start: the telescope's base
    and axes at t = 0, the controller's initial forces on the plant's start forces, the
    plant's home legs on the controller's and sensor's leg inputs."""
    base = simulate_fmu(str(kit["telescope_fmu"]), stop_time=1e-3)
    initial = {n: _vector(base, n, 6)[0] for n in ("base_pose", "base_rate", "base_acc")}
    # (the first row is after the first step: at rest the base has not moved in 1 ms)
    np.testing.assert_allclose(initial["base_pose"], op.BASE_POSE, rtol=0, atol=1e-9)
    for script, name in (("hexapod_plant_fmu", "base_pose"), ("leg_controller_fmu", "base_pose"),
                         ("wind_fmu", "base_pose"), ("base_sensor_fmu", "true_base_pose")):
        # (pythonfmu writes starts to 16 digits; the native FMUs exactly)
        np.testing.assert_allclose(_starts(kit[script], name, 6), op.BASE_POSE, rtol=1e-15, err_msg=script)
    np.testing.assert_allclose(_starts(kit["base_sensor_fmu"], "axis", 2), [0.0, np.radians(30.0)], atol=0)
    home = StewartParams.paper().home_lengths
    for script, name in (("leg_controller_fmu", "leg_length"), ("leg_sensor_fmu", "leg_length")):
        np.testing.assert_allclose(_starts(kit[script], name, 6), home, rtol=1e-15, err_msg=script)
    # the controller's force at initialization (its moving-base feedforward of the held
    # home pose) is the force the plant starts with
    controller = simulate_fmu(str(kit["leg_controller_fmu"]), stop_time=1e-3)
    np.testing.assert_allclose(_vector(controller, "leg_force", 6)[0], _starts(kit["hexapod_plant_fmu"], "leg_force",
                                                                               6),
                               rtol=1e-9)
    slider = simulate_fmu(str(kit["slider_controller_fmu"]), stop_time=1e-3, start_values={"feedforward": 1})
    np.testing.assert_allclose(_starts(kit["slider_controller_fmu"], "slider_position", 3), op.SLIDER_POSITION)
    # the sine reference moves at 5 mm/s from t = 0: its feedforward differs from the static
    # force by the (small) velocity terms only
    np.testing.assert_allclose(_vector(slider, "feedforward_force", 3)[0], op.STATIC_SLIDER_FORCES, rtol=0.05)


def test_choice_parameters_are_enumerations_named_as_the_scenarios_name_them(kit):
    for script, name in NAMES.items():
        with zipfile.ZipFile(kit[script]) as z:
            root = ET.fromstring(z.read("modelDescription.xml"))
        types = {t.get("name"): [(i.get("name"), int(i.get("value"))) for i in t.iter("Item")]
                 for t in root.iter("SimpleType")}
        declared = {v.get("name"): v.find("Enumeration").get("declaredType") for v in root.iter("ScalarVariable")
                    if v.find("Enumeration") is not None}
        assert set(declared) == set(CHOICES.get(name, {})), name
        for variable, labels in CHOICES.get(name, {}).items():
            assert types[declared[variable]] == [(label, k) for k, label in enumerate(labels)], (name, variable)


def test_an_enumeration_is_set_by_its_value_from_fmpys_command_line(kit, tmp_path):
    """fmpy 0.3.32's command line sets an Enumeration by its item's value (it converts
    every start value with int(), names included: see docs/defaults-and-masters.md)."""
    out = tmp_path / "paper.csv"
    run = subprocess.run([sys.executable, "-m", "fmpy.cli", "simulate", str(kit["telescope_fmu"]), "--stop-time",
                          "0.01",
                          "--start-values", "profile", "2", "--output-file", str(out)], capture_output=True, text=True)
    assert run.returncode == 0, run.stderr
    slew = simulate_fmu(str(kit["telescope_fmu"]), stop_time=0.01)
    paper = np.genfromtxt(out, delimiter=",", names=True)
    # the paper manoeuvre's base starts at the {W} origin, the slew's 25 m out along the
    # boresight at 30 deg elevation
    assert np.max(np.abs(paper["base_pose2"] - slew["base_pose[2]"])) > 1.0


def test_the_initial_poses_and_positions_declare_their_ranges(kit):
    """The 6 + 6 + 3 parameters the issue counted without min/max (every other parameter's
    range: tests/fmu_src/test_fmu_errors.py) have both, with the default inside."""
    counted = {}
    for script, name in NAMES.items():
        for v in read_model_description(str(kit[script])).modelVariables:
            if v.causality == "parameter" and v.name.startswith(("initial_pose", "initial_position", "initial_rate")):
                assert v.min is not None and v.max is not None, f"{name}.{v.name}"
                assert float(v.min) <= float(v.start) <= float(v.max), f"{name}.{v.name}"
                counted[name] = counted.get(name, 0) + 1
    assert counted == {"HexapodPlant": 6, "Mechanism3TPlant": 6, "SliderController": 3}


def test_the_recorded_description_is_what_the_builder_wrote(fmus):
    """One description for every writer (the FMI 3 one too): the slave instance's
    enumerations and default experiment are those in modelDescription.xml."""
    slave = builder.slave_instance(fmus["telescope_fmu"])
    assert slave.enumerations == {"profile": CHOICES["Telescope"]["profile"]}
    assert (slave.default_experiment.stop_time, slave.default_experiment.step_size) == (1.0, 1e-3)
