"""Every built FMU's modelDescription declares each output's dependencies (FMI 2
ModelStructure/Outputs/Unknown, FMI 3 ModelStructure/Output) as fmu_src/catalogue.py's
feedthrough table says: an output with no direct feedthrough declares none (""), which FMI
reads as "depends on no input" (a missing attribute is "every input": OMSimulator then saw
an algebraic loop between plant and controller). Checked in the pythonfmu (FMI 2), native
FMI 2 and native FMI 3 FMUs, element by element, and by fmpy's validation."""
import xml.etree.ElementTree as ET
import zipfile

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
