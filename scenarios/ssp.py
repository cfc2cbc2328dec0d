"""A scenario as an SSP (System Structure and Parameterization 1.0) file, and a run of
that file with fmpy's SSP master: an independent master to check ours against.

``export_ssp`` writes a zip holding SystemStructure.ssd (SSP 1.0, the version
fmpy.ssp reads; SSP 2.0 where an instance is FMI 3.0: version "2.0", the same
namespaces, an FMI 3 array one connector with its ssc:Dimension, connections to single
elements by startIndices/endIndices (1-based, as FMI names the elements; SSP 2.0 leaves
the base unsaid), parameters as ssv:Float64/Int32 and Enumerations by item name; no
importer here reads SSP 2.0, see tests/scenarios/test_ssp_fmi3.py) and the FMUs under resources/: those the scenario
chose per instance
(native by default: then the SSP needs no Python in the importing tool; libcosim runs
it, tests/hosts/test_libcosim.py; the pythonfmu FMUs too, with Python in the tool). The SSD has

- one Component per FMU instance (source resources/<file>.fmu), listed in our
  initialization order (master.step_order), so a tool that initialises in document order
  (fmpy does) initialises as we do;
- Connectors: every connected input and every output of each FMU (parameters get no
  connector; SSP requires connectors only for connected variables);
- every scalar connection (vector connections expanded with spec.expand);
- the parameter values as an inline ParameterSet in a ParameterBinding per Component,
  every set named PARAMETER_SET (ecos: ``init(parameter_set="scenario")``), its
  parameters named by the FMU's variable names, in the FMU's units (SI): other FMI/SSP tools
  apply them. "@inst.var" links are resolved to numbers (the source FMU is initialised
  as single.run does and its output read at the start time), enumeration Integers are
  written as their numbers;
- the FMUs under resources/ with their Enumeration parameters declared as Integers
  (``integer_choices``: the SSP hosts set no FMI 2 Enumeration), everything else as built;
- a replayed table (the telescope's replay_table) prepared (fmu_src/replay_table.py: the
  smoothing spline both the native and the pythonfmu Telescope read) inside that
  instance's own copy of the FMU, under its resources/ as <log's name>.mbreplay, the
  parameter written as "resource:<that name>" (``carried_table``);
- Units from the FMUs' unit definitions, DefaultExperiment start/stop, and an
  annotation with our master settings (algorithm, step, extrapolation).

fmpy.ssp.simulate_ssp (fmpy 0.3.32), read in its source, differs from an SSP tool
and from our master in these ways; ``simulate_exported`` deals with each:

- it IGNORES the SSD's ParameterBindings (it parses them but applies only its
  ``parameter_set`` argument). ``simulate_exported`` reads the bindings back out of the
  SSD and passes them as ``parameter_set``, so the numbers simulated are those written.
  fmpy applies them before enterInitializationMode (the SSP rule); our master sets
  them in initialization mode: no difference for our FMUs, which compute everything in
  exitInitializationMode.
- it matches parameters to components by ``name.startswith(component)``: an instance
  name that is a prefix of another (``base``, ``base2``) breaks it; refused here.
- NO INITIAL EXCHANGE: every connector value starts at 0.0, the FMUs are initialised
  without any input set, and the first macro step [t0, t0 + h] is taken with every
  connected input 0.0. Only after the first step are outputs copied to inputs. Our
  master sets the connected inputs fed by FMUs already initialised in initialization
  mode, and steps first with the outputs at t0. ``initial_exchange=True`` adds our
  initial exchange to fmpy's run (see ``_initial_exchange``); everything else
  (parsing, connection resolution, stepping, input/output transfer) stays fmpy's.
- its set_value refuses String variables ("Unsupported type"): ``simulate_exported``
  sets them with fmi2SetString (``_string_parameters``).
- an input connector without a connection silently takes the connection of the input
  declared before it (or fails): only connected inputs are declared here.
- time: ``time += step`` accumulates, and the loop runs ``while time < stop``, so the
  number of steps can be off by one (0 -> 1.2 s at 1 ms takes 1201 steps); each row is
  labelled with the step's start time although it holds the values after the step.
  ``simulate_exported`` passes stop - h/2 (exactly round((stop - start) / h) steps; the
  FMUs never see the stop time) and labels rows with the end of the step.
- results: one row per step (no row at the start time), columns "inst.connector" of
  every declared connector; inputs show the value they get for the next step.
"""
import contextlib
import io
import math
import pathlib
import xml.etree.ElementTree as ET
import zipfile

import numpy as np

from fmu_src import atomic, replay_table
from plant.telescope.replay import PREPARED_SUFFIX, RESOURCE, SMOOTHING_TIME
from scenarios import spec
from scenarios.cosim.fmi import element_count, unpack
from scenarios.cosim.master import start, step_order
from scenarios.spec import Link, expand

SSD = "http://ssp-standard.org/SSP1/SystemStructureDescription"
SSC = "http://ssp-standard.org/SSP1/SystemStructureCommon"
SSV = "http://ssp-standard.org/SSP1/SystemStructureParameterValues"
MB = "urn:movingbase:scenario"
for _prefix, _uri in (("ssd", SSD), ("ssc", SSC), ("ssv", SSV), ("mb", MB)):
    ET.register_namespace(_prefix, _uri)
FMU_TYPE = "application/x-fmu-sharedlibrary"
# the one name of every Component's inline parameter set: ecos applies only the sets named
# at its init (each Component's set named after its instance, it applied none and ran on
# the FMUs' defaults); libcosim and fmpy apply them whatever their name
PARAMETER_SET = "scenario"
_BASE_UNIT = ("kg", "m", "s", "A", "K", "mol", "cd", "rad")


def _q(namespace, tag):
    return f"{{{namespace}}}{tag}"


def _double(value):
    """An xs:double literal that reads back to the same float."""
    value = float(value)
    if math.isnan(value):
        return "NaN"
    if math.isinf(value):
        return "INF" if value > 0 else "-INF"
    return repr(value)


# ------------------------------------------------------------------------- parameters
def resolve_links(scenario, fmu_paths, parameters):
    """``parameters`` (instance -> {variable: value}) with every ``Link`` replaced by its
    number, read by initialising the instances exactly as single.run does (master.start).
    Nothing is instantiated without links."""
    if not any(isinstance(v, Link) for values in parameters.values() for v in values.values()):
        return {inst: dict(values) for inst, values in parameters.items()}
    instances = {}
    try:
        return start(scenario, fmu_paths, parameters, instances)[1]
    finally:
        for instance in instances.values():
            instance.terminate()


def _typed(inst, variable, value, fmi3=False):
    """(SSV type tag, value literal) of a parameter value for an FMU variable (FMI 2.0,
    or FMI 3.0: Float64, Int32, an Enumeration by its item's name as SSP 2.0 writes it)."""
    kind = variable.type
    if kind in ("Real", "Float64"):
        return kind, _double(value)
    if kind == "Int32":
        return kind, str(int(value))
    if kind == "Enumeration" and fmi3 and not isinstance(value, str):
        items = {int(item.value): item.name for item in variable.declaredType.items}
        if int(value) not in items:
            raise ValueError(f"{inst}.{variable.name}: {value!r} is not one of the items {items}")
        return "Enumeration", items[int(value)]
    if kind in ("Integer", "Enumeration"):
        if isinstance(value, str):   # an enumeration name, as in a scenario file
            choices = spec.enumeration(variable)
            if value not in choices:
                raise ValueError(f"{inst}.{variable.name}: {value!r} is not one of {', '.join(choices)}")
            value = choices[value]
        if isinstance(value, float) and not value.is_integer():
            raise ValueError(f"{inst}.{variable.name}: Integer parameter given {value!r}")
        return "Integer", str(int(value))
    if kind == "Boolean":
        return "Boolean", "true" if value else "false"
    if kind == "String":
        return "String", str(value)
    raise ValueError(f"{inst}.{variable.name}: unsupported type {kind}")


# ----------------------------------------------------------------------------- export
def scalar_connections(scenario, variables):
    """[(source inst, source var, target inst, target var)] of every scalar connection."""
    pairs = []
    for source, targets in scenario.connections:
        s_inst = source.split(".", 1)[0]
        for target in targets:
            t_inst = target.split(".", 1)[0]
            s_names, t_names = expand(variables[s_inst], source), expand(variables[t_inst], target)
            if not s_names or len(s_names) != len(t_names):
                raise ValueError(f"connection {source} -> {target}: sizes {len(s_names)} and {len(t_names)}")
            pairs += [(s_inst, s, t_inst, t) for s, t in zip(s_names, t_names)]
    return pairs


def connector_of(md):
    """element name (as fmi.description names it) -> (the FMU's variable, 1-based index
    into it or None for a scalar): an FMI 3 array is one connector, its elements are
    indices; an FMI 2 FMU's variables are their own connectors."""
    if not md.fmiVersion.startswith("3"):
        return {v.name: (v, None) for v in md.modelVariables}
    out = {}
    for var in md.modelVariables:
        if var.causality == "independent":
            continue
        count = element_count(var)
        for k in range(count):
            out[f"{var.name}[{k + 1}]" if var.dimensions else var.name] = (var, k + 1 if var.dimensions else None)
    return out


def _connections(pairs, where):
    """SSD Connection attributes of the scalar ``pairs``: a whole array fed element by
    element in order from a whole array of the same size is one connection without
    indices; every other element its own connection, an array side named by its 1-based
    index (SSP 2.0 startIndices/endIndices; one index per dimension, ours are 1-D)."""
    groups = {}
    for s_inst, s, t_inst, t in pairs:
        (s_var, s_k), (t_var, t_k) = where[s_inst][s], where[t_inst][t]
        groups.setdefault((s_inst, s_var.name, t_inst, t_var.name), []).append((s_var, s_k, t_var, t_k))
    out = []
    for (s_inst, s_name, t_inst, t_name), items in groups.items():
        s_var, t_var = items[0][0], items[0][2]
        whole = list(range(1, element_count(s_var) + 1))
        base = {"startElement": s_inst, "startConnector": s_name, "endElement": t_inst, "endConnector": t_name}
        if s_var.dimensions and t_var.dimensions and [i[1] for i in items] == [i[3] for i in items] == whole \
                and element_count(t_var) == len(whole):
            out.append(base)
            continue
        for _, s_k, _, t_k in items:
            out.append({**base, **({"startIndices": str(s_k)} if s_k else {}),
                        **({"endIndices": str(t_k)} if t_k else {})})
    return out


def build_ssd(scenario, fmu_paths, parameters, sources):
    """The SystemStructureDescription element; ``parameters`` without links,
    ``sources``: instance -> path of its FMU inside the SSP. SSP 1.0 when every FMU is
    FMI 2.0; SSP 2.0 (the same namespaces, version "2.0") when any is FMI 3.0: its
    connectors are its variables, an array one connector with its Dimension."""
    mds = {inst: unpack(fmu_paths[inst])[0] for inst in scenario.fmus}
    where = {inst: connector_of(md) for inst, md in mds.items()}
    version = "2.0" if any(md.fmiVersion.startswith("3") for md in mds.values()) else "1.0"
    pairs = scalar_connections(scenario, {inst: dict.fromkeys(w) for inst, w in where.items()})
    connected_inputs = {(t_inst, where[t_inst][t][0].name) for _, _, t_inst, t in pairs}

    root = ET.Element(_q(SSD, "SystemStructureDescription"),
                      {"version": version, "name": scenario.name, "generationTool": "movingbase scenarios.ssp"})
    if scenario.description:
        root.set("description", scenario.description)
    system = ET.SubElement(root, _q(SSD, "System"), {"name": scenario.name})
    elements = ET.SubElement(system, _q(SSD, "Elements"))
    units = {}
    for inst in step_order(scenario, parameters):
        component = ET.SubElement(elements, _q(SSD, "Component"),
                                  {"name": inst, "type": FMU_TYPE, "source": sources[inst]})
        connectors = ET.SubElement(component, _q(SSD, "Connectors"))
        declared = [v for v in mds[inst].modelVariables if (inst, v.name) in connected_inputs] + \
                   [v for v in mds[inst].modelVariables if v.causality == "output"]
        for var in declared:
            connector = ET.SubElement(connectors, _q(SSD, "Connector"), {"name": var.name, "kind": var.causality})
            kind = "Integer" if var.type == "Enumeration" else var.type
            unit = var.unit or getattr(var.declaredType, "unit", None)     # FMI 3: the unit by its Float64Type
            attributes = {"unit": unit} if var.type in ("Real", "Float64") and unit else {}
            ET.SubElement(connector, _q(SSC, kind), attributes)
            for dimension in var.dimensions or []:
                ET.SubElement(connector, _q(SSC, "Dimension"), {"size": str(int(dimension.start))})
            if attributes:
                units[unit] = next((u for u in mds[inst].unitDefinitions if u.name == unit), None)
        values = parameters.get(inst, {})
        if values:
            binding = ET.SubElement(ET.SubElement(component, _q(SSD, "ParameterBindings")),
                                    _q(SSD, "ParameterBinding"))
            holder = ET.SubElement(binding, _q(SSD, "ParameterValues"))
            pset = ET.SubElement(holder, _q(SSV, "ParameterSet"), {"version": version, "name": PARAMETER_SET})
            plist = ET.SubElement(pset, _q(SSV, "Parameters"))
            for name, value in values.items():
                if isinstance(value, Link):
                    raise ValueError(f"{inst}.{name}: unresolved link {value}; call resolve_links first")
                if name not in where[inst]:
                    raise ValueError(f"{inst}: FMU {sources[inst]} has no variable {name!r}")
                var, index = where[inst][name]
                if index is not None:
                    raise ValueError(f"{inst}.{name}: an element of the FMI 3 array {var.name}; array "
                                     "parameters are not written")
                tag, literal = _typed(inst, var, value, version == "2.0" and mds[inst].fmiVersion.startswith("3"))
                ET.SubElement(ET.SubElement(plist, _q(SSV, "Parameter"), {"name": name}),
                              _q(SSV, tag), {"value": literal})
    connections = ET.SubElement(system, _q(SSD, "Connections"))
    for attributes in _connections(pairs, where):
        ET.SubElement(connections, _q(SSD, "Connection"), attributes)
    annotation = ET.SubElement(ET.SubElement(system, _q(SSD, "Annotations")), _q(SSC, "Annotation"),
                               {"type": "movingbase.scenario"})
    ET.SubElement(annotation, _q(MB, "Master"), {"algorithm": scenario.master, "step": _double(scenario.step),
                                                 "extrapolation": scenario.extrapolation,
                                                 "scenario": pathlib.Path(str(scenario.source)).name})
    defined = {name: unit for name, unit in units.items() if unit is not None}
    if defined:
        unit_list = ET.SubElement(root, _q(SSD, "Units"))
        for name in sorted(defined):
            base = defined[name].baseUnit
            attributes = {k: str(getattr(base, k)) for k in _BASE_UNIT if getattr(base, k, 0)}
            if base.factor != 1.0:
                attributes["factor"] = _double(base.factor)
            if base.offset != 0.0:
                attributes["offset"] = _double(base.offset)
            ET.SubElement(ET.SubElement(unit_list, _q(SSC, "Unit"), {"name": name}), _q(SSC, "BaseUnit"), attributes)
    ET.SubElement(root, _q(SSD, "DefaultExperiment"),
                  {"startTime": _double(scenario.start_time), "stopTime": _double(scenario.stop_time)})
    return root


def export_ssp(scenario, fmu_paths, parameters, path):
    """Write ``scenario`` with ``parameters`` (instance -> {variable: value}, as from
    spec.bind, possibly with a sweep value set; links allowed) as an SSP 1.0 zip at
    ``path``: SystemStructure.ssd plus resources/<file>.fmu. Returns the path.

    The parameter values are written as SSD ParameterBindings (inline ParameterSets per
    Component), which SSP tools apply; fmpy.ssp.simulate_ssp ignores them: run the file
    with ``simulate_exported``, which passes them to fmpy as ``parameter_set``."""
    path = pathlib.Path(path)
    files, sources, tables, prepared = {}, {}, {}, {}
    parameters = dict(parameters)
    for inst, given in parameters.items():   # prepared before the FMUs start (resolve_links): the native read it
        table = given.get("replay_table")
        if table and not isinstance(table, Link):
            smoothing = given.get("replay_smoothing", SMOOTHING_TIME)
            prepared[inst] = (pathlib.Path(table).stem + PREPARED_SUFFIX,
                              replay_table.prepared(table, replay_table.params_of(given), smoothing))
            parameters[inst] = {**given, "replay_table": str(prepared[inst][1])}
    values = resolve_links(scenario, fmu_paths, parameters)
    for inst in scenario.fmus:
        fmu = pathlib.Path(fmu_paths[inst]).resolve()
        name = f"resources/{fmu.name}"
        if inst in prepared:   # the prepared table goes into this instance's own copy of the FMU (carried_table)
            values[inst] = {**values[inst], "replay_table": RESOURCE + prepared[inst][0]}
            name = f"resources/{inst}_{fmu.name}"
            tables[name] = prepared[inst]
        if files.get(name, fmu) != fmu:   # another FMU file of the same name
            name = f"resources/{inst}_{fmu.name}"
        files[name] = fmu
        sources[inst] = name
    root = build_ssd(scenario, fmu_paths, values, sources)
    ET.indent(root)
    text = ET.tostring(root, encoding="utf-8", xml_declaration=True)
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic.replacing(path) as file, zipfile.ZipFile(file, "w") as z:   # a full disk keeps the old SSP
        z.writestr("SystemStructure.ssd", text, compress_type=zipfile.ZIP_DEFLATED)
        for name, fmu in files.items():
            data = integer_choices(fmu) if unpack(fmu)[0].fmiVersion.startswith("2") else fmu.read_bytes()
            if name in tables:
                data = carried_table(data, *tables[name])
            z.writestr(name, data, compress_type=zipfile.ZIP_STORED)   # an FMU is a zip already
    return path


def carried_table(fmu_bytes, name, table):
    """The FMU's bytes with the file ``table`` added as resources/<name>: the SSP carries
    the file, and the telescope reads it as replay_table = "resource:<name>" wherever the
    importing tool unpacks the FMU (a path of the exporting machine would mean nothing there)."""
    out = io.BytesIO()
    with zipfile.ZipFile(io.BytesIO(fmu_bytes)) as source, zipfile.ZipFile(out, "w") as z:
        for info in source.infolist():
            z.writestr(info, source.read(info))
        z.writestr(f"resources/{name}", pathlib.Path(table).read_bytes(), compress_type=zipfile.ZIP_DEFLATED)
    return out.getvalue()


def integer_choices(fmu):
    """The FMU's bytes with its Enumeration parameters declared as the Integers they are
    in FMI 2.0 (same value reference, fmi2SetInteger, start, min, max; the item names stay
    in the description and TypeDefinitions): libcosim 0.0.6 ignores an ssv:Integer binding
    on an Enumeration without a word and aborts on an ssv:Enumeration, ecos 0.7.2 registers
    no Enumeration variable, so an SSP of Enumerations ran on the FMUs' default choices."""
    with zipfile.ZipFile(fmu) as z:
        entries = [(info, z.read(info)) for info in z.infolist()]
    out = io.BytesIO()
    with zipfile.ZipFile(out, "w") as z:
        for info, data in entries:
            if info.filename == "modelDescription.xml":
                root = ET.fromstring(data)
                for kind in root.iterfind("ModelVariables/ScalarVariable/Enumeration"):
                    kind.tag = "Integer"
                    del kind.attrib["declaredType"]
                data = ET.tostring(root, encoding="utf-8", xml_declaration=True)
            z.writestr(info, data)
    return out.getvalue()


# ------------------------------------------------------------------------ fmpy's run
def bound_parameters(ssp_path):
    """The SSD's ParameterBindings as an fmpy ParameterSet with names "component.variable"
    (what simulate_ssp's ``parameter_set`` expects). Only inline and SSV-file bindings
    of top-level Components without prefix or mapping are supported (what export_ssp writes)."""
    from fmpy.ssp.ssd import Parameter, ParameterSet, find_components, read_ssd
    ssd = read_ssd(str(ssp_path))
    parameters = []
    for component in find_components(ssd.system):
        if component.parent is not ssd.system:
            raise ValueError(f"{component.name}: nested systems are not supported")
        for binding in component.parameterBindings:
            if binding.prefix or binding.parameterMapping:
                raise ValueError(f"{component.name}: parameter binding with prefix or mapping not supported")
            for parameter_set in binding.parameterValues:
                for p in parameter_set.parameters:
                    parameters.append(Parameter(name=f"{component.name}.{p.name}", type=p.type, value=p.value))
    return ParameterSet(name=ssd.name, parameters=parameters), [c.name for c in find_components(ssd.system)]


@contextlib.contextmanager
def _string_parameters():
    """Within the block, fmpy.ssp's set_value sets String variables (fmi2SetString), which
    it refuses as "Unsupported type" (the telescope's replay_table)."""
    from fmpy.ssp import simulation
    original = simulation.set_value

    def set_value(component, name, value):
        variable = component.variables[name]
        if variable.type != "String":
            return original(component, name, value)
        component.fmu.setString([variable.valueReference], [str(value)])

    simulation.set_value = set_value
    try:
        yield
    finally:
        simulation.set_value = original


@contextlib.contextmanager
def _initial_exchange():
    """Within the block, fmpy.ssp.simulate_ssp initialises as our master does: each
    component (in the SSD's order) gets, before its initialization, the connected inputs
    fed by components already initialised (values read from fmpy's own instances), and
    after the last one every connection is applied once, so the first macro step sees
    the outputs at the start time instead of 0.0. Done by wrapping fmpy's
    instantiate_fmu; fmpy's stepping loop is untouched."""
    from fmpy.ssp import simulation
    from fmpy.ssp.ssd import Parameter, ParameterSet, find_components, get_connections
    original = simulation.instantiate_fmu

    def instantiate(component, ssp_unzipdir, start_time, stop_time=None, parameter_set=None):
        system = component.parent
        connections = get_connections(system)
        source_of = {end: start for start, end in connections}
        components = find_components(system)
        ready = [c for c in components if getattr(c, "fmu", None) is not None]
        start_inputs = [Parameter(name=f"{component.name}.{c.name}", value=source_of[c].value)
                        for c in component.connectors
                        if c.kind == "input" and c in source_of and any(source_of[c].parent is r for r in ready)]
        merged = ParameterSet(parameters=list(parameter_set.parameters if parameter_set else []) + start_inputs)
        original(component, ssp_unzipdir, start_time, stop_time, merged)
        for connector in component.connectors:
            if connector.kind == "output":
                connector.value = simulation.get_value(component, connector.name)
        if all(getattr(c, "fmu", None) is not None for c in components):
            for start, end in connections:
                end.value = start.value

    simulation.instantiate_fmu = instantiate
    try:
        yield
    finally:
        simulation.instantiate_fmu = original


def experiment(ssp_path):
    """(start, step, stop) [s] of an SSP written by export_ssp: its DefaultExperiment and
    the step of its master annotation (what a host must be told: SSP 1.0 has no step)."""
    with zipfile.ZipFile(ssp_path) as z:
        root = ET.fromstring(z.read("SystemStructure.ssd"))
    run = root.find(_q(SSD, "DefaultExperiment"))
    master = root.find(f"{_q(SSD, 'System')}/{_q(SSD, 'Annotations')}/{_q(SSC, 'Annotation')}/{_q(MB, 'Master')}")
    if run is None or master is None:
        raise ValueError(f"{ssp_path}: not an SSP of this kit (no DefaultExperiment or movingbase master annotation); "
                         "give start, step and stop yourself")
    return float(run.get("startTime")), float(master.get("step")), float(run.get("stopTime"))


def simulate_exported(ssp_path, scenario, initial_exchange=False):
    """Run an SSP written by export_ssp with fmpy.ssp.simulate_ssp: start/step/stop of
    ``scenario``, parameters from the SSD's bindings passed as ``parameter_set``.

    ``initial_exchange=False`` is fmpy as it is (first step with all connected inputs 0.0,
    see the module doc); True adds our master's initialization (``_initial_exchange``).
    fmpy's master is always plain Jacobi: ``scenario.master`` and ``scenario.extrapolation``
    are not reproduced (compare with our master run as jacobi, extrapolation none).

    Returns fmpy's structured array (one row per step, columns "inst.connector") with
    "time" the END of each step (the time the values belong to: t0 + (k+1) h) and fmpy's
    own label, the step's start time accumulated by repeated addition, as "fmpy_time"."""
    from fmpy.ssp.simulation import simulate_ssp
    from numpy.lib import recfunctions
    with zipfile.ZipFile(ssp_path) as z:
        version = ET.fromstring(z.read("SystemStructure.ssd")).get("version")
    if version != "1.0":
        raise ValueError(f"{ssp_path}: SSP {version} (it holds FMI 3.0 FMUs); fmpy's SSP master runs SSP 1.0 with "
                         "FMI 2.0 FMUs: export the scenario with fmi_version = 2 to run it here")
    parameter_set, names = bound_parameters(ssp_path)
    clash = [(a, b) for a in names for b in names if a != b and b.startswith(a)]
    if clash:
        raise ValueError(f"fmpy matches parameters by name prefix: instance {clash[0][0]!r} is a prefix of "
                         f"{clash[0][1]!r}; rename one")
    t0, h = scenario.start_time, scenario.step
    steps = int(round((scenario.stop_time - t0) / h))
    with _initial_exchange() if initial_exchange else contextlib.nullcontext(), _string_parameters():
        result = simulate_ssp(str(ssp_path), start_time=t0, stop_time=t0 + (steps - 0.5) * h, step_size=h,
                              parameter_set=parameter_set)
    if len(result) != steps:
        raise RuntimeError(f"fmpy took {len(result)} steps, expected {steps}")
    result = recfunctions.rename_fields(result, {"time": "fmpy_time"})
    return recfunctions.append_fields(result, "time", t0 + h * np.arange(1, steps + 1), usemask=False)
