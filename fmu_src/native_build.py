"""Native FMI 2.0 and FMI 3.0 co-simulation FMUs of the kit: the same variables as the
pythonfmu FMUs, compiled from C (fmu_src/native/: one model file per FMU over the
plant/controller C kernels, the instance core instance.c, and the thin FMI 2.0 or FMI 3.0
layer over it), so that a host needs no Python.

Nothing is typed twice. From the pythonfmu FMU (after fmu_src/python_build.py has added units
and ranges) this takes the modelDescription.xml (a guid of its own (_guid), generation tool,
SourceFiles, FMU-state capabilities) and, from an instance of its slave class, the exact start values;
from the Python sources of truth (StewartParams.paper(), TelescopeParams.tianma(),
mechanism3t_kernel.pack) the numbers the C needs. Both go into a generated header
<modelIdentifier>_vars.h. The binary is compiled by the machine's cc with the flags of the
cffi build (kernel_build.CFLAGS), so native and Python results agree bit for bit.
"""
import hashlib
import os
import pathlib
import shutil
import subprocess
import tempfile
import uuid
import xml.etree.ElementTree as ET
import zipfile
from concurrent.futures import ThreadPoolExecutor

import fmpy
import numpy as np

from fmu_src import atomic, catalogue

ROOT = pathlib.Path(__file__).resolve().parent.parent
NATIVE = ROOT / "fmu_src" / "native"
KERNELS = (ROOT / "plant" / "c", ROOT / "controller" / "c")
FMI_HEADERS = pathlib.Path(fmpy.__file__).parent / "c-code"
CFLAGS = ["-shared", "-fPIC", "-O2", "-std=c99", "-ffp-contract=off", "-fvisibility=hidden"]
# The FMI layer of each version, and the C every native FMU is compiled from besides its
# layer and model file: the version-neutral instance core and the models' shared checks.
LAYERS = {2: "fmi2_layer.c", 3: "fmi3_layer.c"}
SHARED = ("instance.c", "model_checks.c")
_CAUSALITY = {"parameter": "MB_PARAMETER", "input": "MB_INPUT", "output": "MB_OUTPUT", "local": "MB_LOCAL"}


def _c_literal(value):
    """A C literal that parses to exactly this double (repr round-trips)."""
    value = float(value)
    if np.isnan(value):
        return "NAN"
    if np.isinf(value):
        return "INFINITY" if value > 0 else "-INFINITY"
    text = repr(value)
    return text if any(ch in text for ch in ".en") else text + ".0"


def _array(name, values):
    values = np.asarray(values, dtype=float).ravel()
    return f"static const double {name}[{values.size}] = {{{', '.join(map(_c_literal, values))}}};"


def _stewart_constants():
    from plant.hexapod.model import FIDELITIES, SINGULAR_RATIO, StewartParams, fidelity_mode
    p = StewartParams.paper()
    modes = [fidelity_mode(f) for f in FIDELITIES]
    return [_array("BASE_JOINTS", p.base_joints), _array("PLATFORM_JOINTS", p.platform_joints),
            _array("KERNEL_DATA", p.kernel_data), _array("HOME_LENGTHS", p.home_lengths),
            f"static const double HOME_DET = {_c_literal(p.home_det)};",
            f"static const double SINGULAR_RATIO = {_c_literal(SINGULAR_RATIO)};",
            f'#define SINGULAR_RATIO_TEXT "{SINGULAR_RATIO}"',
            f"static const int FIDELITY_BASE_MODE[{len(modes)}] = {{{', '.join(str(int(m)) for m, _ in modes)}}};",
            f"static const int FIDELITY_LEGS[{len(modes)}] = {{{', '.join(str(int(bool(l))) for _, l in modes)}}};",
            _strings("FIDELITY_NAMES", FIDELITIES)]


def _strings(name, values):
    return (f"#define N_{name} {len(values)}\n"
            f"static const char *const {name}[{len(values)}] = {{{', '.join(chr(34) + v + chr(34) for v in values)}}};")


def _integrators():
    from plant.integrators import INTEGRATORS
    return [_strings("INTEGRATOR_NAMES", INTEGRATORS),
            f"enum {{ INTEGRATOR_RK4 = {INTEGRATORS.index('rk4')}, INTEGRATOR_EULER = {INTEGRATORS.index('euler')}, "
            f"INTEGRATOR_RADAU = {INTEGRATORS.index('radau')} }};"]


def _hexapod_plant():
    return _stewart_constants() + _integrators()


def _leg_sensor():
    from plant.hexapod.model import StewartParams
    return [_array("HOME_LENGTHS", StewartParams.paper().home_lengths)]


def _leg_controller():
    from controller.design import leg_mass_matrix
    from controller.feedforward import FEEDFORWARD_MODES, model_fidelity
    from fmu_src.leg_controller_fmu import OBSERVER_MODELS
    from plant.hexapod.model import FIDELITIES, StewartParams
    fid = [FIDELITIES.index(model_fidelity(m)) for m in FEEDFORWARD_MODES]
    return _stewart_constants() + [
        _strings("FEEDFORWARD_NAMES", FEEDFORWARD_MODES), _strings("OBSERVER_MODEL_NAMES", OBSERVER_MODELS),
        _array("LEG_MASS_HOME", leg_mass_matrix(StewartParams.paper())),   # the Python FMU's leg_mass
        f"static const int FEEDFORWARD_FIDELITY[{len(fid)}] = {{{', '.join(map(str, fid))}}};",
        f"enum {{ FEEDFORWARD_NONE = {FEEDFORWARD_MODES.index('none')} }};"]


def _telescope():
    from fmu_src.telescope_fmu import BLOCK, PROFILES
    from plant.hexapod.model import HOME_POSE, S_BAND_POSE
    from plant.telescope.model import TelescopeParams
    t = TelescopeParams.tianma()
    fields = ("b_y", "c_y", "b_z", "c_z")
    return [_strings("PROFILE_NAMES", PROFILES), f"#define BLOCK {BLOCK}",
            *(f"static const double TIANMA_{f.upper()} = {_c_literal(getattr(t, f))};" for f in fields),
            _array("TIANMA_HOME", t.home), _array("HOME_POSE", HOME_POSE), _array("S_BAND_POSE", S_BAND_POSE),
            f"enum {{ PROFILE_SLEW = {PROFILES.index('slew')}, PROFILE_SIDEREAL = {PROFILES.index('sidereal')}, "
            f"PROFILE_PAPER = {PROFILES.index('paper')}, PROFILE_REPLAY = {PROFILES.index('replay')} }};"]


def _mechanism3t():
    from plant.mechanism3t import kernel
    from plant.mechanism3t.model import Mechanism3TParams
    return [_array("PACKED", kernel.pack(Mechanism3TParams.paper()))] + _integrators()


def constants(identifier):
    """The C constants the native model file of ``identifier`` includes (its catalogue row
    names the generator: ``_<constants>`` here)."""
    name = catalogue.BY_IDENTIFIER[identifier].constants
    return globals()[f"_{name}"]() if name else []


def _c_name(name):
    return name.split("[", 1)[0]


def _variables(slave):
    """The slave's variables the native FMU has: all of them, Strings too (registered last
    by slave.strings, so the numeric ones keep their indices); a String must start empty
    (the native core starts every String at "")."""
    from pythonfmu.variables import String
    for var in slave.vars.values():
        if isinstance(var, String) and var.getter():
            raise RuntimeError(f"String {var.name} starts at {var.getter()!r}: the native FMUs start Strings at \"\"")
    return dict(slave.vars)


def starts(slave):
    """value reference -> start value of the slave instance's numeric variables, exactly
    (a String's: 0.0, unused; it starts at "")."""
    from pythonfmu.variables import Real, String
    return {vr: 0.0 if isinstance(var, String) else
            (slave.get_real([vr]) if isinstance(var, Real) else slave.get_integer([vr]))[0]
            for vr, var in _variables(slave).items()}


def vars_header(identifier, guid, slave, root):
    """The generated C header: guid, one VR_ constant per variable (a vector's first
    element), the variable table with exact starts and the XML's ranges, the constants."""
    xml_vars = {v.get("name"): v for v in root.iter("ScalarVariable")}
    exact = starts(slave)
    allowed = slave.allowed   # Integers whose range has gaps (slave.py)
    rows, enums, seen = [], [], {}
    for vr, var in sorted(_variables(slave).items()):
        element = xml_vars[var.name]
        kind = element[0]
        type_ = {"Real": "MB_REAL", "String": "MB_STRING"}.get(kind.tag, "MB_INTEGER")
        start = exact[vr]
        limits = [(1, _c_literal(kind.get(k))) if kind.get(k) is not None else (0, "0.0") for k in ("min", "max")]
        rows.append(f'    {{"{var.name}", "{kind.get("unit", "")}", {type_}, '
                    f'{_CAUSALITY[element.get("causality", "local")]}, {_c_literal(start)}, '
                    f"{limits[0][0]}, {limits[1][0]}, {limits[0][1]}, {limits[1][1]}, "
                    f"{len(allowed.get(var.name, ()))}, {{{', '.join(map(str, allowed.get(var.name, ()))) or '0'}}}}},")
        base = _c_name(var.name)
        index = int(var.name.split("[", 1)[1].rstrip("]")) if "[" in var.name else 1
        if base not in seen:
            seen[base] = vr
            enums.append(f"    VR_{base} = {vr},")
        elif seen[base] + index - 1 != vr:
            raise RuntimeError(f"{identifier}: elements of {base} do not have consecutive value references")
    lines = [f"/* Generated by fmu_src/native_build.py from the pythonfmu {identifier}: do not edit. */",
             f"#ifndef MB_{identifier.upper()}_VARS_H", f"#define MB_{identifier.upper()}_VARS_H",
             "#include <math.h>", '#include "model.h"', f'#define MB_IDENTIFIER "{identifier}"',
             f'#define MB_GUID "{guid}"', f"#define MB_NVARS {len(rows)}", "enum {", *enums, "};",
             "static const mb_var MB_VARS[MB_NVARS] = {", *rows, "};", *constants(identifier), "#endif", ""]
    return "\n".join(lines)


def model_description(xml_text, guid, sources, exact):
    """The pythonfmu modelDescription made the native FMU's: guid, tool, capabilities,
    SourceFiles; Real starts (``exact``: by value reference) written to round-trip
    (pythonfmu rounds them to 16 digits)."""
    root = ET.fromstring(xml_text)
    for var in root.iter("ScalarVariable"):
        real = var.find("Real")
        if real is not None and real.get("start") is not None:
            real.set("start", repr(float(exact[int(var.get("valueReference"))])))
    root.set("guid", guid)
    root.set("generationTool", "movingbase fmu_src/native_build.py (FMI 2.0 C, no Python at run time)")
    cs = root.find("CoSimulation")
    cs.set("needsExecutionTool", "false")
    cs.set("canGetAndSetFMUstate", "true")
    cs.set("canSerializeFMUstate", "true")
    files = ET.SubElement(cs, "SourceFiles")
    for name in sources:
        if name.endswith(".c"):
            ET.SubElement(files, "File", name=name)
    return root


def _sources(identifier, version=2):
    """Every C file the FMU's binary is built from (flat names, as in the FMU's sources/):
    the FMI ``version``'s layer, the core, the model file, the headers, the kernels."""
    return [NATIVE / LAYERS[version], *_shared_sources(identifier)]


def _shared_sources(identifier):
    """The C both FMI versions' binaries of a model are built from (all but the layer)."""
    model = NATIVE / catalogue.BY_IDENTIFIER[identifier].c_file
    files = [*(NATIVE / name for name in SHARED), model, *sorted(NATIVE.glob("*.h"))]
    for folder in KERNELS:
        files += sorted(folder.glob("*.c")) + sorted(folder.glob("*.h"))
    return files


def _guid(identifier, xml_text, empty):
    """The native FMUs' guid (FMI 3.0: instantiation token), from what they are made of:
    the pythonfmu modelDescription (a new one, with its own new guid, at every pythonfmu
    build) and the C both versions share. The FMI 2.0 and FMI 3.0 FMUs of one pythonfmu
    FMU, built apart, so carry the same guid, and a binary never meets a description
    made for other C."""
    digest = hashlib.sha256(xml_text.encode())
    for path in _shared_sources(identifier):
        digest.update(path.name.encode() + b"\0" + path.read_bytes())
    return "{" + str(uuid.uuid5(uuid.NAMESPACE_URL, f"movingbase:{identifier}:{int(empty)}:{digest.hexdigest()}")) + "}"


def compile_binary(source_dir, c_files, target, defines=(), link=()):
    """cc the sources into one shared library; raises with the compiler's output on failure."""
    cc = os.environ.get("CC", "cc")
    cmd = [cc, *CFLAGS, *(f"-D{d}" for d in defines), f"-I{FMI_HEADERS}", f"-I{source_dir}",
           *(str(source_dir / f) for f in c_files), "-o", str(target), "-lm", *link]
    run = subprocess.run(cmd, capture_output=True, text=True)
    if run.returncode:
        raise RuntimeError(f"compiling {target.name} failed:\n{' '.join(cmd)}\n{run.stderr}")


def build_native(python_fmu, out, empty=False):
    """The native FMU of the pythonfmu FMU ``python_fmu`` in ``out`` (same file name);
    ``empty``: the same interface with doStep and initialization doing nothing (the
    exchange floor of benchmarks/bench_native.py)."""
    python_fmu = pathlib.Path(python_fmu)
    identifier, vars_h, root2 = _from_python(python_fmu, empty)
    return _build(2, identifier, vars_h, root2, pathlib.Path(out) / python_fmu.name, empty)


def _from_python(python_fmu, empty):
    """(model identifier, generated <id>_vars.h, the native FMI 2.0 modelDescription root)
    of a pythonfmu FMU: the variable table and both versions' descriptions come from its
    modelDescription and an instance of its slave class."""
    from fmu_src import python_build as builder
    with zipfile.ZipFile(python_fmu) as z:
        xml_text = z.read("modelDescription.xml").decode()
    root = ET.fromstring(xml_text)
    identifier = root.find("CoSimulation").get("modelIdentifier")
    guid = _guid(identifier, xml_text, empty)
    slave = builder.slave_instance(python_fmu)
    names = sorted({p.name for p in _sources(identifier)} | {f"{identifier}_vars.h"})
    return identifier, vars_header(identifier, guid, slave, root), model_description(xml_text, guid, names,
                                                                                    starts(slave))


def _build(version, identifier, vars_h, root2, fmu, empty):
    """Compile the FMI ``version`` FMU ``fmu`` from the sources (the layer, the core, the
    model file, the kernels, the generated ``vars_h``) with its modelDescription (FMI 2.0:
    ``root2``; FMI 3.0: translated from it) into ``fmu``; returns its path."""
    fmu.parent.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp:
        tmp = pathlib.Path(tmp)
        sources = tmp / "sources"
        sources.mkdir()
        for f in _sources(identifier, version):
            shutil.copy(f, sources / f.name)
        (sources / f"{identifier}_vars.h").write_text(vars_h)
        if version == 3:
            (sources / "fmi3_variables.h").write_text(fmi3_variables_header(root2))
        c_files = sorted(p.name for p in sources.glob("*.c"))
        binaries = tmp / "binaries" / ("linux64" if version == 2 else fmi3_platform())
        binaries.mkdir(parents=True)
        compile_binary(sources, c_files, binaries / f"{identifier}.so", ["MB_EMPTY_MODEL"] if empty else [])
        if version == 2:
            descriptions = {"modelDescription.xml": root2}
        else:
            descriptions = {"modelDescription.xml": model_description3(root2),
                            "sources/buildDescription.xml": build_description3(identifier, c_files)}
        for name, root in descriptions.items():
            (tmp / name).write_text(ET.tostring(root, encoding="unicode", xml_declaration=True))
        return pack(tmp, fmu)


def pack(folder, fmu):
    """Zip the FMU's ``folder``, validate it with fmpy, and move it into ``fmu`` whole
    (fmu_src.atomic: the file's date is the build's stamp, so a build killed part-way
    must not leave a newer, torn FMU); returns ``fmu``."""
    members = sorted(p for p in folder.rglob("*") if p.is_file())
    packed = folder / fmu.name
    with zipfile.ZipFile(packed, "w", zipfile.ZIP_DEFLATED) as z:
        for path in members:
            z.write(path, path.relative_to(folder).as_posix())
    from fmpy.validation import validate_fmu  # here: a run whose FMUs are built does not import it
    problems = validate_fmu(str(packed))
    if problems:
        raise RuntimeError(f"native {fmu.name} fails fmpy validation:\n" + "\n".join(problems))
    return atomic.write_bytes(fmu, packed.read_bytes())


def _inputs(version=2):
    """Files a native FMU of the FMI ``version`` is made from: its C (no other version's
    layer), and the Python its numbers come from."""
    others = {name for v, name in LAYERS.items() if v != version}
    files = [p for p in NATIVE.glob("*") if p.name not in others] + [p for folder in KERNELS for p in folder.glob("*")]
    files += [p for folder in ("plant", "controller", "fmu_src") for p in (ROOT / folder).glob("*.py")]
    return files


def ensure_native(scripts, out=None, python=None):
    """Paths of the native FMUs of ``scripts`` (fmu_src/<script>.py names), rebuilt when
    missing or older than their pythonfmu FMU or any file they are made from; ``python``
    (script -> path) names the pythonfmu FMUs to make them from, else those of build/fmu."""
    from fmu_src import python_build as builder
    out = pathlib.Path(out) if out is not None else builder.OUT / "native"
    python = {script: python[script] for script in scripts} if python is not None else builder.ensure_built(scripts)
    return _ensure(2, python, out)


def _ensure(version, python, out):
    """script -> native FMU of the FMI ``version`` in ``out`` of the pythonfmu FMUs ``python``
    (script -> path), rebuilt when missing or older than its pythonfmu FMU or any of _inputs."""
    from fmu_src import python_build as builder
    newest = max(p.stat().st_mtime for p in _inputs(version))
    build = build_native if version == 2 else build_native3
    paths, due = {}, []
    with atomic.building(out):        # another process building here: wait, then find it built
        for script, source in python.items():
            target = out / source.name
            if not (target.exists() and target.stat().st_mtime >= max(newest, source.stat().st_mtime)):
                builder.LOG.info("building the native FMI %d.0 FMU of %s", version, script)
                due.append(source)
            paths[script] = target
        with ThreadPoolExecutor(os.cpu_count()) as pool:   # each build compiles in its own folder: side by side
            for _ in pool.map(lambda source: build(source, out), due):   # an error is raised here, as before
                pass
    return paths


# ------------------------------------------------------------------------- FMI 3.0
# The FMI 3.0 FMU of a native model is compiled as its FMI 2.0 FMU is (the model file, the
# kernels, the generated <id>_vars.h and the instance core), with fmi3_layer.c in place of
# fmi2_layer.c, and a modelDescription translated from the native FMI 2.0 one, so names,
# units, ranges, starts, enumerations and the default experiment have one source.
_FMI3_KIND = {"Real": "Float64", "Integer": "Int32", "Enumeration": "Enumeration", "String": "String"}
_FMI3_ATTRIBUTES = ("declaredType", "unit", "displayUnit", "min", "max", "nominal")


def fmi3_platform():
    """This platform's FMI 3.0 binaries folder (x86_64-linux, aarch64-linux)."""
    import platform
    return f"{platform.machine()}-linux"


def _groups(root):
    """The FMI 2 ScalarVariables grouped into FMI 3 variables: (name, [elements]). The
    elements of a vector name[1..n] (consecutive value references) form one array where
    they agree in everything but their start values; a vector whose elements differ (the
    pose: metres and radians; FMI 3 gives an array one unit) stays n scalars named as in
    FMI 2."""
    groups = {}
    for var in root.iter("ScalarVariable"):
        groups.setdefault(_c_name(var.get("name")), []).append(var)
    result = []
    for name, elements in groups.items():
        vrs = [int(e.get("valueReference")) for e in elements]
        if vrs != list(range(vrs[0], vrs[0] + len(vrs))):
            raise RuntimeError(f"{name}: the elements do not have consecutive value references")
        alike = {(tuple(sorted((k, v) for k, v in e.attrib.items() if k not in ("name", "valueReference"))),
                  e[0].tag, tuple(sorted((k, v) for k, v in e[0].attrib.items() if k != "start"))) for e in elements}
        if len(alike) == 1 or len(elements) == 1:
            result.append((name, elements))
        else:
            result += [(e.get("name"), [e]) for e in elements]
    return result


def _derivatives(root2):
    """FMI 2 value reference of an output's first element -> that of the output which is its
    time derivative (its catalogue row's output_derivatives), element by element; and the highest order any
    output has (maxOutputDerivativeOrder)."""
    declared = catalogue.BY_IDENTIFIER[root2.find("CoSimulation").get("modelIdentifier")].output_derivatives
    vrs = {v.get("name"): int(v.get("valueReference")) for v in root2.iter("ScalarVariable")}
    derivative = {}
    for name, integrand in declared.items():
        k = 1
        while f"{name}[{k}]" in vrs:
            derivative[vrs[f"{integrand}[{k}]"]] = vrs[f"{name}[{k}]"]
            k += 1
        if k == 1 or f"{integrand}[{k}]" in vrs or f"{integrand}[{k - 1}]" not in vrs:
            raise RuntimeError(f"{name} and {integrand}: not two vectors of the same length")

    def order(vr):
        return 1 + order(derivative[vr]) if vr in derivative else 0
    return derivative, max((order(vr) for vr in derivative), default=0)


def _fmi3_variable(parent, name, elements):
    first = elements[0]
    kind = first[0]
    if kind.tag not in _FMI3_KIND:
        raise RuntimeError(f"{name}: no FMI 3 translation of an FMI 2 {kind.tag} variable")
    var = ET.SubElement(parent, _FMI3_KIND[kind.tag], name=name, valueReference=first.get("valueReference"))
    for attribute in ("description", "causality", "variability", "initial"):
        if first.get(attribute) is not None:
            var.set(attribute, first.get(attribute))
    if kind.tag != "Real" and var.get("variability") == "continuous":
        var.set("variability", "discrete")    # FMI 3: only floats are continuous
    for attribute in _FMI3_ATTRIBUTES:
        if kind.get(attribute) is not None:
            var.set(attribute, kind.get(attribute))
    if var.get("unit") is not None:   # the unit through a Float64Type (see _unit_types)
        var.set("declaredType", _unit_type_name(var.attrib.pop("unit"), var.attrib.pop("displayUnit", None)))
    starts = [e[0].get("start") for e in elements]
    if kind.tag == "String":   # FMI 3: a String's start is a child element
        for start in starts:
            ET.SubElement(var, "Start", value=start or "")
    elif all(s is not None for s in starts):
        var.set("start", " ".join(starts))
    if first.get("name") != name:
        ET.SubElement(var, "Dimension", start=str(len(elements)))
    return var


def _unit_type_name(unit, display):
    return unit if display is None else f"{unit} in {display}"


def _unit_types(root2):
    """Float64Types carrying the Reals' units: a variable declares its unit through one
    (valid FMI 3, as the Reference FMUs do), since an importer's strict schema (fmi-sim
    0.7) refuses unit on the variable itself."""
    pairs = {(real.get("unit"), real.get("displayUnit")) for real in root2.iter("Real") if real.get("unit")}
    return [(_unit_type_name(u, d), u, d) for u, d in sorted(pairs, key=lambda p: (p[0], p[1] or ""))]


def model_description3(root2):
    """The FMI 3.0 modelDescription of the native FMI 2.0 one ``root2`` (an Element)."""
    cs2 = root2.find("CoSimulation")
    keep = ("modelName", "description", "author", "version", "copyright", "license", "generationDateAndTime")
    root = ET.Element("fmiModelDescription", fmiVersion="3.0",
                      **{k: root2.get(k) for k in keep if root2.get(k) is not None})
    root.set("instantiationToken", root2.get("guid"))
    root.set("generationTool", "movingbase fmu_src/native_build.py (FMI 3.0 C, no Python at run time)")
    root.set("variableNamingConvention", "structured")
    ET.SubElement(root, "CoSimulation", modelIdentifier=cs2.get("modelIdentifier"), needsExecutionTool="false",
                  canBeInstantiatedOnlyOncePerProcess="false", canGetAndSetFMUState="true",
                  canSerializeFMUState="true", canHandleVariableCommunicationStepSize="true",
                  hasEventMode="false", providesIntermediateUpdate="false")
    units = root2.find("UnitDefinitions")
    if units is not None:
        root.append(units)    # Unit / BaseUnit / DisplayUnit: the same shape in FMI 3
    types2 = root2.find("TypeDefinitions")
    types = ET.SubElement(root, "TypeDefinitions")
    for name, unit, display in _unit_types(root2):
        ET.SubElement(types, "Float64Type", name=name, unit=unit, **({"displayUnit": display} if display else {}))
    if types2 is not None:
        for simple in types2.iter("SimpleType"):
            enum = simple.find("Enumeration")
            if enum is None:
                raise RuntimeError(f"type {simple.get('name')}: only Enumerations are translated to FMI 3")
            kind = ET.SubElement(types, "EnumerationType", name=simple.get("name"))
            for item in enum.iter("Item"):
                ET.SubElement(kind, "Item", **{k: item.get(k) for k in ("name", "value", "description")
                                               if item.get(k) is not None})
    if not len(types):
        root.remove(types)
    categories = ET.SubElement(root, "LogCategories")
    for category in root2.find("LogCategories"):
        ET.SubElement(categories, "Category", name=category.get("name"),
                      description=category.get("description", "").replace("fmi2", "fmi3"))
    if root2.find("DefaultExperiment") is not None:
        root.append(root2.find("DefaultExperiment"))
    variables = ET.SubElement(root, "ModelVariables")
    ET.SubElement(variables, "Float64", name="time", valueReference=str(len(list(root2.iter("ScalarVariable")))),
                  causality="independent", variability="continuous",
                  description="simulation time (value reference: one past the FMI 2 variables)")
    structure_outputs, initial_unknowns, inputs = [], [], {}
    derivative, max_order = _derivatives(root2)
    integrand = {d: vr for vr, d in derivative.items()}
    if max_order:
        root.find("CoSimulation").set("maxOutputDerivativeOrder", str(max_order))
    for name, elements in _groups(root2):
        var = _fmi3_variable(variables, name, elements)
        if int(var.get("valueReference")) in integrand:
            var.set("derivative", str(integrand[int(var.get("valueReference"))]))
        if var.get("causality") == "input":
            inputs[name] = var.get("valueReference")
        if var.get("causality") == "output":
            structure_outputs.append((name, var.get("valueReference")))
            if var.get("initial", "calculated") != "exact":
                initial_unknowns.append(var.get("valueReference"))
        elif var.get("causality") == "calculatedParameter":
            initial_unknowns.append(var.get("valueReference"))
    structure = ET.SubElement(root, "ModelStructure")
    key = catalogue.BY_IDENTIFIER[cs2.get("modelIdentifier")].key
    for name, vr in structure_outputs:     # the inputs each follows within a step ("": none)
        ET.SubElement(structure, "Output", valueReference=vr, dependencies=" ".join(
            inputs[n] for n in catalogue.output_dependencies(key, name, list(inputs))))
    for vr in initial_unknowns:
        ET.SubElement(structure, "InitialUnknown", valueReference=vr)
    ET.indent(root)
    return root


def fmi3_variables_header(root2):
    """fmi3_variables.h: per FMI 2 value reference, the FMI 3 variable that starts there
    (its element count and kind: Float64, Int32, or an Enumeration set as Int64; count 0:
    a later element of an array), as model_description3 declares them, and the output
    that is its time derivative (its catalogue row's output_derivatives)."""
    variables = list(root2.iter("ScalarVariable"))
    kinds = {"Real": "K_FLOAT64", "Integer": "K_INT32", "Enumeration": "K_ENUM", "String": "K_STRING"}
    counts, kind = [0] * len(variables), ["K_NONE"] * len(variables)
    for _, elements in _groups(root2):
        vr = int(elements[0].get("valueReference"))
        counts[vr], kind[vr] = len(elements), kinds[elements[0][0].tag]
    derivative, max_order = _derivatives(root2)
    return "\n".join([
        "/* Generated by fmu_src/native_build.py from the FMI 2.0 modelDescription: do not edit. */",
        "#ifndef MB3_VARIABLES_H", "#define MB3_VARIABLES_H", f"#define MB3_NVARS {len(variables)}",
        "enum { K_NONE = 0, K_FLOAT64, K_INT32, K_ENUM, K_STRING };",
        f"static const int MB3_COUNT[MB3_NVARS] = {{{', '.join(map(str, counts))}}};",
        f"static const unsigned char MB3_KIND[MB3_NVARS] = {{{', '.join(kind)}}};",
        "/* the value reference of the output that is the time derivative of the one here, or -1 */",
        f"#define MB3_MAX_DERIVATIVE_ORDER {max_order}",
        f"static const int MB3_DERIVATIVE[MB3_NVARS] = "
        f"{{{', '.join(str(derivative.get(vr, -1)) for vr in range(len(variables)))}}};",
        "#endif", ""])


def build_description3(identifier, c_files):
    """buildDescription.xml: the sources a tool compiles into the FMU."""
    root = ET.Element("fmiBuildDescription", fmiVersion="3.0")
    config = ET.SubElement(root, "BuildConfiguration", modelIdentifier=identifier)
    files = ET.SubElement(config, "SourceFileSet", language="C99")
    for name in c_files:
        ET.SubElement(files, "SourceFile", name=name)
    ET.SubElement(files, "IncludeDirectory", name=".")
    ET.SubElement(config, "Library", name="m")
    ET.indent(root)
    return root


def build_native3(native_fmu, out, empty=False):
    """The FMI 3.0 FMU of ``native_fmu`` in ``out`` (same file name); ``empty`` as in
    build_native. ``native_fmu`` is either the pythonfmu FMU (the variable table and the
    FMI 2.0 description it is translated from are made as build_native makes them, with
    the same guid: no FMI 2.0 FMU is needed) or a native FMI 2.0 FMU (its description and
    generated variable table: the FMI 3.0 twin of that build). Either way the binary is
    compiled from fmu_src/native/ and the kernels."""
    native_fmu = pathlib.Path(native_fmu)
    with zipfile.ZipFile(native_fmu) as z:
        root2 = ET.fromstring(z.read("modelDescription.xml"))
        identifier = root2.find("CoSimulation").get("modelIdentifier")
        vars_name = f"sources/{identifier}_vars.h"
        vars_h = z.read(vars_name).decode() if vars_name in z.namelist() else None
    if vars_h is None:   # a pythonfmu FMU
        identifier, vars_h, root2 = _from_python(native_fmu, empty)
    return _build(3, identifier, vars_h, root2, pathlib.Path(out) / native_fmu.name, empty)


def ensure_native3(scripts, out=None):
    """Paths of the FMI 3.0 native FMUs of ``scripts``, built from their pythonfmu FMUs (no
    FMI 2.0 FMU needed) when missing or older than those or any file they are made from."""
    from fmu_src import python_build as builder
    out = pathlib.Path(out) if out is not None else builder.OUT / "native3"
    return _ensure(3, builder.ensure_built(scripts), out)
