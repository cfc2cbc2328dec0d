"""The layout the docs promise (docs/development.md), held: the data flows one way
(plant -> controller -> fmu_src -> scenarios -> studies -> movingbase, and within scenarios
spec -> cosim -> output -> runs -> the SSP export), the folders are the packages, and one
catalogue names every FMU."""
import ast
import pathlib
import re

import pytest

from fmu_src import catalogue

ROOT = pathlib.Path(__file__).resolve().parents[1]
# lowest first: a module may import its own layer and those before it, never one after
LAYERS = ("plant", "controller", "fmu_src", "scenarios.spec", "scenarios.cosim", "scenarios.output",
          "scenarios.runs", "scenarios", "studies", "movingbase")
PACKAGES = ("plant", "controller", "fmu_src", "scenarios", "studies", "movingbase")


def layer(module):
    """The index in LAYERS of the longest layer name that ``module`` is or lies in; None
    for a module outside the kit (numpy, fmpy, ...)."""
    found = [i for i, name in enumerate(LAYERS) if module == name or module.startswith(name + ".")]
    return max(found, key=lambda i: len(LAYERS[i])) if found else None


def modules():
    for package in PACKAGES:
        for path in sorted((ROOT / package).rglob("*.py")):
            yield path, ".".join(path.relative_to(ROOT).with_suffix("").parts)


def imported(path, module):
    """Every module ``path`` imports, at any depth (function-level imports too)."""
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            yield from (alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                parent = module.split(".")[:-node.level] if not path.name == "__init__.py" else \
                    module.split(".")[:len(module.split(".")) - node.level + 1]
                base = ".".join(parent + ([base] if base else []))
            yield from (f"{base}.{alias.name}" for alias in node.names)


@pytest.mark.parametrize("path, module", list(modules()), ids=lambda v: v if isinstance(v, str) else "")
def test_imports_go_down_the_layers_only(path, module):
    own = layer(module)
    upward = sorted({m for m in imported(path, module) if layer(m) is not None and layer(m) > own})
    assert not upward, f"{module} ({LAYERS[own]}) imports from a later layer: {upward}"


def test_the_layer_rule_sees_an_upward_import(tmp_path):
    """The check itself: a plant module importing the master is caught."""
    bad = tmp_path / "bad.py"
    bad.write_text("def f():\n    from scenarios.cosim import master\n")
    assert layer("plant.bad") < max(layer(m) for m in imported(bad, "plant.bad") if layer(m) is not None)


def test_no_module_adds_to_the_import_path():
    """The folders are the packages: nothing inserts into sys.path to find the kit."""
    offenders = [str(path.relative_to(ROOT)) for path, _ in modules() if "sys.path.insert" in path.read_text()]
    assert not offenders


def test_one_catalogue_names_every_fmu():
    """Each row's script, class and C file exist under the one name; no FMU file is
    outside the catalogue; the identifier is the key in CamelCase."""
    scripts = {p.stem for p in (ROOT / "fmu_src").glob("*_fmu.py")}
    c_files = {p.name for p in (ROOT / "fmu_src" / "native").glob("*_fmu.c")}
    assert scripts == set(catalogue.SCRIPTS)
    assert c_files == {f.c_file for f in catalogue.FMUS}
    for fmu in catalogue.FMUS:
        text = (ROOT / "fmu_src" / f"{fmu.script}.py").read_text()
        assert re.search(rf"^class {fmu.identifier}\(", text, flags=re.M), fmu.key
        assert f'"{fmu.identifier}_vars.h"' in (ROOT / "fmu_src" / "native" / fmu.c_file).read_text(), fmu.key
        assert fmu.identifier.lower() == fmu.key.replace("_", "")


def test_the_tests_mirror_the_packages():
    """Every folder of tests/ (but the C host's sources and the golden files, in folders or not) is a
    package folder or sub-package of the kit."""
    folders = {p.relative_to(ROOT / "tests") for p in (ROOT / "tests").rglob("*") if p.is_dir()
               and p.name not in ("__pycache__", "golden", "c_host") and "golden" not in p.relative_to(ROOT).parts}
    kit = {p.relative_to(ROOT) for package in PACKAGES for p in [ROOT / package, *(ROOT / package).rglob("*")]
           if p.is_dir() and (p / "__init__.py").exists()}
    assert folders - kit - {pathlib.Path("hosts")} == set()
