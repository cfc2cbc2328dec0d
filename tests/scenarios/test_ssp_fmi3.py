"""SSP 2.0 export of scenarios with FMI 3.0 instances (scenarios/ssp.py).

No importer here runs SSP 2.0: ecos 0.7.2 refuses version "2.0" (and, with a 1.0 header,
the ssv:Float64 parameters), fmpy 0.3.32's SSP master reads SSP 1.0 with FMI 2.0 FMUs, and
libcosim has no FMI 3. So the file is checked against the standard itself and against
the SSP 1.0 export of the same scenario, which those three run (tests/scenarios/test_ssp.py,
test_ecos.py, test_libcosim.py):

- the normative XML schemas of SSP 2.0 accept the SSD (modelica/ssp-standard, schema/,
  2.0.1-rc.2, commit a83fcb5): where MB_SSP2_SCHEMA names a folder holding them. They are
  not in this repository (we commit no file of a repository we do not maintain), so that
  test skips without them;
- the standard's rules the schema cannot say (docs/5___ssd.adoc): a connector names a
  variable of its FMU (read with fmpy from the FMU inside the SSP), its kind is that
  variable's causality, its type the variable's type, its Dimension the variable's
  dimensions; a connection's indices lie inside the connector's size, and a scalar
  connector has none;
- element for element, the connections and parameter values are those of the SSP 1.0
  export of the same scenario with FMI 2.0 FMUs."""
import os
import pathlib
import zipfile

import pytest
from fmpy import read_model_description
from lxml import etree

from scenarios import spec, ssp
from scenarios.runs import runner

SCHEMA_FOLDER = os.environ.get("MB_SSP2_SCHEMA")
NS = {"ssd": ssp.SSD, "ssc": ssp.SSC, "ssv": ssp.SSV}


def export(tmp_path, versions, name="keyhole_tracking"):
    """The scenario's [ci] run, instance -> FMI version as ``versions`` says (default 2),
    exported; returns (SSP path, parsed SSD)."""
    scenario = spec.load(runner.resolve(name))
    scenario = spec.load(runner.resolve(name), overrides=scenario.ci)
    scenario.fmi_versions = {inst: versions.get(inst, 2) for inst in scenario.fmus}
    scenario, paths, descriptions, values = runner.prepare_loaded(scenario)
    if scenario.sweep:
        inst, variable, value = spec.sweep_value(scenario, descriptions, scenario.sweep[1][0])
        values[inst][variable] = value
    label = "-".join(f"{i}{v}" for i, v in sorted(scenario.fmi_versions.items()))
    path = ssp.export_ssp(scenario, paths, values, tmp_path / f"{label}.ssp")
    with zipfile.ZipFile(path) as z:
        return path, etree.fromstring(z.read("SystemStructure.ssd"))


def fmu_variables(path, ssd):
    """component -> {variable name: fmpy's variable} of the FMU the SSP holds for it."""
    out = {}
    with zipfile.ZipFile(path) as z:
        folder = path.parent / (path.stem + "_unpacked")
        z.extractall(folder)
    for component in ssd.iterfind(".//ssd:Component", NS):
        md = read_model_description(str(folder / component.get("source")))
        out[component.get("name")] = (md, {v.name: v for v in md.modelVariables})
    return out


def element_connections(path, ssd):
    """The connections element by element, named as FMI 2.0 names the elements
    (an FMI 3 array connector's index i is name[i]); the standard's rules checked."""
    fmus = fmu_variables(path, ssd)
    sizes = {}
    for component in ssd.iterfind(".//ssd:Component", NS):
        md, variables = fmus[component.get("name")]
        for connector in component.iterfind("ssd:Connectors/ssd:Connector", NS):
            var = variables[connector.get("name")]              # names a variable of its FMU
            assert connector.get("kind") == var.causality, connector.get("name")
            kind = etree.QName(connector[0]).localname
            assert kind == ("Integer" if var.type == "Enumeration" else var.type), connector.get("name")
            dims = [int(d.get("size")) for d in connector.iterfind("ssc:Dimension", NS)]
            assert dims == [int(d.start) for d in (var.dimensions or [])], connector.get("name")
            sizes[component.get("name"), connector.get("name")] = dims
    out = []
    for c in ssd.iterfind(".//ssd:Connection", NS):
        ends = []
        for side in ("start", "end"):
            key = (c.get(f"{side}Element"), c.get(f"{side}Connector"))
            assert key in sizes, key                           # a declared connector
            indices = c.get(f"{side}Indices")
            if not sizes[key]:
                assert indices is None, key                   # a scalar has no indices
                ends.append([f"{key[0]}.{key[1]}"])
            elif indices is None:                             # the whole array
                ends.append([f"{key[0]}.{key[1]}[{i + 1}]" for i in range(sizes[key][0])])
            else:
                index = [int(i) for i in indices.split()]
                assert len(index) == len(sizes[key]) and all(1 <= i <= n for i, n in zip(index, sizes[key])), key
                ends.append([f"{key[0]}.{key[1]}[{index[0]}]"])
        assert len(ends[0]) == len(ends[1])
        out += list(zip(*ends))
    return out


def parameters(ssd, fmus=None):
    """{(component, parameter): value}, an Enumeration's item name as its number."""
    out = {}
    for component in ssd.iterfind(".//ssd:Component", NS):
        for p in component.iterfind(".//ssv:Parameter", NS):
            kind, value = etree.QName(p[0]).localname, p[0].get("value")
            if kind == "Enumeration":
                var = fmus[component.get("name")][1][p.get("name")]
                value = next(int(item.value) for item in var.declaredType.items if item.name == value)
            out[component.get("name"), p.get("name")] = float(value)
    return out


@pytest.mark.parametrize("versions", [{"base": 3, "plant": 3, "controller": 3}, {"plant": 3}],
                         ids=["all-fmi3", "plant-fmi3"])
def test_ssp2_export_is_valid_and_says_what_the_ssp1_export_says(versions, tmp_path):
    path1, ssd1 = export(tmp_path, {})
    path2, ssd2 = export(tmp_path, versions)
    assert ssd1.get("version") == "1.0" and ssd2.get("version") == "2.0"
    assert {p.get("version") for p in ssd2.iterfind(".//ssv:ParameterSet", NS)} == {"2.0"}
    arrays = ssd2.findall(".//ssd:Connector/ssc:Dimension", NS)
    assert arrays and all(d.get("size") == "6" for d in arrays)            # leg_force and the leg vectors
    connections = element_connections(path2, ssd2)
    assert sorted(connections) == sorted(element_connections(path1, ssd1))
    assert len(connections) == len(set(connections))
    if versions.get("controller") != 3:        # the FMI 2 controller's scalars feed the FMI 3 plant's array
        assert ssd2.find(".//ssd:Connection[@endConnector='leg_force'][@endIndices='6']", NS) is not None
    else:                                      # array to array: one connection
        assert len(ssd2.findall(".//ssd:Connection[@endConnector='leg_force']", NS)) == 1
    assert parameters(ssd2, fmu_variables(path2, ssd2)) == parameters(ssd1)
    assert ssd2.find(".//ssv:Enumeration", NS) is not None


@pytest.mark.skipif(not SCHEMA_FOLDER, reason="MB_SSP2_SCHEMA (the SSP 2.0 XSD folder) not set")
@pytest.mark.parametrize("versions", [{"base": 3, "plant": 3, "controller": 3}, {"plant": 3}, {}],
                         ids=["all-fmi3", "plant-fmi3", "ssp1-fmi2"])
def test_exports_validate_against_the_ssp2_schemas(versions, tmp_path):
    """The SSP 2.0 files, and the SSP 1.0 file (FMI 2.0 FMUs), which the standard says
    stays valid, against the standard's own schemas."""
    schema = etree.XMLSchema(etree.parse(str(pathlib.Path(SCHEMA_FOLDER) / "SystemStructureDescription.xsd")))
    assert schema.validate(export(tmp_path, versions)[1]), schema.error_log


def test_command_line_writes_ssp2_where_an_instance_is_fmi3(tmp_path):
    """`movingbase run --ssp` of a scenario file choosing fmi_version = 3 for one
    instance writes SSP 2.0 holding that instance's FMI 3.0 FMU."""
    from movingbase.cli import run_command as main
    text = (runner.SHIPPED / "keyhole_tracking.toml").read_text()
    scene = tmp_path / "scene.toml"
    scene.write_text(text.replace("[fmus.plant]", "[fmus.plant]\nfmi_version = 3", 1))
    main(["--ssp", str(tmp_path / "scene.ssp"), str(scene)])
    with zipfile.ZipFile(tmp_path / "scene.ssp") as z:
        ssd = etree.fromstring(z.read("SystemStructure.ssd"))
        source = ssd.find(".//ssd:Component[@name='plant']", NS).get("source")
        assert b'fmiVersion="3.0"' in zipfile.ZipFile(z.open(source)).read("modelDescription.xml")
    assert ssd.get("version") == "2.0"


def test_fmpy_run_of_an_ssp2_file_is_refused_by_name(tmp_path):
    """fmpy 0.3.32 runs SSP 1.0 with FMI 2.0 FMUs: simulate_exported refuses an SSP 2.0
    file with the reason and the remedy, before fmpy sees it."""
    path, _ = export(tmp_path, {"plant": 3})
    scenario = spec.load(runner.resolve("keyhole_tracking"))
    with pytest.raises(ValueError, match=r"SSP 2.0 .*fmpy's SSP master runs SSP 1.0 .*fmi_version = 2"):
        ssp.simulate_exported(path, scenario)
