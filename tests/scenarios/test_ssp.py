"""SSP export and the cross-check of our master against fmpy's SSP master.

The shipped telescope_slew scenario (its [ci] settings, shortened to 1 s, the slew
starting at 0.5 s so that the base moves, feedforward = moving_base) is exported as an
SSP and run by fmpy.ssp.simulate_ssp and by our Jacobi master. fmpy as it is has no
initial exchange (first step with every connected input 0.0), which this kit's controller
cannot step from (singular reference pose), see test_fmpy_as_is_*; with our initial
exchange added (scenarios.ssp._initial_exchange) fmpy's loop reproduces our master.
"""
import dataclasses
import io
import multiprocessing
import zipfile

import numpy as np
import pytest
from fmpy.fmi1 import FMICallException
from fmpy.ssp.ssd import read_ssd, validate_tree
from lxml import etree

from scenarios import spec, ssp
from scenarios.cosim import master
from scenarios.cosim.fmi import FmuError, Instance
from scenarios.runs import single
from tests.ssp_helpers import RECORD, columns, configure, run_columns

NS = {"ssd": ssp.SSD, "ssc": ssp.SSC, "ssv": ssp.SSV}


@pytest.fixture(scope="module")
def case(fmus, tmp_path_factory):
    scenario, paths, descriptions, params = configure(fmus)
    folder = tmp_path_factory.mktemp("ssp")
    return scenario, paths, descriptions, params, ssp.export_ssp(scenario, paths, params, folder / "slew.ssp"), folder


# ------------------------------------------------------------------------------- SSD
def test_ssd_is_valid_and_names_every_component_connection_and_parameter(case):
    scenario, paths, descriptions, params, path, _ = case
    with zipfile.ZipFile(path) as z:
        names = set(z.namelist())
        root = etree.fromstring(z.read("SystemStructure.ssd"))
        fmu_bytes = {n: z.read(n) for n in names if n.startswith("resources/")}
    validate_tree(root, "SystemStructureDescription.xsd")     # the SSP 1.0 schema fmpy ships
    assert root.get("version") == "1.0"
    ssd = read_ssd(str(path))                                   # and fmpy reads it

    components = {c.get("name"): c for c in root.iterfind("ssd:System/ssd:Elements/ssd:Component", NS)}
    assert set(components) == set(scenario.fmus)
    assert list(components) == master.step_order(scenario, params)   # fmpy initialises in document order
    for inst, component in components.items():
        source = component.get("source")
        assert fmu_bytes[source] == ssp.integer_choices(paths[inst])
        # the FMU as built, but for its choice parameters, declared as the Integers they are in FMI
        with zipfile.ZipFile(paths[inst]) as built, zipfile.ZipFile(io.BytesIO(fmu_bytes[source])) as inside:
            assert built.namelist() == inside.namelist()
            assert all(built.read(n) == inside.read(n) for n in built.namelist() if n != "modelDescription.xml")
            before, after = (etree.fromstring(z.read("modelDescription.xml")) for z in (built, inside))
        choices = [
            v.get("name") for v in before.iterfind("ModelVariables/ScalarVariable") if v.find("Enumeration") is not None
        ]
        assert choices and not after.findall("ModelVariables/ScalarVariable/Enumeration")
        for name in choices:
            (was,) = before.findall(f"ModelVariables/ScalarVariable[@name='{name}']/Enumeration")
            (now,) = after.findall(f"ModelVariables/ScalarVariable[@name='{name}']/Integer")
            assert {k: v for k, v in was.attrib.items() if k != "declaredType"} == dict(now.attrib)

    # every scalar connection, each end a declared connector of the right kind
    expected = set()
    for source, targets in scenario.connections:
        s_inst = source.split(".", 1)[0]
        s_vars = {v.name for v in descriptions[s_inst].modelVariables}
        for target in targets:
            t_inst = target.split(".", 1)[0]
            t_vars = {v.name for v in descriptions[t_inst].modelVariables}
            pairs = list(zip(spec.expand(s_vars, source), spec.expand(t_vars, target)))
            assert pairs and len(pairs) == len(spec.expand(t_vars, target))
            expected |= {(s_inst, s, t_inst, t) for s, t in pairs}
    written = [(c.get("startElement"), c.get("startConnector"), c.get("endElement"), c.get("endConnector"))
               for c in root.iterfind("ssd:System/ssd:Connections/ssd:Connection", NS)]
    assert len(written) == len(set(written)) and set(written) == expected
    assert len(expected) == 6 * 12      # 9 vector connections, 3 of them to two targets
    kinds = {(inst, c.get("name")): c.get("kind")
             for inst, comp in components.items() for c in comp.iterfind("ssd:Connectors/ssd:Connector", NS)}
    for s_inst, s, t_inst, t in expected:
        assert kinds[(s_inst, s)] == "output" and kinds[(t_inst, t)] == "input"
    connected = {(t_inst, t) for _, _, t_inst, t in expected}
    assert {k for k,
            kind in kinds.items() if kind == "input"} == connected   # fmpy needs every declared input connected
    for inst in scenario.fmus:
        outputs = {v.name for v in descriptions[inst].modelVariables if v.causality == "output"}
        assert {n for (i, n), kind in kinds.items() if i == inst and kind == "output"} == outputs
    defined = {u.get("name") for u in root.iterfind("ssd:Units/ssc:Unit", NS)}
    used = {r.get("unit") for r in root.iterfind(".//ssd:Connector/ssc:Real", NS) if r.get("unit")}
    assert used and used <= defined

    # parameters: inline SSV parameter sets, all of one name (ecos applies the set named
    # at its init), Integers and Enumerations as Integers, the link resolved
    reference = Instance(paths["base"], "reference")
    try:
        reference.initialize(0.0, params["base"])
        pose = [reference.get_real(f"reference_pose[{i}]") for i in range(1, 7)]
    finally:
        reference.terminate()
    for inst, component in components.items():
        sets = component.findall("ssd:ParameterBindings/ssd:ParameterBinding/ssd:ParameterValues/ssv:ParameterSet", NS)
        if not params.get(inst):
            assert not sets
            continue
        (parameter_set,) = sets
        assert parameter_set.get("name") == ssp.PARAMETER_SET
        validate_tree(parameter_set, "SystemStructureParameterValues.xsd")
        written = {}
        for p in parameter_set.iterfind("ssv:Parameters/ssv:Parameter", NS):
            (value,) = list(p)
            written[p.get("name")] = (etree.QName(value).localname, value.get("value"))
        assert set(written) == set(params[inst])
        types = {v.name: v.type for v in descriptions[inst].modelVariables}
        for name, value in params[inst].items():
            kind, literal = written[name]
            assert kind == {"Enumeration": "Integer"}.get(types[name], types[name])
            if isinstance(value, spec.Link):
                value = pose[int(name[-2]) - 1]
            assert (int(literal) if kind == "Integer" else float(literal)) == value, name
    assert components["controller"].find(".//ssv:Parameter[@name='feedforward']/ssv:Integer", NS).get("value") == "2"
    assert components["plant"].find(".//ssv:Parameter[@name='moving_base']/ssv:Integer", NS).get("value") == "1"

    # what simulate_exported hands fmpy: the same values, named component.variable
    parameter_set, _ = ssp.bound_parameters(path)
    handed = {p.name: p.value for p in parameter_set.parameters}
    assert set(handed) == {f"{i}.{n}" for i, v in params.items() for n in v}
    assert [c.name for c in ssd.system.elements] == list(components)


# ------------------------------------------------------------------ the cross-check
def test_fmpy_with_initial_exchange_agrees_with_our_jacobi_master(case):
    scenario, paths, descriptions, params, path, folder = case
    assert scenario.master == "jacobi"
    ours = run_columns(single.run(scenario, paths, params, folder, "ours"))
    theirs = ssp.simulate_exported(path, scenario, initial_exchange=True)

    steps = round(scenario.stop_time / scenario.step)
    assert len(theirs) == steps and len(ours["time"]) == steps + 1      # fmpy has no row at t0
    assert np.array_equal(theirs["time"], ours["time"][1:])
    # fmpy labels row k with the step's start, accumulated by repeated addition
    np.testing.assert_allclose(theirs["fmpy_time"], ours["time"][:-1], rtol=0, atol=1e-12)

    names = columns(scenario, descriptions, RECORD)
    assert len(names) == 30
    worst = 0.0
    for name in names:
        np.testing.assert_allclose(theirs[name], ours[name][1:], rtol=1e-9, atol=1e-12, err_msg=name)
        worst = max(worst, np.max(np.abs(theirs[name] - ours[name][1:])))
    print(f"fmpy vs ours over {steps} steps: largest difference {worst:.3g}")
    # the run is not trivial: the base moves and the loop works
    assert np.ptp(ours["base.base_pose[2]"]) > 1e-4 and np.max(np.abs(ours["controller.leg_force[1]"])) > 1e3

    # and the comparison can fail: Gauss-Seidel (a real semantic change) does not agree
    gauss = run_columns(single.run(dataclasses.replace(scenario, master="gauss-seidel"), paths, params, folder,
                                "gauss"))
    assert np.max(np.abs(gauss["controller.leg_force[1]"][1:] - theirs["controller.leg_force[1]"])) > 1.0


def test_fmpy_applies_the_integer_bindings(case, fmus):
    """The scenario's Integer parameters equal the FMUs' defaults; a non-default
    feedforward written in the SSD must change what fmpy computes."""
    scenario, *_, folder = case
    short = dataclasses.replace(scenario, stop_time=20 * scenario.step)
    runs = {}
    for mode in ("none", "moving_base"):
        s, paths, _, params = configure(fmus, mode, stop=short.stop_time)
        runs[mode] = ssp.simulate_exported(ssp.export_ssp(s, paths, params, folder / f"{mode}.ssp"), s,
                                           initial_exchange=True)
    assert (
        np.max(np.abs(runs["none"]["controller.leg_force[1]"] - runs["moving_base"]["controller.leg_force[1]"])) > 100
    )


# --------------------------------------------------- fmpy's own initialization
def _plain_fmpy(path, scenario):
    """fmpy's simulate_ssp as it is; the error message it raises."""
    try:
        ssp.simulate_exported(path, scenario)
    except FMICallException as exc:
        return str(exc)
    return "no error"


def test_fmpy_as_is_steps_first_with_zero_inputs_and_the_controller_refuses(case):
    """fmpy 0.3.32 initialises every FMU without inputs and takes the first step with
    every connected input 0.0. The controller's reference pose is then the zero pose, in
    which the hexapod is singular: it answers fmi2Discard and fmpy raises."""
    scenario, paths, descriptions, params, path, _ = case
    short = dataclasses.replace(scenario, stop_time=5 * scenario.step)
    # in a child process: fmpy does not free the FMUs of a failed run, and an unfreed
    # pythonfmu instance can corrupt the heap when its process exits
    with multiprocessing.get_context("spawn").Pool(1) as pool:
        error = pool.apply(_plain_fmpy, (path, short))
    assert "fmi2DoStep failed with status 2" in error

    # the same first step, by hand: controller initialised with its parameters only,
    # every connected input 0.0, one step from t0
    controller = Instance(paths["controller"], "by_hand")
    try:
        controller.initialize(scenario.start_time, params["controller"])
        for name, var in controller.variables.items():
            if var.causality == "input":
                controller.set(name, 0.0)
        with pytest.raises(FmuError, match="singular configuration"):
            controller.do_step(scenario.start_time, scenario.step)
    finally:
        controller.terminate()


def _fmpy_itself(path, stop, step):
    """fmpy.ssp.simulate_ssp with no project code between (no parameter set, no initial
    exchange): (error message or "no error", rows)."""
    from fmpy.ssp.simulation import simulate_ssp
    try:
        return "no error", len(simulate_ssp(str(path), stop_time=stop, step_size=step))
    except FMICallException as exc:
        return str(exc), 0


def test_plain_fmpy_simulate_ssp_stops_at_the_first_step(case):
    """The plain host: fmpy 0.3.32 writes its connectors' initial 0.0 into every connected
    input before the first doStep (fmpy/ssp/simulation.py: ``connector.value = 0.0``, then
    do_step's set_value), so the FMUs' start values (the operating point, which a host that
    steps without setting inputs does use: tests/fmu_src/test_fmu_defaults.py) never reach that step,
    and the controller refuses the zero reference pose. What a plain fmpy user meets, kept
    as a regression: it must fail at t = 0 with the controller's Discard, never run on."""
    scenario, paths, descriptions, params, path, _ = case
    with multiprocessing.get_context("spawn").Pool(1) as pool:
        error, rows = pool.apply(_fmpy_itself, (path, 5 * scenario.step, scenario.step))
    assert "fmi2DoStep failed with status 2" in error and rows == 0


def test_export_refuses_what_it_cannot_write(case):
    scenario, paths, descriptions, params, _, folder = case
    bad = {inst: dict(v) for inst, v in params.items()}
    bad["plant"]["fidelity"] = 1.5
    with pytest.raises(ValueError, match="Integer"):
        ssp.export_ssp(scenario, paths, bad, folder / "bad.ssp")


@pytest.mark.parametrize("implementation", [None, "native", "python"])
def test_command_line_exports_a_scenario(implementation, tmp_path, capsys):
    """The SSP carries the implementation asked for (the file's choice, native, by default):
    a pythonfmu FMU holds pythonfmu's wrapper behind our shim, a native one its C sources."""
    from movingbase.cli import run_command as main
    main(["telescope_slew", "--ci", "--ssp", str(tmp_path / "slew.ssp")]
         + (["--implementation", implementation] if implementation else []))
    assert "SSP written to" in capsys.readouterr().out
    with zipfile.ZipFile(tmp_path / "slew.ssp") as z:
        names = z.namelist()
        fmus = [n for n in names if n.endswith(".fmu")]
        inner = [zipfile.ZipFile(io.BytesIO(z.read(n))).namelist() for n in fmus]
    assert "SystemStructure.ssd" in names and len(fmus) == 3
    python = [any(f.endswith(".pythonfmu.so") for f in files) for files in inner]
    native = [any(f.startswith("sources/") and f.endswith(".c") for f in files) for files in inner]
    assert python == [implementation == "python"] * 3 and native == [implementation != "python"] * 3


def test_two_scenarios_for_one_ssp_file_are_refused_naming_both(tmp_path):
    """--ssp with two scenarios exported the first and dropped the second without a word."""
    from movingbase.cli import run_command as main
    with pytest.raises(SystemExit, match=r"--ssp .*two.ssp: exports one scenario, 2 given \(telescope_slew, "
                                         r"paper_manoeuvre\); run one --ssp per scenario"):
        main(["telescope_slew", "paper_manoeuvre", "--ci", "--ssp", str(tmp_path / "two.ssp")])
    assert not (tmp_path / "two.ssp").exists()
