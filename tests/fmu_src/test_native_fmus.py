"""Native FMUs (fmu_src/native, C) against their pythonfmu twins, the independent truth:
the same variables, the same results in every shipped scenario, the same failure
messages on bad input; plus what only the native ones promise: FMU states that replay
bit for bit through get/set and serialisation, and fmi2Discard with the last accepted
state kept."""
import math
import xml.etree.ElementTree as ET
import zipfile

import fmpy.fmi2
import numpy as np
import pytest
from fmpy import read_model_description, simulate_fmu
from fmpy.build import build_platform_binary
from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import fmi2Real

from fmu_src import catalogue
from fmu_src import python_build as builder
from scenarios.cosim.fmi import Instance
from scenarios.cosim.records import read_records
from scenarios.runs import runner
from tests.fmu_helpers import DISCARD, OPENED, _failure, _scales, _stepping_failure, failure_lines, opened, reals, step

OK, ERROR = 0, 3


# ------------------------------------------------------------------- description
@pytest.mark.parametrize("script", catalogue.SCRIPTS)
def test_same_variables_as_the_pythonfmu_fmu(fmus, native, script):
    """Names, value references, causalities, variabilities, types, units, descriptions and
    start values (exactly, as the Python instance has them) agree, String parameters (the
    telescope's replay_table) too; only the native FMU
    says it needs no execution tool and lists its sources, which the zip holds."""
    py, nat = read_model_description(str(fmus[script])), read_model_description(str(native[script]))
    assert nat.coSimulation.modelIdentifier == py.coSimulation.modelIdentifier
    assert nat.guid != py.guid
    fields = ("name", "valueReference", "causality", "variability", "initial", "type", "unit", "displayUnit",
              "description", "min", "max")
    for a, b in zip(py.modelVariables, nat.modelVariables, strict=True):
        assert [getattr(a, f) for f in fields] == [getattr(b, f) for f in fields]
        if a.type == "String":
            assert a.start == b.start == ""
            continue
        if a.initial == "calculated":   # the outputs: no start value (fmu_src/slave.py to_xml)
            assert a.start is None and b.start is None
            continue
        assert float(b.start) == pytest.approx(float(a.start), rel=1e-15, abs=0)
    assert [u.variable.name for u in nat.initialUnknowns] == [u.variable.name for u in py.initialUnknowns]
    slave = builder.slave_instance(fmus[script])
    for var in nat.modelVariables:   # native starts are the Python instance's, to the bit
        if var.start is None or var.type == "String":
            continue
        vr = var.valueReference
        exact = slave.get_real([vr])[0] if var.type == "Real" else slave.get_integer([vr])[0]
        assert float(var.start) == exact, var.name
    with zipfile.ZipFile(native[script]) as z:
        names = set(z.namelist())
        root = ET.fromstring(z.read("modelDescription.xml"))
    cs = root.find("CoSimulation")
    assert cs.get("needsExecutionTool") == "false" and cs.get("canSerializeFMUstate") == "true"
    listed = {f.get("name") for f in cs.find("SourceFiles")}
    assert {
        f"sources/{n}" for n in listed
    } <= names and f"binaries/linux64/{nat.coSimulation.modelIdentifier}.so" in names
    assert not any(n.startswith("resources/") and n.endswith(".py") for n in names)


# ---------------------------------------------------------------------- scenarios
def _columns(path):
    """Columns of a run's records file by header, e.g. "plant.pose[1] [m]"."""
    return read_records(path).columns


def _numbers(tree, prefix=""):
    """The numbers of a nested metrics dict, by dotted key."""
    if isinstance(tree, dict):
        return {k: v for key, sub in tree.items() for k, v in _numbers(sub, f"{prefix}{key}.").items()}
    return {prefix[:-1]: tree} if isinstance(tree, (int, float)) else {}


@pytest.mark.parametrize("name", [   # the observer scenes' FMUs: test_observer_twins.py, in the default run
    pytest.param(p.stem, marks=[pytest.mark.slow] if p.stem.endswith("_observer") else [])
    for p in sorted(runner.SHIPPED.glob("*.toml"))])
def test_shipped_scenario_same_native_and_python(name, tmp_path):
    """Every recorded variable of every sweep value of the [ci] run agrees to 1e-12 of its
    vector's largest magnitude, and so do the metrics (the same C kernels behind both)."""
    runs = {impl: runner.run_scenario(name, tmp_path / impl, ci=True, progress=False, implementation=impl)[1]
            for impl in ("python", "native")}
    assert len(runs["python"]) == len(runs["native"]) > 0
    for a_run, b_run in zip(runs["python"], runs["native"]):
        a, b = _columns(a_run.record_path), _columns(b_run.record_path)
        assert list(a) == list(b) and a["time [s]"].shape == b["time [s]"].shape
        for column, scale in _scales(a).items():
            assert np.max(np.abs(a[column] - b[column])) <= 1e-12 * scale, (a_run.label, column)
        ma, mb = _numbers(a_run.metrics), _numbers(b_run.metrics)
        assert list(ma) == list(mb)
        for key, value in ma.items():
            assert mb[key] == pytest.approx(value, rel=1e-12, abs=0), (a_run.label, key)


# ---------------------------------------------------------------------- bad input
def _both(fmus, native, script, values, drive):
    """Run ``drive(inst)`` on the python and native FMU; returns both instances."""
    return [drive(opened(paths[script], **values)) for paths in (fmus, native)]


PLANT = {"moving_base": 0, "fidelity": 0, "integrator": 0}


@pytest.mark.parametrize("name, value, kind", [("leg_force[3]", math.nan, "leg forces"),
                                               ("base_acc[2]", math.inf, "base acc")])
def test_plant_nan_inf_input_discards(fmus, native, name, value, kind):
    text = _stepping_failure(fmus, native, "hexapod_plant_fmu", PLANT, {name: value})
    assert text == f"InvalidInputError at t=0 s: {kind} input contains NaN or inf"


def test_plant_leg_past_stroke_discards(fmus, native):
    """Zero leg forces: the platform falls under gravity until a leg leaves its 1 mm stroke."""
    text = _stepping_failure(fmus, native, "hexapod_plant_fmu", dict(PLANT, stroke=1e-3), {}, steps=200)
    assert text.startswith("StrokeError at t=") and "outside its stroke" in text


def test_plant_diverging_integrator_discards(fmus, native):
    """Euler over 1 s substeps under 1e9 N leg forces leaves the 100 m bound (in the second step)."""
    text = _stepping_failure(fmus, native, "hexapod_plant_fmu", dict(PLANT, integrator=1, max_step=1.0, stroke=3.0),
                             {f"leg_force[{i}]": 1e9 for i in range(1, 7)}, steps=3, h=1.0)
    assert text.startswith("ConvergenceError at t=1 s: integrator euler diverged over [1, 2] s (substep 1 s)")


def test_plant_singular_initial_pose_is_an_error(fmus, native):
    """The platform in the base plane: every leg horizontal, det J = 0."""
    texts = []
    for paths in (fmus, native):
        inst, status = opened(paths["hexapod_plant_fmu"], **PLANT, **{"initial_pose[3]": 0.0})
        texts.append(_failure(failure_lines(inst)[-1]))
        if paths is native:
            assert status == ERROR
    assert texts[0] == texts[1] and texts[1].startswith("SingularConfigurationError in initialization: singular pose")


def test_plant_nan_input_at_initialization_is_an_error(native):
    inst, status = opened(native["hexapod_plant_fmu"], **PLANT, **{"leg_force[1]": math.nan})
    assert status == ERROR
    assert failure_lines(inst)[-1] == ("[ERROR] InvalidInputError in initialization: input leg_force[1] = nan "
                                       "at initialization: inputs must be finite")


def test_plant_radau_needs_python(native):
    inst, status = opened(native["hexapod_plant_fmu"], **dict(PLANT, integrator=2))
    assert status == ERROR and "radau needs the python implementation" in failure_lines(inst)[-1]


def test_plant_tolerance_needs_rk4(fmus, native):
    """Error-controlled substeps are RK4's: with Euler the tolerance is refused at
    initialization, in the same words by both implementations (plant.hexapod.ode.check_tolerance)."""
    texts = []
    for paths in (fmus, native):
        inst, status = opened(paths["hexapod_plant_fmu"], **dict(PLANT, integrator=1, tolerance=1e-10))
        texts.append(_failure(failure_lines(inst)[-1]))
        if paths is native:
            assert status == ERROR
    assert texts[0] == texts[1]
    assert texts[1] == ("InvalidInputError in initialization: tolerance 1e-10 (error-controlled substeps) needs "
                        "integrator rk4, got 'euler'; set tolerance 0 for euler")


def test_controller_nan_input_discards(fmus, native):
    text = _stepping_failure(fmus, native, "leg_controller_fmu", {}, {"leg_rate[4]": math.nan})
    assert text == "InvalidInputError at t=0 s: leg_rate input contains NaN or inf"


def test_controller_singular_reference_discards(fmus, native):
    text = _stepping_failure(fmus, native, "leg_controller_fmu", {}, {"reference_pose[3]": 0.0})
    assert text.startswith("SingularConfigurationError at t=0 s: singular configuration")


def test_controller_saturation_warns_once(fmus, native):
    """A 1 m leg-length error with a 10 N limit saturates every leg; said once, as in Python."""
    warnings = []
    for paths in (fmus, native):
        inst, status = opened(paths["leg_controller_fmu"], force_limit=10.0)
        inst.set("leg_length[1]", inst.get_real("leg_length[1]") - 1.0)
        for k in range(3):
            assert step(inst, k * 1e-3, 1e-3) == OK
        warnings.append([line for line in inst.log if line.startswith("[WARNING]")])
    assert warnings[0] == warnings[1] and len(warnings[1]) == 1 and "saturated at +-10 N at t=0.001 s" in warnings[1][0]


def test_mechanism_nan_force_discards(fmus, native):
    text = _stepping_failure(fmus, native, "mechanism3t_plant_fmu", {}, {"slider_force[2]": math.nan})
    assert text == "InvalidInputError at t=0 s: slider forces contains NaN or inf"


def test_mechanism_driven_out_of_reach_discards(fmus, native):
    """1 kN more on y_A1 than gravity needs drives the sliders to where the mechanism
    cannot assemble (or into a singularity): both implementations fail at the same step,
    with the same message."""
    text = _stepping_failure(fmus, native, "mechanism3t_plant_fmu", {}, {"slider_force[2]": 5e3}, steps=2000)
    assert text.split(":")[0].split(" at ")[0] in ("UnreachableError", "SingularConfigurationError", "ConvergenceError")


@pytest.mark.parametrize("script", ["mechanism3t_plant_fmu", "slider_controller_fmu"])
def test_assembly_mode_zero_is_an_error(fmus, native, script):
    """mode lies in [-1, 1] but only -1 and +1 are assembly modes."""
    texts = []
    for paths in (fmus, native):
        inst, status = opened(paths[script], mode=0)
        texts.append(_failure(failure_lines(inst)[-1]))
    assert texts[0] == texts[1] == "InvalidInputError in initialization: parameter mode = 0 is not one of -1, 1"
    assert status == ERROR


def test_slider_controller_nan_measurement_discards(fmus, native):
    inst, status = opened(native["slider_controller_fmu"])
    inst.set("slider_rate[1]", math.nan)
    assert step(inst, 0.0, 1e-3) == DISCARD
    assert failure_lines(inst)[-1].startswith("[DISCARD] InvalidInputError at t=0 s: measured slider position/rate "
                                              "input contains NaN or inf")


def test_telescope_source_below_horizon_is_an_error(fmus, native):
    """Sidereal tracking with the default source and start time: below the horizon at t = 0."""
    texts = []
    for paths in (fmus, native):
        inst, status = opened(paths["telescope_fmu"], profile=1)
        texts.append(_failure(failure_lines(inst)[-1]))
    assert texts[0] == texts[1] == "InvalidInputError in initialization: the source is below the horizon at t = 0.0 s"
    assert status == ERROR


# --------------------------------------------------------------------- FMU states
CLOSED_LOOP = ("hexapod_plant_fmu", {"leg_force[1]": 5.3e3, "leg_force[4]": 5.1e3}, ["pose[3]", "leg_rate[2]"])


@pytest.mark.parametrize("script, inputs, watch", [
    CLOSED_LOOP,
    ("leg_controller_fmu", {"leg_length[2]": 3.0, "leg_force_measured[2]": 5e3},
     ["leg_force[2]", "integral[2]", "disturbance_estimate[2]"]),
    ("telescope_fmu", {}, ["base_acc[5]", "reference_pose[3]"]),
    ("mechanism3t_plant_fmu", {"slider_force[1]": 20.0}, ["platform_position[3]", "slider_rate[1]"]),
    ("slider_controller_fmu", {"slider_position[3]": 0.1}, ["slider_force[3]", "integral[3]"]),
    ("wind_fmu", {"base_pose[5]": 0.3}, ["platform_wrench[1]", "gust"]),
    ("leg_sensor_fmu", {"leg_length[1]": 3.1}, ["measured_length[1]", "estimated_rate[1]"]),
    ("load_cell_fmu", {"leg_force[1]": 5e3}, ["measured_force[1]"]),
    ("base_sensor_fmu", {"axis[2]": 0.5, "axis_rate[2]": 0.01}, ["base_pose[4]", "base_rate[5]"]),
])
@pytest.mark.parametrize("implementation", ["native", "python"])
def test_state_get_set_and_serialisation_replay_bit_for_bit(fmus, native, implementation, script, inputs, watch):
    """From a state saved after 5 steps: the rest of the run replays identically after
    fmi2SetFMUstate and after a serialise/deserialise round trip, in a new instance too
    (pythonfmu's own serialization took no numpy state: fmu_src/slave.py's codec)."""
    paths = native if implementation == "native" else fmus
    assert read_model_description(str(paths[script])).coSimulation.canSerializeFMUstate
    values = {"telescope_fmu": {"profile": 2}, "leg_sensor_fmu": {"noise": 1e-6, "rate_cutoff": 20.0},
              "base_sensor_fmu": {"source": 1}, "leg_controller_fmu": {"observer_bandwidth": 20.0},
              "load_cell_fmu": {"noise": 5.0, "bandwidth": 500.0, "delay_steps": 1},
              }.get(script, {})   # random and filter states in play
    inst, status = opened(paths[script], **values)
    assert status == OK

    def run(instance, start, n):
        rows = []
        for k in range(start, start + n):
            for name, value in inputs.items():
                instance.set(name, value * (1 + 1e-3 * k))
            assert step(instance, k * 1e-3, 1e-3) == OK
            rows.append(reals(instance, watch))
        return np.array(rows)

    run(inst, 0, 5)
    state = inst.fmu.getFMUstate()
    blob = inst.fmu.serializeFMUstate(state)
    first = run(inst, 5, 20)
    inst.fmu.setFMUstate(state)
    assert np.array_equal(run(inst, 5, 20), first)
    other, _ = opened(paths[script], **values)
    restored = other.fmu.deSerializeFMUstate(blob)
    other.fmu.setFMUstate(restored)
    assert np.array_equal(run(other, 5, 20), first)
    inst.fmu.freeFMUstate(state)
    other.fmu.freeFMUstate(restored)


# ------------------------------------------------------------------------ sources
@pytest.mark.parametrize("script, start", [("hexapod_plant_fmu", {"moving_base": 0, "leg_force[1]": 5.3e3}),
                                           ("slider_controller_fmu", {"slider_position[2]": 0.1})])
def test_sources_alone_build_the_fmu(native, script, start, tmp_path):
    """What a tool on another platform does: drop the binary, compile sources/ as the
    modelDescription lists them (fmpy compile: CMake and this machine's compiler), run.
    Same numbers as the shipped binary."""
    folder = tmp_path / "fmu"
    with zipfile.ZipFile(native[script]) as z:
        z.extractall(folder, [n for n in z.namelist() if not n.startswith("binaries/")])
    build_platform_binary(unzipdir=folder)
    identifier = read_model_description(str(native[script])).coSimulation.modelIdentifier
    assert (folder / "binaries" / "linux64" / f"{identifier}.so").exists()
    runs = [simulate_fmu(str(p), stop_time=0.2, output_interval=1e-3, start_values=start)
            for p in (native[script], folder)]
    for name in runs[0].dtype.names:
        scale = np.max(np.abs(runs[0][name]))
        assert np.max(np.abs(runs[0][name] - runs[1][name])) <= 1e-12 * scale, name


# ------------------------------------------------------------------------- ranges
def test_parameters_outside_their_range_are_refused(fmus, native):
    """Every parameter with a min or max in the modelDescription (fmu_src/python_build.py adds
    them): a value just outside makes fmi2ExitInitializationMode answer fmi2Error with the
    python FMU's line naming parameter, value and range; the bound itself is accepted."""
    ranged = 0
    for script, path in native.items():
        md = read_model_description(str(path))
        for var in md.modelVariables:
            if var.causality != "parameter" or (var.min is None and var.max is None):
                continue
            for bound, outside in ((var.min, -1), (var.max, +1)):
                if bound is None:
                    continue
                ranged += 1
                value = int(bound) if var.type in ("Integer", "Enumeration") else float(bound)
                bad = (
                    value + outside
                    if var.type in ("Integer", "Enumeration")
                    else value + outside * max(1.0, abs(value)) * 1e-3
                )
                texts = []
                for paths in (fmus, native):
                    inst, status = opened(paths[script], **{var.name: bad})
                    texts.append(_failure(failure_lines(inst)[-1]))
                    if paths is native:
                        assert status == ERROR, var.name
                assert texts[0] == texts[1], var.name
                assert texts[1].startswith(f"InvalidInputError in initialization: parameter {var.name} = ")
                assert "outside its valid range" in texts[1]
                inst, status = opened(native[script], **{var.name: value})
                assert f"parameter {var.name} = " not in " ".join(inst.log), var.name
    assert ranged > 0, "no parameter has a range in the modelDescription"


# ------------------------------------------------------------------------- misuse
def test_misuse_answers_error_with_a_log_line(native):
    """Calls out of order, unknown value references, outputs set, a fixed parameter set
    after initialization, foreign state bytes: fmi2Error and a line naming the problem."""
    path = native["hexapod_plant_fmu"]
    inst = Instance(path, "misuse")
    OPENED.append(inst)
    c = inst.fmu.component
    vr = (fmpy.fmi2.fmi2ValueReference * 1)
    value = (fmi2Real * 1)()
    assert step(inst, 0.0, 1e-3) == ERROR
    assert (
        "fmi2DoStep: not allowed in the instantiated state" in inst.log[-1]
    )  # more: tests/hosts/test_c_host_misuse.py
    pose = inst.vr("pose[1]")
    assert inst.raw("fmi2SetReal")(c, vr(pose), 1, value) == ERROR and "pose[1] is an output" in inst.log[-1]
    inst.initialize(0.0, {"moving_base": 0})
    assert inst.raw("fmi2GetReal")(c, vr(10_000), 1, value) == ERROR and "value reference 10000" in inst.log[-1]
    value[0] = 2e-3
    assert inst.raw("fmi2SetReal")(c, vr(inst.vr("max_step")), 1, value) == ERROR
    assert "max_step is fixed after initialization" in inst.log[-1]
    blob = inst.fmu.serializeFMUstate(inst.fmu.getFMUstate())
    with pytest.raises(Exception):
        inst.fmu.deSerializeFMUstate(blob[:-1])
    assert "not a serialised HexapodPlant state" in inst.log[-1]
    other = Instance(native["leg_controller_fmu"], "other")
    OPENED.append(other)
    with pytest.raises(Exception):
        other.fmu.deSerializeFMUstate(blob)
    assert "not a serialised LegController state" in other.log[-1]
    assert step(inst, 0.0, 1e-3) == OK   # the instance still works


@pytest.mark.parametrize("implementation", ["native", "python"])
def test_bytes_that_are_no_state_are_an_error_and_harm_nothing(fmus, native, implementation):
    """fmi2DeSerializeFMUstate of bytes this FMU did not serialize (not a state, another
    FMU's state, a state with one byte changed) answers fmi2Error with a log line, and the
    instance then steps as an untouched one does (pythonfmu's wrapper answered a failing
    deserialization with fmi2Fatal after dropping references the instance needs: the
    shim refuses such bytes before it sees them)."""
    paths = native if implementation == "native" else fmus
    telescope, _ = opened(paths["telescope_fmu"], profile=2)
    other = bytes(telescope.fmu.serializeFMUstate(telescope.fmu.getFMUstate()))
    plant, _ = opened(paths["hexapod_plant_fmu"], moving_base=0)
    good = bytearray(plant.fmu.serializeFMUstate(plant.fmu.getFMUstate()))
    good[len(good) // 2] ^= 0x01
    runs = []
    for garbage in (b"\0" * 24, b'{"not": "a state"}', other, bytes(good), None):
        inst, status = opened(paths["hexapod_plant_fmu"], **{"moving_base": 0, "leg_force[1]": 5.3e3})
        assert status == OK
        if garbage:
            with pytest.raises(FMICallException) as raised:
                inst.fmu.deSerializeFMUstate(garbage)
            assert raised.value.status == ERROR, garbage[:40]
            assert any(line.startswith("[ERROR]") for line in inst.log), inst.log
        runs.append([(step(inst, k * 1e-3, 1e-3), *reals(inst, ["pose[3]"])) for k in range(5)])
    assert all(run == runs[-1] for run in runs)
