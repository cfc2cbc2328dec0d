"""Every built FMU's modelDescription declares each output's dependencies (FMI 2
ModelStructure/Outputs/Unknown, FMI 3 ModelStructure/Output) as fmu_src/catalogue.py's
feedthrough table says: an output with no direct feedthrough declares none (""), which FMI
reads as "depends on no input" (a missing attribute is "every input": OMSimulator then saw
an algebraic loop between plant and controller). Checked in the pythonfmu (FMI 2), native
FMI 2 and native FMI 3 FMUs, element by element, and by fmpy's validation."""
import xml.etree.ElementTree as ET
import zipfile

import numpy as np
import pytest
from fmpy import read_model_description
from fmpy.validation import validate_fmu

from fmu_src import catalogue, native_build
from fmu_src import python_build as builder


@pytest.fixture(scope="module")
def built():
    """{(kind, script): path} of the kit's FMUs (built into build/fmu if missing or stale)."""
    scripts = builder.available()
    kinds = {"pythonfmu": builder.ensure_built(scripts), "native": native_build.ensure_native(scripts),
             "native3": native_build.ensure_native3(scripts)}
    return {(kind, script): path for kind, paths in kinds.items() for script, path in paths.items()}


def _root(path):
    with zipfile.ZipFile(path) as z:
        return ET.fromstring(z.read("modelDescription.xml"))


def _expected(key, output, inputs):
    """The catalogue's row read apart from catalogue.output_dependencies: the inputs whose
    base name (before '[') the output's base name lists, or all for ALL."""
    row = catalogue.FEEDTHROUGH.get(key, {}).get(output.split("[")[0], ())
    return {name for name in inputs if row == catalogue.ALL or name.split("[")[0] in row}


def test_every_output_declares_the_inputs_the_catalogue_says_it_follows(built):
    checked = {"pythonfmu": 0, "native": 0, "native3": 0}
    for (kind, script), path in built.items():
        root = _root(path)
        key = catalogue.BY_IDENTIFIER[root.find("CoSimulation").get("modelIdentifier")].key
        if kind == "native3":
            variables = root.find("ModelVariables")
            by_vr = {v.get("valueReference"): v for v in variables}
            inputs = {v.get("name") for v in variables if v.get("causality") == "input"}
            outputs = root.find("ModelStructure").findall("Output")
            assert {o.get("valueReference") for o in outputs} == \
                {v.get("valueReference") for v in variables if v.get("causality") == "output"}
            for output in outputs:
                declared = {by_vr[vr].get("name") for vr in output.get("dependencies").split()}
                assert declared == _expected(key, by_vr[output.get("valueReference")].get("name"), inputs), path
                assert all(by_vr[vr].get("causality") == "input" for vr in output.get("dependencies").split())
                checked[kind] += 1
        else:
            variables = list(root.iter("ScalarVariable"))
            inputs = {v.get("name") for v in variables if v.get("causality") == "input"}
            unknowns = root.find("ModelStructure/Outputs").findall("Unknown")
            assert len(unknowns) == sum(v.get("causality") == "output" for v in variables)
            for unknown in unknowns:
                output = variables[int(unknown.get("index")) - 1]
                declared = {variables[int(i) - 1].get("name") for i in unknown.get("dependencies").split()}
                assert output.get("causality") == "output"
                assert declared == _expected(key, output.get("name"), inputs), (path, output.get("name"))
                checked[kind] += 1
    # every FMU of the catalogue, in all three kinds, and every output of each (FMI 3 arrays: fewer)
    assert {s for _, s in built} == set(catalogue.SCRIPTS)
    assert checked["pythonfmu"] == checked["native"] > checked["native3"] > 0


def test_the_declarations_pin_the_table_s_rows(built):
    """Known rows, counted by hand from the FMUs' interfaces: the plant's delivered force
    follows its 6 force inputs and nothing else; the telescope's outputs follow no input
    (support_load reaches them through the support's state); the base sensor's every input."""
    root = _root(built[("native", "hexapod_plant_fmu")])
    variables = list(root.iter("ScalarVariable"))
    for unknown in root.find("ModelStructure/Outputs"):
        name = variables[int(unknown.get("index")) - 1].get("name")
        deps = [variables[int(i) - 1].get("name") for i in unknown.get("dependencies").split()]
        assert deps == ([f"leg_force[{k}]" for k in range(1, 7)] if name.startswith("leg_force_actual[") else []), name
    root = _root(built[("native3", "telescope_fmu")])
    assert root.find("ModelStructure").findall("Output") and \
        all(o.get("dependencies") == "" for o in root.find("ModelStructure").findall("Output"))
    root = _root(built[("pythonfmu", "base_sensor_fmu")])
    n_inputs = sum(v.get("causality") == "input" for v in root.iter("ScalarVariable"))
    assert n_inputs > 0 and all(len(u.get("dependencies").split()) == n_inputs
                                for u in root.find("ModelStructure/Outputs"))


def test_fmpy_validates_every_fmu_and_reads_the_dependencies(built):
    for (kind, _), path in built.items():
        assert validate_fmu(str(path)) == [], path
        md = read_model_description(str(path), validate=True)
        assert md.outputs and all(output.dependencies is not None for output in md.outputs), path


# Found by the test below, left as it is: the load cell's measured_force is its leg_force sampled
# at t and read out at t + h, as the leg sensor's measured_length is, which the table counts as
# feedthrough ("a sensor's delay line counts as no state"); the load cell has no row, so its
# modelDescription declares dependencies="" (true at one instant, FMI's reading). A row would
# also move the load cell from first to after the plant in master.step_order's initialization
# order of the observer scenes (telescope_slew_observer, keyhole_tracking_observer): a change
# of their numbers, for the lead to decide. Pinned here so that adding the row drops this entry.
SAMPLED_LATE = {("load_cell", "leg_force")}


def test_an_output_declared_independent_of_an_input_does_not_follow_it_within_a_step(built):
    """The table against the FMUs themselves (native FMI 2.0): instances alike but for one
    input (all its elements moved by 0.1 % + 1e-3 of a unit), one step of h: an output that
    declares no dependency on that input moves by at most what its state can carry in h = 1 us
    (1e-6 of its scale); where the input has declared dependents, one of them moves by as much
    at h = 0.1 us as at 1 us (at least half: direct feedthrough acts at once, a state's effect
    shrinks with the step) and by more than rounding (rows that name every input, "*", say
    "any it may use": the base sensor reads some inputs in one source mode only)."""
    from tests.fmu_helpers import open_fmu
    checked = 0
    for (kind, script), path in built.items():
        if kind != "native":
            continue
        md = read_model_description(str(path))
        key = catalogue.BY_IDENTIFIER[md.coSimulation.modelIdentifier].key
        inputs = [v for v in md.modelVariables if v.causality == "input" and v.type == "Real"]
        outputs = [v.name for v in md.modelVariables if v.causality == "output" and v.type == "Real"]
        names = [v.name for v in md.modelVariables if v.causality == "input"]
        for group in dict.fromkeys(v.name.split("[")[0] for v in inputs):
            moved, deltas = {}, {}
            for v in inputs:
                if v.name.split("[")[0] == group:
                    start, delta = float(v.start), 1e-3 * (abs(float(v.start)) + 1)
                    high = float(v.max) if v.max is not None else np.inf
                    moved[v.name] = start + delta if start + delta <= high else start - delta
                    deltas[v.name] = delta

            def change(h):
                a, b = open_fmu(path, "a"), open_fmu(path, "b")
                for name, value in moved.items():
                    b.set(name, value)
                a.do_step(0.0, h)
                b.do_step(0.0, h)
                return ({o: abs(b.get_real(o) - a.get_real(o)) for o in outputs},
                        {o: 1.0 + abs(a.get_real(o)) for o in outputs})

            (long, scale), (short, _) = change(1e-6), change(1e-7)
            declared = {o for o in outputs if set(moved) & set(catalogue.output_dependencies(key, o, names))}
            for name in set(outputs) - declared:
                if (key, group) in SAMPLED_LATE:     # the input's move itself, at any step
                    element = f"{group}[{name.split('[')[1]}"
                    assert long[name] == short[name] == pytest.approx(deltas[element], rel=1e-9), (script, name)
                    continue
                assert long[name] <= 1e-6 * scale[name], (script, group, name, long[name])
            if declared and catalogue.ALL not in catalogue.FEEDTHROUGH[key].values():   # ALL: "any it may use"
                assert any(short[n] >= 0.5 * long[n] and short[n] > 1e-12 * scale[n] for n in declared), \
                    (script, group, {n: (long[n], short[n]) for n in declared})
            checked += 1
    assert checked >= 15
