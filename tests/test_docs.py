"""The documentation against the code it describes: the scenario-file reference's table
(scenarios/spec/__init__.py KEYS) against what the checker accepts, refuses and fills in; the
figures against the files; the README's commands against the constraints file; the
constraints file against the ranges pyproject.toml declares; the layout table, the shipped
files and the quoted step refusal against the tree and the kit."""
import importlib.util
import pathlib
import re
import tomllib

import pytest
from packaging.requirements import Requirement

from fmu_src import catalogue
from scenarios import spec

ROOT = pathlib.Path(__file__).resolve().parent.parent
DOCS = ROOT / "docs"

# the smallest valid scenario; each test adds the keys it is about
MINIMAL = {"stop_time": '"1 s"', "step": '"1 ms"'}
BODY = """
[fmus.plant]
fmu = "mechanism3t_plant"
[fmus.controller]
fmu = "slider_controller"
[[connections]]
from = "controller.slider_force"
to = "plant.slider_force"
"""


def _text(top=None, body=BODY):
    keys = {**MINIMAL, **(top or {})}
    return "\n".join(f"{k} = {v}" for k, v in keys.items() if v is not None) + "\n" + body


def _generate():
    loaded = importlib.util.spec_from_file_location("docs_generate", DOCS / "generate.py")
    module = importlib.util.module_from_spec(loaded)
    loaded.loader.exec_module(module)
    return module


def test_every_top_level_key_the_checker_accepts_is_documented():
    documented = {re.split(r"[.\[]", key)[0] for key in spec.KEYS}
    assert documented == spec.TOP_KEYS


@pytest.mark.parametrize("table, accepted, documented_body, bogus_body", [
    ("fmus.<instance>", {"fmu", "implementation", "parameters"}, BODY.replace('fmu = "mechanism3t_plant"',
                                     'fmu = "mechanism3t_plant"\nimplementation = "python"\nparameters = {}'),
     BODY.replace('fmu = "mechanism3t_plant"', 'fmu = "mechanism3t_plant"\nbogus = 1')),
    ("connections[]", {"from", "to"}, BODY, BODY.replace('to = "plant.slider_force"',
                                                         'to = "plant.slider_force"\nbogus = 1')),
    ("record", {"interval", "variables", "metric_interval"},
     BODY + '[record]\ninterval = "2 ms"\nmetric_interval = "1 ms"\nvariables = ["plant.slider_position"]\n',
     BODY + "[record]\nbogus = 1\n"),
    ("sweep", {"parameter", "values"}, BODY + '[sweep]\nparameter = "controller.feedforward"\nvalues = ["off", "on"]\n',
     BODY + '[sweep]\nparameter = "controller.feedforward"\nvalues = ["off"]\nbogus = 1\n'),
    ("metrics[]", {"kind", "name", "from"}, BODY + '[[metrics]]\nkind = "peak"\nname = "force"\nfrom = "0.5 s"\n'
     'variable = "controller.slider_force"\n',
     BODY + '[[metrics]]\nkind = "peak"\nvariable = "controller.slider_force"\nbogus = "plant.slider_rate"\n'),
])
def test_sub_keys_documented_are_those_the_checker_accepts(table, accepted, documented_body, bogus_body):
    """The documented keys of a table are those the checker takes (``accepted``, read from
    spec.parse; a metric's kind-specific keys come from METRIC_KINDS): a file using each
    of them parses, one more key is refused."""
    documented = {key[len(table) + 1:] for key in spec.KEYS if key.startswith(table + ".")}
    assert documented == accepted, table
    for key in documented - {"kind"}:
        assert re.search(rf"^{re.escape(key)} = ", documented_body, re.M), (table, key)
    spec.parse(_text(body=documented_body), "x.toml")
    with pytest.raises(spec.ScenarioError):
        spec.parse(_text(body=bogus_body), "x.toml")


def test_required_keys_are_refused_when_missing():
    required = [key for key, (_, default, _) in spec.KEYS.items() if default == spec._REQUIRED]
    assert {"stop_time", "step", "fmus.<instance>.fmu", "connections[].from", "connections[].to"} <= set(required)
    for key in ("stop_time", "step"):
        with pytest.raises(spec.ScenarioError, match=key):
            spec.parse(_text({key: None}), "x.toml")
    for line in ('fmu = "mechanism3t_plant"', 'from = "controller.slider_force"', 'to = "plant.slider_force"'):
        with pytest.raises(spec.ScenarioError):
            spec.parse(_text(body=BODY.replace(line, "")), "x.toml")
    with pytest.raises(spec.ScenarioError, match="sweep"):
        spec.parse(_text(body=BODY + '[sweep]\nparameter = "controller.feedforward"\n'), "x.toml")
    with pytest.raises(spec.ScenarioError, match="kind"):
        spec.parse(_text(body=BODY + '[[metrics]]\nvariable = "controller.slider_force"\n'), "x.toml")


def test_documented_defaults_are_what_the_checker_fills_in():
    body = BODY + '[[metrics]]\nkind = "peak"\nvariable = "controller.slider_force"\n'
    scenario = spec.parse(_text(body=body), "dir/my_scene.toml")
    assert spec.KEYS["name"][1] == "the file's name without .toml" and scenario.name == "my_scene"
    assert spec.KEYS["description"][1] == "empty" and scenario.description == ""
    assert spec.KEYS["start_time"][1] == "0 s" and scenario.start_time == 0.0
    assert spec.KEYS["master"][1] == f'"{scenario.master}"'
    assert spec.KEYS["extrapolation"][1] == f'"{scenario.extrapolation}"'
    assert {f'"{i}"' for i in scenario.implementations.values()} == {spec.KEYS["fmus.<instance>.implementation"][1]}
    assert spec.KEYS["record.interval"][1] == "step" and scenario.record_interval == scenario.step
    assert spec.KEYS["record.variables"][1] == "none" and scenario.record == []
    assert spec.KEYS["metrics[].name"][1] == "the kind" and scenario.metrics[0].name == "peak"
    assert spec.KEYS["metrics[].from"][1] == "0 s" and scenario.metrics[0].start == 0.0
    assert spec.KEYS["fidelity_tolerance"][1] == "none" and scenario.fidelity_tolerance is None
    assert spec.KEYS["ci"][1] == "none" and scenario.ci == {} and scenario.sweep is None


def test_scenario_reference_lists_every_key_kind_fmu_and_unit():
    generate = _generate()
    # the FMU table needs the built FMUs; the keys, kinds and units do not
    generate._model_names = lambda: {fmu: fmu for fmu in catalogue.KEYS}
    text = generate.scenario_reference()
    for key in spec.KEYS:
        assert f"| `{key}` |" in text
    for kind, needs in spec.METRIC_KINDS.items():
        assert f"| `{kind}` | {', '.join(f'`{k}`' for k in needs)} |" in text
    for fmu in catalogue.KEYS:
        assert f"| `{fmu}` |" in text
    from scenarios.spec.units import UNITS
    for unit in UNITS:
        assert f"`{unit}`" in text


def test_every_figure_is_shown_with_the_command_that_draws_it():
    """Each PNG under docs/figures is listed in docs/figures.md (which names its command);
    every figure a page or the README shows exists."""
    listed = (DOCS / "figures.md").read_text()
    for png in (DOCS / "figures").glob("*.png"):
        assert f"`{png.name}`" in listed, png.name
    pages = [*DOCS.glob("*.md"), *DOCS.glob("conventions/*.md"), ROOT / "README.md"]
    for page in pages:
        for target in re.findall(r"!\[[^\]]*\]\(([^)]+\.png)\)", page.read_text()):
            assert (page.parent / target).exists(), (page.name, target)


def test_readme_is_short_and_starts_with_the_two_commands_on_the_tested_set():
    lines = (ROOT / "README.md").read_text().splitlines()
    assert len(lines) <= 150
    block = lines[lines.index("```sh") + 1:]
    commands = block[:block.index("```")]
    assert len(commands) == 2 and lines.index("```sh") <= 3
    assert all("pip install -q -c constraints.txt -e " in c for c in commands)
    assert commands[1].endswith("python -m pytest -q")


def test_constraints_pin_every_declared_dependency_within_its_range():
    """A fresh machine gets the tested set: every requirement of pyproject.toml (and its
    extras) has an exact pin in constraints.txt, and that pin lies in the declared range."""
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    pins = {}
    for line in (ROOT / "constraints.txt").read_text().splitlines():
        line = line.split("#", 1)[0].strip()
        if line:
            name, version = line.split("==")
            pins[re.sub(r"[-_.]+", "-", name).lower()] = version
    requirements = [*project["dependencies"],
                    *(r for extra in project["optional-dependencies"].values() for r in extra)]
    for text in requirements:
        requirement = Requirement(text)
        if requirement.marker is not None and not requirement.marker.evaluate():
            continue
        name = re.sub(r"[-_.]+", "-", requirement.name).lower()
        assert name in pins, requirement.name
        assert requirement.specifier.contains(pins[name], prereleases=True), (text, pins[name])


def test_the_committed_reference_pages_are_what_generate_writes():
    """docs/reference/*.md are committed so that the docs' links work wherever they are read;
    a change of the checker's rules or of an FMU's variables must regenerate them
    (python docs/generate.py)."""
    for name, text in _generate().pages().items():
        committed = DOCS / "reference" / name
        assert committed.exists(), f"docs/reference/{name} is not committed: python docs/generate.py"
        assert committed.read_text() == text, f"docs/reference/{name} is stale: python docs/generate.py"


def _anchors(page):
    """The heading anchors of a Markdown page as mkdocs writes them (lower case, spaces to
    hyphens, other punctuation dropped)."""
    return {re.sub(r"[^\w\- ]", "", heading.strip().lower()).replace(" ", "-")
            for heading in re.findall(r"^#+ (.+)$", page.read_text(), flags=re.M)}


def test_every_link_of_the_docs_to_a_page_of_the_repository_resolves():
    """A page the docs link to (docs/reference/fmus.md once) exists in the repository, and
    so does the heading a link names (#telescopebase outlived the FMU's rename, and the
    site's strict build refused it)."""
    missing = []
    for page in [*DOCS.glob("*.md"), *DOCS.glob("reference/*.md"), DOCS.parent / "README.md"]:
        for target, anchor in re.findall(r"\]\(([^)#\s]+\.(?:md|ipynb|toml|py|png|json))(?:#([^)]*))?\)",
                                         page.read_text()):
            resolved = (page.parent / target).resolve()
            if resolved.parent == DOCS / "examples":     # a page generated from examples/<stem>.ipynb
                resolved = DOCS.parent / "examples" / f"{resolved.stem}.ipynb"
            if not target.startswith("http") and not resolved.exists():
                missing.append(f"{page.name} -> {target}")
            elif anchor and resolved.suffix == ".md" and anchor not in _anchors(resolved):
                missing.append(f"{page.name} -> {target}#{anchor}")
    assert missing == []


def test_the_example_notebooks_are_committed_executed():
    """examples/*.ipynb ship with their outputs (the docs site shows them): every code cell
    ran, and only a cell tagged raises-exception (the usual mistakes) shows an error."""
    import json
    notebooks = sorted((DOCS.parent / "examples").glob("*.ipynb"))
    assert {n.stem for n in notebooks} >= {"newcomer", "single_scenario", "small_campaign"}
    for path in notebooks:
        for cell in json.loads(path.read_text())["cells"]:
            if cell["cell_type"] != "code":
                continue
            assert cell["execution_count"] is not None, f"{path.name}: a cell was not run"
            errors = [o for o in cell["outputs"] if o["output_type"] == "error"]
            assert not errors or "raises-exception" in cell["metadata"].get("tags", []), \
                f"{path.name}: {errors[0]['ename']}: {errors[0]['evalue']}"


def test_the_layout_table_names_every_folder_and_module():
    """docs/development.md's layout table against the tree: every folder git tracks at the
    top and every module of the packages (it had gone stale: no api.py, flags.py,
    records.py, units.py, no movingbase/, examples/ or .ci/)."""
    import subprocess
    tracked = subprocess.run(["git", "ls-files"], cwd=ROOT, capture_output=True, text=True)
    if tracked.returncode != 0:
        pytest.skip("not a git checkout")
    page = (DOCS / "development.md").read_text(encoding="utf-8")
    table = page[page.index("| folder | holds |"):page.index("## Tests")]
    folders = sorted({line.split("/")[0] for line in tracked.stdout.splitlines() if "/" in line})
    missing = [f"{name}/" for name in folders if f"`{name}/`" not in table]
    for package in ("plant", "controller", "fmu_src", "scenarios", "studies", "movingbase"):
        missing += [f"{package}/{p.relative_to(ROOT / package)}" for p in (ROOT / package).rglob("*.py")
                    if p.name != "__init__.py" and not p.name.endswith("_fmu.py") and p.name not in table]
    assert missing == []


def test_the_pages_list_every_shipped_scenario_and_campaign():
    """scenarios.md and campaigns.md name every shipped file (telescope_slew_realistic
    was missing from scenarios.md) and no file that is gone."""
    from scenarios.runs import campaign, runner

    def listed(page, start, end):
        text = (DOCS / page).read_text(encoding="utf-8")
        text = text[text.index(start):]
        return set(re.findall(r"`([a-z0-9_]+)`", text[:text.index(end)]))
    assert listed("scenarios.md", "(shipped names:", "--help") == set(runner.shipped_names())
    assert listed("campaigns.md", "(shipped:", ")") == {p.stem for p in campaign.SHIPPED.glob("*.toml")}


def test_the_step_refusal_quoted_in_flagged_runs_is_what_the_kit_says(tmp_path):
    """flagged-runs.md quotes the refusal of the shipped slew at a 4 ms step (it once
    quoted a limit of 2.001 ms, beyond the true 2.00009 ms): the kit's own words, line
    breaks aside."""
    import movingbase
    page = (DOCS / "flagged-runs.md").read_text(encoding="utf-8")
    quoted = page[page.index("```text\nscenario error: slew_4ms.toml") + len("```text\n"):]
    quoted = " ".join(quoted[:quoted.index("```")].split())
    text = (ROOT / "scenarios" / "files" / "telescope_slew.toml").read_text(encoding="utf-8")
    text = re.sub(r'^name = "telescope_slew"', 'name = "slew_4ms"', text, count=1, flags=re.M)
    text = re.sub(r'^step = "1 ms"', 'step = "4 ms"', text, count=1, flags=re.M)
    (tmp_path / "slew_4ms.toml").write_text(text.replace('interval = "10 ms"', 'interval = "20 ms"'), encoding="utf-8")
    with pytest.raises(movingbase.ScenarioError) as refused:
        movingbase.run(tmp_path / "slew_4ms.toml", progress=False)
    assert " ".join(f"scenario error: {refused.value}".split()).replace(str(tmp_path) + "/", "") == quoted
