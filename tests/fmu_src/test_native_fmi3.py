"""The FMI 3.0 native FMUs (fmu_src/native/fmi3_layer.c, native_build.build_native3)
against their FMI 2.0 builds, the independent truth here: the same description
translated, the same numbers bit for bit (one model file and kernel behind both), and
FMI 3.0's states and misuse answered as the standard says, with a log line."""
import csv
import pathlib
import xml.etree.ElementTree as ET
import zipfile
from ctypes import CFUNCTYPE, POINTER, byref, c_bool, c_double, c_int, c_void_p

import numpy as np
import pytest
from fmpy import read_model_description, simulate_fmu
from fmpy.fmi1 import FMICallException
from fmpy.validation import validate_fmu

from fmu_src import catalogue, native_build
from fmu_src import python_build as builder
from fmu_src.telescope_fmu import PROFILES
from scenarios.cosim import fmi
from scenarios.cosim.records import run_records
from scenarios.runs import campaign, runner
from tests.fmu_helpers import OPENED

OK, DISCARD, ERROR = 0, 2, 3


@pytest.fixture(scope="module")
def pairs():
    """script -> (FMI 2.0 native FMU, FMI 3.0 native FMU), built when stale (build/fmu/)."""
    fmi2 = native_build.ensure_native(builder.available())
    fmi3 = native_build.ensure_native3(builder.available())
    return {script: (fmi2[script], fmi3[script]) for script in fmi3}


def status_of(call, *args, **kwargs):
    """The FMI status of one of fmpy's calls (it raises on Discard and above)."""
    try:
        call(*args, **kwargs)
    except FMICallException as exc:
        return exc.status
    return OK


def open3(path, name="a"):
    """An FMI 3.0 instance (fmi.Instance3), instantiated, freed after the test."""
    inst = fmi.Instance(path, name)
    OPENED.append(inst)
    assert isinstance(inst, fmi.Instance3)
    return inst


# ------------------------------------------------------------------- description
@pytest.mark.parametrize("script", catalogue.SCRIPTS)
def test_description_is_the_fmi2_one_in_fmi3_terms(pairs, script):
    """fmpy validates the FMU; every FMI 2 variable is an element of an FMI 3 variable
    with the same value reference, type, unit, causality, range, description and exact
    start; the units keep their base units; the default experiment is the same; only
    fmi3* functions are exported."""
    path2, path3 = pairs[script]
    assert validate_fmu(str(path3)) == []
    md2, md3 = read_model_description(str(path2)), read_model_description(str(path3))
    assert md3.fmiVersion == "3.0" and md3.instantiationToken == md2.guid
    assert md3.coSimulation.canGetAndSetFMUstate and md3.coSimulation.canSerializeFMUstate
    elements = {v.name: v for v in fmi.description(path3).modelVariables}
    assert list(elements) == [v.name for v in md2.modelVariables]
    for v2 in md2.modelVariables:
        e = elements[v2.name]
        assert (e.valueReference, e.type, e.unit, e.displayUnit, e.causality, e.description) == \
            (v2.valueReference, v2.type, v2.unit, v2.displayUnit, v2.causality, v2.description), v2.name
        assert getattr(e.declaredType, "name", None) == getattr(v2.declaredType, "name", None), v2.name
        assert (e.min, e.max) == (v2.min, v2.max), v2.name
        if v2.type == "String":   # the telescope's replay_table, <Start value=""/> in FMI 3
            assert e.start == v2.start == "", v2.name
        elif v2.start is not None:
            assert float(e.start) == float(v2.start), v2.name
    def base(unit):
        fields = ("kg", "m", "s", "A", "K", "mol", "cd", "rad", "factor", "offset")
        return None if unit.baseUnit is None else {k: getattr(unit.baseUnit, k) for k in fields}
    assert {u.name: base(u) for u in md3.unitDefinitions} == {u.name: base(u) for u in md2.unitDefinitions}
    assert any(base(u) for u in md3.unitDefinitions)
    for attribute in ("startTime", "stopTime", "stepSize", "tolerance"):
        assert getattr(md3.defaultExperiment, attribute, None) == getattr(md2.defaultExperiment, attribute, None)
    assert [v.name for v in md3.modelVariables if v.causality == "independent"] == ["time"]
    with zipfile.ZipFile(path3) as z:
        assert f"binaries/{native_build.fmi3_platform()}/{md3.coSimulation.modelIdentifier}.so" in z.namelist()
        assert "sources/buildDescription.xml" in z.namelist() and "sources/fmi3_layer.c" in z.namelist()


def test_vectors_of_one_unit_are_arrays(pairs):
    """leg_force is one Float64 of 6 elements (set and read in one call); the pose, whose
    elements are metres and radians, stays six scalars (an FMI 3 array has one unit)."""
    md3 = read_model_description(str(pairs["hexapod_plant_fmu"][1]))
    variables = {v.name: v for v in md3.modelVariables}
    assert [int(d.start) for d in variables["leg_force"].dimensions] == [6]
    assert variables["leg_force"].type == "Float64" and variables["leg_force"].declaredType.unit == "N"
    assert (
        "pose" not in variables
        and variables["pose[4]"].declaredType.unit == "rad"
        and not variables["pose[4]"].dimensions
    )
    inst = open3(pairs["hexapod_plant_fmu"][1])
    inst.fmu.enterInitializationMode(startTime=0.0)
    inst.fmu.setInt32([variables["moving_base"].valueReference], [0])
    forces = [5.1e3, 5.2e3, 5.3e3, 5.4e3, 5.5e3, 5.6e3]
    inst.fmu.setFloat64([variables["leg_force"].valueReference], forces)
    assert inst.fmu.getFloat64([variables["leg_force"].valueReference], nValues=6) == forces


# ------------------------------------------------------------------------ numbers
@pytest.mark.parametrize("script", catalogue.SCRIPTS)
def test_simulate_fmu_gives_the_fmi2_numbers_bit_for_bit(pairs, script):
    """fmpy.simulate_fmu with the default start values: every output of the FMI 3 FMU
    (array columns element by element) equals the FMI 2 FMU's exactly."""
    runs = [simulate_fmu(str(p), stop_time=0.1, output_interval=1e-3) for p in pairs[script]]
    moved = assert_same_results(*runs)
    # with their inputs held at the start values (fmu_src/operating_point.py) the sensors,
    # the controller and the 3T plant (held by its static slider forces) stay put
    assert moved == (script not in ("leg_controller_fmu", "leg_sensor_fmu", "base_sensor_fmu", "mechanism3t_plant_fmu",
                                   "load_cell_fmu"))


def assert_same_results(fmi2, fmi3):
    """Every column of an FMI 2 simulate_fmu result equals the FMI 3 one (an array's
    element by element) exactly; returns whether any output moved."""
    assert fmi2.shape == fmi3.shape and fmi2.size > 40
    moved = False
    for name in fmi2.dtype.names:
        base = name.split("[", 1)[0]
        if base in fmi3.dtype.names and fmi3[base].ndim == 2:
            column = fmi3[base][:, int(name.split("[")[1].rstrip("]")) - 1]
        else:
            column = fmi3[name]
        assert np.array_equal(fmi2[name], column), name
        moved |= name != "time" and np.ptp(column) > 0
    return moved


SHIPPED = sorted(p.stem for p in runner.SHIPPED.glob("*.toml"))
FAST = "keyhole_tracking"   # the shortest [ci] runs (~25 s both); the others are marked slow


@pytest.mark.parametrize("name", [pytest.param(n, marks=[] if n == FAST else [pytest.mark.slow]) for n in SHIPPED])
def test_shipped_scenario_same_with_fmi3_and_fmi2(name, tmp_path):
    """Every instance FMI 3 against every instance FMI 2: the records of every sweep
    value are identical (every recorded variable bit for bit) and so are the metrics."""
    runs = {v: runner.run_scenario(name, tmp_path / str(v), ci=True, progress=False, fmi_version=v)[1]
            for v in (2, 3)}
    assert len(runs[2]) == len(runs[3]) > 0
    for a, b in zip(runs[2], runs[3]):
        assert (a.failure, a.steps) == (b.failure, b.steps), a.label
        ra, rb = run_records(a), run_records(b)
        assert ra.names == rb.names and ra.values.tobytes() == rb.values.tobytes(), a.label
        assert repr(a.metrics) == repr(b.metrics), a.label


def test_scenario_key_fmi_version_is_checked(tmp_path):
    """fmi_version takes 2 or 3, and 3 only with the native implementation."""
    text = (runner.SHIPPED / "mechanism3t_paper.toml").read_text()
    instance = text.split("[fmus.", 1)[1].split("]", 1)[0]
    for value, message in (("4", "unknown FMI version 4"), ('"3"', "unknown FMI version '3'")):
        bad = tmp_path / "bad.toml"
        bad.write_text(text.replace(f"[fmus.{instance}]", f"[fmus.{instance}]\nfmi_version = {value}", 1))
        with pytest.raises(runner.spec.ScenarioError, match=message):
            runner.spec.load(bad)
    bad.write_text(text.replace(f"[fmus.{instance}]",
                                f'[fmus.{instance}]\nfmi_version = 3\nimplementation = "python"', 1))
    with pytest.raises(runner.spec.ScenarioError, match="native FMUs only"):
        runner.spec.load(bad)


# -------------------------------------------------------------------- FMU states
@pytest.mark.parametrize("script, inputs, watch", [
    ("hexapod_plant_fmu", {"leg_force[1]": 5.3e3}, ["pose[3]", "leg_length[1]"]),
    ("leg_sensor_fmu", {"leg_length[1]": 3.1}, ["measured_length[1]", "estimated_rate[1]"]),
    ("telescope_fmu", {}, ["base_acc[5]", "reference_pose[3]"]),
])
def test_state_get_set_and_serialisation_replay_bit_for_bit(pairs, script, inputs, watch):
    """From a state saved after 5 steps, the rest of the run replays identically after
    fmi3SetFMUState and after a serialise/deserialise round trip into a new instance."""
    values = {"hexapod_plant_fmu": {"moving_base": 0}, "leg_sensor_fmu": {"noise": 1e-6, "rate_cutoff": 20.0},
              "telescope_fmu": {"profile": 2}}[script]
    path = pairs[script][1]

    def opened():
        inst = open3(path)
        inst.initialize(0.0, values)
        return inst

    def run(inst, start, n):
        rows = []
        for k in range(start, start + n):
            for name, value in inputs.items():
                inst.set(name, value * (1 + 1e-3 * k))
            inst.do_step(k * 1e-3, 1e-3)
            rows.append([inst.get_real(w) for w in watch])
        return np.array(rows)

    inst = opened()
    run(inst, 0, 5)
    state = inst.fmu.getFMUState()
    blob = inst.fmu.serializeFMUState(state)
    first = run(inst, 5, 20)
    inst.fmu.setFMUState(state)
    assert np.array_equal(run(inst, 5, 20), first)
    other = opened()
    restored = other.fmu.deserializeFMUState(blob)
    other.fmu.setFMUState(restored)
    assert np.array_equal(run(other, 5, 20), first)
    inst.fmu.freeFMUState(state)
    other.fmu.freeFMUState(restored)


# ------------------------------------------------------------------------- misuse
def test_call_sequence_and_bad_references_answer_error_with_a_log_line(pairs):
    """FMI 3.0's state machine: each call out of its states, an unknown or wrongly typed
    value reference, an element of an array, a wrong nValues, an output or time set, a
    fixed parameter set after initialization, a second terminate: fmi3Error and a line."""
    inst = open3(pairs["hexapod_plant_fmu"][1], "misuse")
    f = inst.fmu
    md = {v.name: v.valueReference for v in read_model_description(str(pairs["hexapod_plant_fmu"][1])).modelVariables}
    force = md["leg_force"]
    assert status_of(f.doStep, 0.0, 1e-3) == ERROR and "fmi3DoStep: not allowed in state Instantiated" in inst.log[-1]
    assert status_of(f.getFloat64, [force],
                     6) == ERROR and "fmi3GetFloat64: not allowed in state Instantiated" in inst.log[-1]
    assert status_of(f.exitInitializationMode) == ERROR
    assert "fmi3ExitInitializationMode: not allowed in state Instantiated" in inst.log[-1]
    assert status_of(f.terminate) == ERROR and "fmi3Terminate: not allowed" in inst.log[-1]
    f.enterInitializationMode(startTime=0.5)
    assert f.getFloat64([md["time"]]) == [0.5]
    assert status_of(f.setFloat64, [md["time"]], [1.0]) == ERROR and "independent variable" in inst.log[-1]
    assert status_of(f.getFloat64, [force + 1]) == ERROR and f"value reference {force + 1}" in inst.log[-1]
    assert status_of(f.getFloat64, [10_000]) == ERROR and "value reference 10000" in inst.log[-1]
    assert status_of(f.getFloat64, [force], 5) == ERROR and "cover 6 values, nValues is 5" in inst.log[-1]
    assert status_of(f.getInt32, [force]) == ERROR and "no Int32 variable" in inst.log[-1]
    assert status_of(f.setFloat64, [md["pose[1]"]], [0.0]) == ERROR
    assert inst.log[-1].endswith("fmi3SetFloat64: pose[1] is an output and cannot be set")
    assert status_of(f.getBoolean, [0]) == ERROR and "no Boolean variables" in inst.log[-1]
    assert status_of(f.enterEventMode) == ERROR and "no event mode" in inst.log[-1]
    f.setInt32([md["moving_base"]], [0])
    f.setFloat64([force], [5.3e3] * 6)
    f.exitInitializationMode()
    assert status_of(f.enterInitializationMode) == ERROR and "not allowed in state StepMode" in inst.log[-1]
    assert status_of(f.setFloat64, [md["max_step"]], [2e-3]) == ERROR
    assert "max_step is fixed after initialization" in inst.log[-1]
    assert f.doStep(0.5, 1e-3)[3] == pytest.approx(0.501, abs=0)
    assert f.getFloat64([md["time"]]) == [0.501]
    f.terminate()
    assert status_of(f.terminate) == ERROR and "not allowed in state Terminated" in inst.log[-1]
    assert status_of(f.setFloat64, [force], [1.0] * 6) == ERROR and "not allowed in state Terminated" in inst.log[-1]
    assert status_of(f.doStep, 0.501, 1e-3) == ERROR
    assert len(f.getFloat64([force], 6)) == 6     # reading the end is allowed
    f.reset()
    f.enterInitializationMode(startTime=0.0)      # a reset instance starts again


def test_a_refused_step_ends_stepping(pairs):
    """With no leg forces the platform falls and a leg leaves its stroke: fmi3DoStep
    answers Discard with terminateSimulation; a further doStep is an error
    (StepDiscarded), the outputs still read, terminate is allowed."""
    inst = open3(pairs["hexapod_plant_fmu"][1])
    f = inst.fmu
    f.enterInitializationMode(startTime=0.0)
    force = next(v for v in read_model_description(str(pairs["hexapod_plant_fmu"][1])).modelVariables
                 if v.name == "leg_force")
    f.setFloat64([force.valueReference], [0.0] * 6)
    f.exitInitializationMode()
    step = CFUNCTYPE(c_int, c_void_p, c_double, c_double, c_bool, POINTER(c_bool), POINTER(c_bool), POINTER(c_bool),
                     POINTER(c_double))(("fmi3DoStep", f.dll))
    event, terminate, early, last = c_bool(), c_bool(), c_bool(), c_double()
    t, status = 0.0, OK
    while status == OK and t < 2.0:
        status = step(f.component, t, 1e-3, True, byref(event), byref(terminate), byref(early), byref(last))
        t += 1e-3 if status == OK else 0.0
    assert status == DISCARD and terminate.value and not event.value and not early.value
    assert last.value == pytest.approx(t, abs=1e-12) and 0.1 < t < 0.3
    assert any("StrokeError" in line for line in inst.log)
    assert step(f.component, t, 1e-3, True, byref(event), byref(terminate), byref(early), byref(last)) == ERROR
    assert "fmi3DoStep: not allowed in state StepDiscarded" in inst.log[-1]
    assert np.isfinite(inst.get_real("pose[3]"))
    f.terminate()


def test_host_strings_are_text_never_a_format(pairs):
    """An instantiation token and a log category holding %s/%n are quoted in the log line
    as given (issue 18's crash), and the call is refused."""
    path = pairs["leg_sensor_fmu"][1]
    md = read_model_description(str(path))
    lines = []
    slave = fmi.FMU3Slave(guid="%s%s%s%n%n", unzipDirectory=fmi.unpack(path)[1], instanceName="x",
                          modelIdentifier=md.coSimulation.modelIdentifier)
    with pytest.raises(Exception, match="Failed to instantiate"):
        slave.instantiate(logMessage=lambda env, status, category, message: lines.append(message.decode()))
    assert "instantiationToken '%s%s%s%n%n' is not this FMU's" in lines[-1]
    slave.freeLibrary()
    inst = open3(path)
    assert status_of(inst.fmu.setDebugLogging, True, ["%s%s%s%n"]) == ERROR
    assert "unknown log category '%s%s%s%n'" in inst.log[-1]
    assert status_of(inst.fmu.setDebugLogging, True, ["logStatusError"]) == OK


def test_event_mode_and_intermediate_variables_are_refused(pairs):
    """No event mode and no intermediate update: instantiating with them answers NULL
    and a line saying why."""
    path = pairs["leg_sensor_fmu"][1]
    md = read_model_description(str(path))
    for kwargs, why in (({"eventModeUsed": True}, "has no event mode"),
                        ({"requiredIntermediateVariables": [0]}, "provides no intermediate variables")):
        lines = []
        slave = fmi.FMU3Slave(guid=md.guid, unzipDirectory=fmi.unpack(path)[1], instanceName="x",
                              modelIdentifier=md.coSimulation.modelIdentifier)
        with pytest.raises(Exception, match="Failed to instantiate"):
            slave.instantiate(logMessage=lambda env, s, c, m: lines.append(m.decode()), **kwargs)
        assert why in lines[-1]
        slave.freeLibrary()


def test_bytes_that_are_no_state_are_an_error_and_harm_nothing(pairs):
    """Deserializing bytes of another FMU, or a state with one byte changed, answers
    fmi3Error with a line; the instance then steps on as before."""
    telescope = open3(pairs["telescope_fmu"][1], "t")
    telescope.initialize(0.0, {"profile": 2})
    other = telescope.fmu.serializeFMUState(telescope.fmu.getFMUState())
    inst = open3(pairs["hexapod_plant_fmu"][1], "p")
    inst.initialize(0.0, {"moving_base": 0, "leg_force[1]": 5.3e3})
    good = bytearray(inst.fmu.serializeFMUState(inst.fmu.getFMUState()))
    good[len(good) // 2] ^= 0x01
    for garbage in (other, bytes(good), b"\x04" + b"\0" * 7 + b"x"):
        assert status_of(inst.fmu.deserializeFMUState, garbage) == ERROR
        assert "not a serialised" in inst.log[-1]
    inst.do_step(0.0, 1e-3)


# -------------------------------------------------------------------- enumerations
def test_enumeration_is_set_as_int64(pairs, tmp_path):
    """An FMI 2 Integer declared an Enumeration (as fmu_src/python_build.py declares the
    choice parameters) becomes an FMI 3 Enumeration with the same items, set through
    fmi3SetInt64 (fmi3SetInt32 refused): profile = paper gives the FMI 2 numbers."""
    path2 = pairs["telescope_fmu"][0]
    with zipfile.ZipFile(path2) as z:
        files = {n: z.read(n) for n in z.namelist()}
    root = ET.fromstring(files["modelDescription.xml"])
    types = ET.Element("TypeDefinitions")
    kind = ET.SubElement(ET.SubElement(types, "SimpleType", name="profile"), "Enumeration")
    for value, label in enumerate(PROFILES):
        ET.SubElement(kind, "Item", name=label, value=str(value))
    root.insert(list(root).index(root.find("UnitDefinitions")) + 1, types)
    var = next(v for v in root.iter("ScalarVariable") if v.get("name") == "profile")
    var[0].tag = "Enumeration"
    var[0].set("declaredType", "profile")
    files["modelDescription.xml"] = ET.tostring(root)
    enum2 = tmp_path / "Telescope.fmu"
    with zipfile.ZipFile(enum2, "w") as z:
        for name, data in files.items():
            z.writestr(name, data)
    path3 = native_build.build_native3(enum2, tmp_path / "3")
    md3 = read_model_description(str(path3))
    profile = next(v for v in md3.modelVariables if v.name == "profile")
    assert profile.type == "Enumeration" and profile.declaredType.name == "profile"
    assert [item.name for item in profile.declaredType.items] == list(PROFILES)
    inst = open3(path3)
    inst.fmu.enterInitializationMode(startTime=0.0)
    assert status_of(inst.fmu.setInt32, [profile.valueReference], [2]) == ERROR
    assert "no Int32 variable" in inst.log[-1]
    inst.fmu.setInt64([profile.valueReference], [PROFILES.index("paper")])
    inst.fmu.exitInitializationMode()
    assert inst.fmu.getInt64([profile.valueReference]) == [PROFILES.index("paper")]
    runs = [simulate_fmu(str(p), stop_time=0.5, output_interval=1e-2, start_values={"profile": 2})
            for p in (pairs["telescope_fmu"][0], path3)]
    assert assert_same_results(*runs)


def test_part_of_an_array_connected_keeps_the_rest(tmp_path):
    """Only leg_force[2..6] of the plant connected (an FMI 3 array written in part by the
    C loop, leg_force[1] held at the value set at initialization): the records equal the FMI 2 run's
    bit for bit. Writing the array without reading it first would zero leg_force[1]."""
    text = (runner.SHIPPED / "keyhole_tracking.toml").read_text()
    whole = 'from = "controller.leg_force"\nto = "plant.leg_force"'
    assert whole in text
    parts = "\n[[connections]]\n".join(f'from = "controller.leg_force[{i}]"\nto = "plant.leg_force[{i}]"'
                                       for i in range(2, 7))
    scene = tmp_path / "part.toml"
    text = text.replace(whole, parts).replace('stop_time = "8 s"', 'stop_time = "3 s"')
    scene.write_text(text.replace('max_step = "1 ms",', 'max_step = "1 ms", "leg_force[1]" = 5.3e3,'))
    runs = {v: runner.run_scenario(scene, tmp_path / str(v), ci=True, progress=False, fmi_version=v,
                                   allow_unstable=True)[1] for v in (2, 3)}
    for a, b in zip(runs[2], runs[3], strict=True):
        ra, rb = run_records(a), run_records(b)
        assert (a.failure, a.steps) == (b.failure, b.steps) and a.steps > 10
        assert ra.values.tobytes() == rb.values.tobytes(), a.label
        force = ra.names.index("controller.leg_force[1]")
        assert np.ptp(ra.values[:, force]) > 0    # the controller's force moves; the plant's leg 1 does not get it


def test_a_campaign_over_an_fmi3_scenario_runs_fmi3_fmus(tmp_path):
    """A campaign whose base scenario chooses fmi_version = 3 for every instance: its
    jobs carry FMI 3.0 FMU files (read from the files themselves), it runs through the
    engine's worker processes, and its metrics equal those of the same campaign over
    the FMI 2 scenario exactly."""
    text = (runner.SHIPPED / "keyhole_tracking.toml").read_text()
    summaries = {}
    for version in (2, 3):
        scene = tmp_path / f"scene{version}.toml"
        scene.write_text(text.replace("fmu = ", f"fmi_version = {version}\nfmu = "))
        assert set(runner.spec.load(scene).fmi_versions.values()) == {version}
        path = tmp_path / f"c{version}.toml"
        path.write_text(f'name = "c{version}"\nscenario = "{scene}"\nset = {{ stop_time = "2.5 s" }}\n'
                        '[grid]\n"controller.feedforward" = ["fixed_base", "moving_base"]\n')
        job_list, files = campaign.jobs(campaign.load(path))
        versions = {fmi.unpack(files[d])[0].fmiVersion for job in job_list for d in job.fmus.values()}
        assert versions == {f"{version}.0"}
        camp, jobs, store, outcome, summary = campaign.run_campaign(path, tmp_path / "out", jobs_=1, progress=False)
        assert len(outcome.computed) == len(camp.cases) > 1 and not outcome.failed
        with open(summary) as f:
            summaries[version] = [{k: v for k, v in row.items() if k != "run_time_s"} for row in csv.DictReader(f)]
    assert summaries[2] == summaries[3]
    assert float(summaries[3][0]["leg error rms"]) > 0


def test_one_call_of_many_variables_equals_one_call_each(pairs):
    """fmi3GetFloat64/fmi3SetFloat64 take consecutive variables in one inner call (the
    layer's runs): any order, time in between, arrays and scalars, a run that ends where
    time's value reference begins, give the values of one call per variable."""
    path = pairs["hexapod_plant_fmu"][1]
    inst = open3(path)
    md = {v.name: v for v in read_model_description(str(path)).modelVariables}
    inst.initialize(0.0, {"moving_base": 0, **{f"leg_force[{k}]": 5.0e3 + k for k in range(1, 7)}})
    inst.do_step(0.0, 1e-3)
    floats = [v for v in md.values() if v.type == "Float64"]
    size = {v.name: int(np.prod([int(d.start) for d in v.dimensions])) if v.dimensions else 1 for v in floats}
    one = {v.name: inst.fmu.getFloat64([v.valueReference], size[v.name]) for v in floats}
    last = max(floats, key=lambda v: v.valueReference if v.name != "time" else -1)
    for order in (floats, floats[::-1], [md["pose[2]"], md["time"], md["pose[3]"], md["leg_force"], md["pose[1]"]],
                  [last, md["time"]]):
        values = inst.fmu.getFloat64([v.valueReference for v in order], sum(size[v.name] for v in order))
        assert values == [x for v in order for x in one[v.name]]
    inst.fmu.setFloat64([md["leg_force"].valueReference], [1.0, 2.0, 3.0, 4.0, 5.0, 6.0])
    assert inst.fmu.getFloat64([md["leg_force"].valueReference], 6) == [1.0, 2.0, 3.0, 4.0, 5.0, 6.0]
    assert status_of(inst.fmu.setFloat64, [md["leg_force"].valueReference, md["time"].valueReference],
                     [9.0] * 7) == ERROR
    assert inst.fmu.getFloat64([md["leg_force"].valueReference], 6) == [1.0, 2.0, 3.0, 4.0, 5.0, 6.0]   # nothing set


def test_python_build_py_builds_the_fmi3_fmus_too(tmp_path):
    """`python build.py` ("every FMU of the kit") built no FMI 3.0 FMU: they needed
    `python -m fmu_src.native_build --fmi3`."""
    import subprocess
    import sys

    from fmpy import read_model_description
    root = pathlib.Path(__file__).resolve().parents[2]
    done = subprocess.run([sys.executable, str(root / "build.py"), "--out", str(tmp_path), "leg_sensor_fmu"],
                          capture_output=True, text=True, check=True)
    assert "native3" in done.stdout
    versions = {folder: read_model_description(str(tmp_path / folder / "LegSensor.fmu")).fmiVersion
                for folder in (".", "native", "native3")}
    assert versions == {".": "2.0", "native": "2.0", "native3": "3.0"}
