"""Build every FMU of the kit into build/fmu/ and check each with fmpy's validator
(the CLI is build.py at the top of the repository: python build.py [--out DIR] [names]).

pythonfmu packs each script of fmu_src/ (class __init__ runs here, at build time); this
script then adds what pythonfmu leaves out: SI units with mm/deg display units, the
parameters' min/max and the choice parameters as FMI Enumerations in modelDescription.xml, and
resources/requirements.txt naming the Python packages the FMU
needs at run time (pythonfmu's `deploy` installs from it). It puts fmu_src/pythonfmu_shim.c,
compiled with the machine's cc, in front of pythonfmu's Linux wrapper (fmi2Error, not
fmi2Fatal, for a failed initialization; a clean exit in a C host; see that file); the
win64 DLL pythonfmu ships stays as it is. The CLI also builds each FMU's native C twin into
<out>/native/ (FMI 2.0) and <out>/native3/ (FMI 3.0) (fmu_src/native_build.py).
"""
import hashlib
import importlib
import json
import logging
import os
import pathlib
import subprocess
import tempfile
import tomllib
import xml.etree.ElementTree as ET
import zipfile

import fmpy

from fmu_src import atomic, catalogue

ROOT = pathlib.Path(__file__).resolve().parent.parent   # the checkout, or site-packages
PYPROJECT = ROOT / "pyproject.toml"
OUT = (ROOT if PYPROJECT.exists() else pathlib.Path.cwd()) / "build" / "fmu"
LOG = logging.getLogger("movingbase.build")    # each build as it starts (scenarios.runs.runner says it on stderr)
SHIM = ROOT / "fmu_src" / "pythonfmu_shim.c"

_BASE = {"m": {"m": "1"}, "rad": {"rad": "1"}, "s": {"s": "1"}, "N": {"kg": "1", "m": "1", "s": "-2"},
         "m/s": {"m": "1", "s": "-1"}, "rad/s": {"rad": "1", "s": "-1"}, "m/s2": {"m": "1", "s": "-2"},
         "rad/s2": {"rad": "1", "s": "-2"}, "N/m": {"kg": "1", "s": "-2"},
         "N/(m.s)": {"kg": "1", "s": "-3"}, "N.s/m": {"kg": "1", "s": "-1"}, "m.s": {"m": "1", "s": "1"},
         "1/s": {"s": "-1"},
         "m2": {"m": "2"}, "kg/m3": {"kg": "1", "m": "-3"}, "kg/m": {"kg": "1", "m": "-1"},
         "N.m": {"kg": "1", "m": "2", "s": "-2"},
         # noise densities: s^(-1/2), which FMI's integer BaseUnit exponents cannot say (no BaseUnit)
         "rad/s/sqrt(Hz)": None, "m/s2/sqrt(Hz)": None, "1": {}}   # "1": dimensionless
_DISPLAY = {"m": ("mm", 1e3), "rad": ("deg", 57.29577951308232), "m/s": ("mm/s", 1e3),
            "rad/s": ("deg/s", 57.29577951308232), "m/s2": ("mm/s2", 1e3),
            "rad/s2": ("deg/s2", 57.29577951308232), "1/s": ("Hz", 1.0)}

# units of the leg actuator and sensor parameters (Hz written 1/s, as scenarios/spec/units.py reads it)
_BASE.update({"kg": {"kg": "1"}, "N.m": {"kg": "1", "m": "2", "s": "-2"}, "1/s": {"s": "-1"},
              "N/s": {"kg": "1", "m": "1", "s": "-3"},
              "kg.m2": {"kg": "1", "m": "2"}})
_BASE["rad/m"] = {"rad": "1", "m": "-1"}   # the feed support's mode shapes (Telescope)


def requirements():
    """Runtime requirements of the FMUs: the pinned dependencies plus this kit."""
    from importlib import metadata  # here: its import costs every `movingbase run` 17 ms
    if PYPROJECT.exists():
        project = tomllib.loads(PYPROJECT.read_text())["project"]
        name, version, dependencies = project["name"], metadata.version("movingbase"), project["dependencies"]
    else:   # an installed copy: the same list from its metadata
        name, version = "movingbase", metadata.version("movingbase")
        dependencies = [r for r in metadata.requires(name) if "extra ==" not in r]
    lines = ["# install into the Python that runs the FMU (movingbase itself: pip install <its repository>)"]
    lines += [f"{name}=={version}", *dependencies]
    return "\n".join(lines) + "\n"


def add_units(xml_text, units):
    """modelDescription.xml with UnitDefinitions and unit/displayUnit on every Real."""
    root = ET.fromstring(xml_text)
    definitions = ET.Element("UnitDefinitions")
    for name in sorted(set(units.values())):
        unit = ET.SubElement(definitions, "Unit", name=name)
        if _BASE[name] is not None:
            ET.SubElement(unit, "BaseUnit", _BASE[name])
        if name in _DISPLAY:
            ET.SubElement(unit, "DisplayUnit", name=_DISPLAY[name][0], factor=repr(_DISPLAY[name][1]))
    position = list(root).index(root.find("CoSimulation")) + 1
    root.insert(position, definitions)
    for var in root.iter("ScalarVariable"):
        real = var.find("Real")
        if real is not None and var.get("name") in units:
            unit = units[var.get("name")]
            real.set("unit", unit)
            if unit in _DISPLAY:
                real.set("displayUnit", _DISPLAY[unit][0])
    return ET.tostring(root, encoding="unicode", xml_declaration=True)


def add_ranges(xml_text, ranges):
    """modelDescription.xml with FMI min/max (inclusive) on every ranged Real/Integer."""
    root = ET.fromstring(xml_text)
    for var in root.iter("ScalarVariable"):
        valid = ranges.get(var.get("name"))
        kind = var.find("Real") if var.find("Real") is not None else var.find("Integer")
        if valid is None or kind is None:
            continue
        for attribute, value in zip(("min", "max"), valid):
            if value is not None:
                kind.set(attribute, repr(float(value)) if kind.tag == "Real" else str(int(value)))
    return ET.tostring(root, encoding="unicode", xml_declaration=True)


def add_enumerations(xml_text, enumerations):
    """modelDescription.xml with a TypeDefinitions SimpleType per choice parameter (items
    named as the scenario files name them, values 0..n-1 as the FMU counts) and that
    parameter declared an Enumeration of it: ``fmpy simulate --start-values profile paper``."""
    if not enumerations:
        return xml_text
    root = ET.fromstring(xml_text)
    types = ET.Element("TypeDefinitions")
    for name, labels in sorted(enumerations.items()):
        simple = ET.SubElement(types, "SimpleType", name=name)
        kind = ET.SubElement(simple, "Enumeration")
        for value, label in enumerate(labels):
            ET.SubElement(kind, "Item", name=label, value=str(value))
    after = root.find("UnitDefinitions") if root.find("UnitDefinitions") is not None else root.find("CoSimulation")
    root.insert(list(root).index(after) + 1, types)
    for var in root.iter("ScalarVariable"):
        if var.get("name") in enumerations:
            integer = var.find("Integer")
            integer.tag = "Enumeration"
            integer.set("declaredType", var.get("name"))
    return ET.tostring(root, encoding="unicode", xml_declaration=True)


def add_dependencies(xml_text):
    """modelDescription.xml with each output's ``dependencies`` in ModelStructure/Outputs:
    the indices of the inputs it follows within a step (catalogue.output_dependencies; ""
    for none)."""
    root = ET.fromstring(xml_text)
    key = catalogue.BY_IDENTIFIER[root.find("CoSimulation").get("modelIdentifier")].key
    variables = list(root.iter("ScalarVariable"))
    inputs = {v.get("name"): i for i, v in enumerate(variables, 1) if v.get("causality") == "input"}
    for unknown in root.find("ModelStructure/Outputs"):
        output = variables[int(unknown.get("index")) - 1].get("name")
        unknown.set("dependencies", " ".join(str(inputs[n]) for n in catalogue.output_dependencies(key, output,
                                                                                                   list(inputs))))
    return ET.tostring(root, encoding="unicode", xml_declaration=True)


def slave_instance(fmu):
    """An instance of the FMU's slave class, made on the FMU's own resources (the units it
    recorded; the exact start values fmu_src/native_build.py compiles in)."""
    with tempfile.TemporaryDirectory() as tmp:
        with zipfile.ZipFile(fmu) as z:
            z.extractall(tmp)
        resources = pathlib.Path(tmp) / "resources"
        module = importlib.import_module("fmu_src." + (resources / "slavemodule.txt").read_text().strip())
        slave_class = next(c for c in vars(module).values()
                           if isinstance(c, type) and c.__module__ == module.__name__ and hasattr(c, "step"))
        return slave_class(instance_name="build", resources=str(resources))


def _recorded(fmu):
    """(units, ranges, enumerations) the slave recorded."""
    slave = slave_instance(fmu)
    return slave.units, slave.ranges, slave.enumerations


def compile_shim(folder):
    """fmu_src/pythonfmu_shim.c compiled into ``folder`` against fmpy's FMI 2 headers; its path."""
    library = pathlib.Path(folder) / "pythonfmu_shim.so"
    headers = pathlib.Path(fmpy.__file__).resolve().parent / "c-code"
    cc = os.environ.get("CC", "cc")
    command = [cc, "-shared", "-fPIC", "-O2", "-Wall", "-Wextra", "-Werror", "-I", str(headers), "-I", str(SHIM.parent),
               str(SHIM),
               "-o", str(library), "-ldl", "-lpthread"]
    try:
        p = subprocess.run(command, capture_output=True, text=True)
    except FileNotFoundError:
        raise RuntimeError(f"no C compiler '{cc}' (set CC): it compiles {SHIM.name} into every pythonfmu FMU") from None
    if p.returncode:
        raise RuntimeError(f"compiling {SHIM.name} with {cc} failed:\n{p.stderr}")
    return library


def _rewrite(fmu, units, ranges, enumerations, shim):
    """Units, ranges and enumerations into modelDescription.xml; the shim in front of the Linux wrapper,
    which is kept beside it as <id>.pythonfmu.so."""
    with zipfile.ZipFile(fmu) as z:
        files = {name: z.read(name) for name in z.namelist()}
    xml_text = add_dependencies(add_enumerations(add_ranges(add_units(files["modelDescription.xml"].decode(), units),
                                                            ranges), enumerations))
    files["modelDescription.xml"] = xml_text.encode()
    identifier = ET.fromstring(xml_text).find("CoSimulation").get("modelIdentifier")
    wrapper = f"binaries/linux64/{identifier}.so"
    files[f"binaries/linux64/{identifier}.pythonfmu.so"] = files.pop(wrapper)
    files[wrapper] = pathlib.Path(shim).read_bytes()
    with zipfile.ZipFile(fmu, "w", zipfile.ZIP_DEFLATED) as z:
        for name, data in files.items():
            z.writestr(name, data)


def controller_defaults():
    """Default PID gains, designed with python-control at a 1 ms communication step."""
    from controller.design import DEFAULT_CROSSOVER_HZ, DEFAULT_PHASE_MARGIN_DEG, design_pid
    from plant.hexapod.model import StewartParams
    d = design_pid(StewartParams.paper(), DEFAULT_CROSSOVER_HZ, DEFAULT_PHASE_MARGIN_DEG, 1e-3)
    text = (f"h = 1 ms: crossover {d.crossover_hz:.1f} Hz, phase margin {d.modal_phase_margin_deg:.0f} deg, "
            f"gain margin {d.modal_gain_margin_db:.1f} dB")
    gains = {k: getattr(d.gains, k) for k in ("kp", "ki", "kd", "force_limit")}
    return json.dumps({"gains": gains, "design": text})


EXTRA_RESOURCES = {"leg_controller_fmu": {"leg_controller_defaults.json": controller_defaults}}


def build(script, out):
    """Build one FMU from fmu_src/<script>.py; returns its path. It is made and validated
    in a temporary folder and moved into ``out`` whole (a build killed part-way leaves the
    FMU that was there, never a torn one)."""
    path = ROOT / "fmu_src" / f"{script}.py"
    with tempfile.TemporaryDirectory() as tmp:
        files = {"requirements.txt": requirements}
        files.update(EXTRA_RESOURCES.get(script, {}))
        project_files = []
        for name, make in files.items():
            project_files.append(pathlib.Path(tmp) / name)
            atomic.write_text(project_files[-1], make())
        made = pathlib.Path(tmp) / "fmu"
        from fmpy.validation import validate_fmu  # here: a run whose FMUs are built pays for neither (docs/speed.md)
        from pythonfmu.builder import FmuBuilder
        fmu = FmuBuilder.build_FMU(path, dest=made, project_files=project_files, canGetAndSetFMUstate=True,
                                   canSerializeFMUstate=True)
        _rewrite(fmu, *_recorded(fmu), compile_shim(tmp))
        problems = validate_fmu(str(fmu))
        if problems:
            raise RuntimeError(f"{fmu.name} fails fmpy validation:\n" + "\n".join(problems))
        return atomic.write_bytes(pathlib.Path(out) / fmu.name, fmu.read_bytes())


def file_sha256(path):
    """SHA-256 of a file's bytes (what a stamp vouches for)."""
    return hashlib.sha256(pathlib.Path(path).read_bytes()).hexdigest()


def stamped(stamp, newest):
    """The FMU path a stamp vouches for, or None: a stamp older than ``newest`` (the
    sources changed), unreadable, or whose FMU is missing or not the bytes it stamped
    (a build killed part-way, an FMU edited or truncated) is not trusted."""
    try:
        if stamp.stat().st_mtime < newest:
            return None
        path, digest = stamp.read_text(encoding="utf-8").splitlines()
        return pathlib.Path(path) if file_sha256(path) == digest else None
    except (OSError, ValueError):
        return None


def write_stamp(stamp, fmu):
    """The stamp of a built FMU, written last and atomically: its path and SHA-256."""
    atomic.write_text(stamp, f"{fmu}\n{file_sha256(fmu)}\n")


def available():
    """The FMU scripts present in fmu_src/."""
    return [s for s in catalogue.SCRIPTS if (ROOT / "fmu_src" / f"{s}.py").exists()]


def _sources():
    return [p for folder in ("fmu_src", "controller") for p in (ROOT / folder).glob("*.py")] + \
        [p for p in (PYPROJECT, SHIM, SHIM.parent / "native" / "crc32.h") if p.exists()]


def ensure_built(scripts, out=OUT):
    """Paths of the FMUs of ``scripts``, (re)building those missing or older than the
    kit's FMU and controller sources."""
    newest = max(p.stat().st_mtime for p in _sources())
    paths = {}
    with atomic.building(out):        # another process building here: wait, then find it built
        for script in scripts:
            paths[script] = stamped(out / f"{script}.built", newest)
            if paths[script] is None:
                LOG.info("building the pythonfmu FMU of %s (a first build takes ~10 s)", script)
                paths[script] = build(script, out)
                write_stamp(out / f"{script}.built", paths[script])
    return paths
