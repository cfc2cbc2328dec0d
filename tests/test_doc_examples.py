"""Every code block of README.md and docs/*.md that the docs present as runnable runs, and
runs clean: Python blocks (a page's blocks in order, in one namespace, in a fresh folder),
TOML scenario and campaign files (written out, checked, and run at full length, every run
unflagged), and ```sh / ```console blocks of `movingbase ...` commands (run in a folder
holding the page's TOML files). A ```text block is shown, not run; any other block the
test does not run says why in an HTML comment right above it (`<!-- not run: ... -->`),
and every block is one or the other: the docs' own example (my_slew, 101 s of slew in
40 s) was once flagged at full length and looked clean under ci=True. The convention is
in docs/development.md."""
import math
import pathlib
import shlex
import subprocess
import sys
import tomllib
import warnings

import pytest

import movingbase
from scenarios import spec
from scenarios.runs import campaign, runner
from scenarios.runs import estimates as resources

ROOT = pathlib.Path(__file__).resolve().parent.parent
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md")),
         *sorted((ROOT / "docs" / "conventions").glob("*.md"))]
NOT_RUN = "<!-- not run: "
SLOW_STEPS = 250_000     # a full-length example of more steps (all runs: ~3 s native) is a slow test


def blocks(page):
    """(language, code, skipped) of each fenced block of ``page``, in order; ``skipped``:
    the line above the fence is a ``<!-- not run: why -->`` comment."""
    found, lines, i = [], page.read_text(encoding="utf-8").splitlines(), 0
    while i < len(lines):
        if lines[i].startswith("```"):
            end = next(j for j in range(i + 1, len(lines)) if lines[j].startswith("```"))
            above = lines[i - 1].strip() if i else ""
            skipped = above.startswith(NOT_RUN) and above.endswith("-->") and len(above) > len(NOT_RUN) + 3
            found.append((lines[i][3:].strip(), "\n".join(lines[i + 1:end]), skipped))
            i = end
        i += 1
    return found


RUN = [(page, lang, code) for page in PAGES for lang, code, skipped in blocks(page) if not skipped]


def _setup(lang, code):
    """The README's two commands (and their copies): CI runs the test command on a clean
    clone, the first is tried from a fresh clone before each stop (docs/development.md)."""
    return lang == "sh" and all(line.startswith("python3 -m venv .venv") for line in code.splitlines())


def commands(lang, code):
    """The `movingbase ...` command lines of a ```sh or ```console block ("$ " prompts,
    the README's ".venv/bin/" and comments dropped), or None if it is not such a block."""
    if lang not in ("sh", "console"):
        return None
    lines = [line.strip().removeprefix("$ ").removeprefix(".venv/bin/") for line in code.splitlines()]
    lines = [line for line in lines if line and not line.startswith("#")]
    return lines if lines and all(line.startswith("movingbase ") for line in lines) else None


def test_every_block_is_run_or_says_why_not():
    untold = [f"{page.relative_to(ROOT)}: ```{lang}" for page, lang, code in RUN
              if lang not in ("python", "toml", "text") and not _setup(lang, code) and commands(lang, code) is None]
    assert untold == []
    assert {page.name for page, _, _ in RUN} >= {"README.md", "python-api.md", "scenarios.md", "campaigns.md"}


def test_blocks_are_found_with_their_markers(tmp_path):
    """The reader of the pages itself: a marker skips only the block right under it, and
    a marker without a reason skips nothing."""
    page = tmp_path / "page.md"
    page.write_text("text\n<!-- not run: a cluster -->\n```sh\ndask scheduler\n```\n\n```python\nx = 1\n```\n"
                    "<!-- not run: -->\n```console\n$ movingbase run a.toml\n```\n", encoding="utf-8")
    assert blocks(page) == [("sh", "dask scheduler", True), ("python", "x = 1", False),
                            ("console", "$ movingbase run a.toml", False)]
    assert commands("console", "$ movingbase run a.toml\n# a comment\n") == ["movingbase run a.toml"]
    assert commands("sh", ".venv/bin/movingbase run a.toml") == ["movingbase run a.toml"]
    assert commands("sh", "dask worker tcp://x:8786") is None


LIST_ITEM = ("- ", "* ", "+ ")


def indented_blocks(page):
    """Line numbers where an indented (4 spaces) code block starts outside a fence: after a
    blank line, below a paragraph that is neither indented nor a list item (there it
    continues the item). Such a block has no tag to say whether it runs."""
    found, fenced, above = [], False, ""
    lines = page.read_text(encoding="utf-8").splitlines()
    for number, line in enumerate(lines, 1):
        if line.startswith("```"):
            fenced = not fenced
        elif not fenced and line.startswith("    ") and line.strip() and not lines[number - 2].strip() \
                and above and not above[0].isspace() and not above.startswith(LIST_ITEM) \
                and not above.split(" ", 1)[0].rstrip(".").isdigit():
            found.append(number)
        if line.strip():
            above = line
    return found


def test_no_block_hides_from_the_test_as_an_indented_one(tmp_path):
    """Every code block is fenced, so that its tag or marker says whether it runs (an
    indented command or scenario part went unseen: fmi3.md, flagged-runs.md, kernel.md)."""
    page = tmp_path / "page.md"
    page.write_text("Run:\n\n    movingbase run a.toml\n\n- an item\n\n    its second paragraph\n\n"
                    "```sh\n\n    indented in a fence\n```\n", encoding="utf-8")
    assert indented_blocks(page) == [3]
    assert {str(page.relative_to(ROOT)): indented_blocks(page) for page in PAGES if indented_blocks(page)} == {}


@pytest.fixture
def fresh(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    with warnings.catch_warnings():
        warnings.simplefilter("error", movingbase.RunWarning)     # a flagged example is a failed example
        yield tmp_path


@pytest.mark.parametrize("page", sorted({p for p, lang, _ in RUN if lang == "python"}), ids=lambda p: p.name)
def test_the_python_blocks_of_a_page_run(page, fresh):
    namespace = {}
    for _, lang, code in [r for r in RUN if r[0] == page and r[1] == "python"]:
        exec(compile(code, f"{page.name} block", "exec"), namespace)


TOMLS = [(page, code) for page, lang, code in RUN if lang == "toml"] + \
    [(path,
      path.read_text(encoding="utf-8")) for path in sorted((ROOT / "examples").glob("*.toml"))]   # the notebooks' own


def steps(code):
    """Communication steps of every run of a TOML example at full length, from the file
    alone (no FMU is built to collect the tests): a scenario's sweep values times its
    steps; a campaign's runs (grid axes times cases, times the base scenario's sweep unless
    the campaign sets that parameter) times the steps of the base scenario under its set."""
    data = tomllib.loads(code)
    if "scenario" not in data:
        scenario = spec.parse(code)
        return resources.estimate(scenario).steps * (len(scenario.sweep[1]) if scenario.sweep else 1)
    given = data.get("set", {})
    base = spec.parse(runner.resolve(data["scenario"]).read_text(encoding="utf-8"),
                      overrides={k: v for k, v in given.items() if "." not in k})
    keys = {*given, *(k for axis in data.get("grid", []) for k in axis), *(k for case in data.get("cases",
                                                                                                  []) for k in case)}
    runs = math.prod(len(next(iter(axis.values()))) for axis in data.get("grid", [])) * max(1, len(data.get("cases",
                                                                                                            [])))
    if base.sweep and base.sweep[0] not in keys:
        runs *= len(base.sweep[1])
    return runs * resources.estimate(base).steps


def _written(fresh, code):
    """The example written out as <its name>.toml, as the docs name it; its parsed data."""
    data = tomllib.loads(code)
    path = fresh / f"{data['name']}.toml"
    path.write_text(code, encoding="utf-8")
    return path, data


@pytest.mark.parametrize("page, code", TOMLS, ids=[f"{p.name}-{i}" for i, (p, _) in enumerate(TOMLS)])
def test_a_scenario_or_campaign_of_the_docs_is_valid(page, code, fresh):
    """Cheap, for every TOML block: the checks a run makes before anything runs."""
    path, data = _written(fresh, code)
    if "scenario" in data:
        campaign.jobs(campaign.load(path))
    else:
        movingbase.load_scenario(path)


def test_steps_of_an_example_are_counted_from_its_file():
    """The slow mark's count against the files' own numbers: my_slew sweeps two values
    over 40 s at 1 ms; the campaign example crosses 2 x 2 grid values with one case over
    its set 40 s, at telescope_slew's 1 ms."""
    by_name = {tomllib.loads(code)["name"]: code for _, code in TOMLS}
    assert steps(by_name["my_slew"]) == 2 * 40_000
    assert steps(by_name["sky_slews"]) == 4 * 40_000


@pytest.mark.parametrize("page, code", [pytest.param(p, c, marks=[pytest.mark.slow] * (steps(c) > SLOW_STEPS))
                                        for p, c in TOMLS], ids=[f"{p.name}-{i}" for i, (p, _) in enumerate(TOMLS)])
def test_a_scenario_or_campaign_of_the_docs_runs_clean_at_full_length(page, code, fresh):
    path, data = _written(fresh, code)
    if "scenario" in data:         # a campaign file
        table = movingbase.campaign(path, out=fresh / "out", jobs=2, progress=False).table()
        assert list(table["status"]) == ["ok"] * len(table) and list(table["flags"]) == [""] * len(table), \
            table[["label", "flags"]].to_string()
        return
    result = movingbase.run(path, progress=False)
    assert [run.status for run in result] == ["ok"] * len(result), result.flags
    assert result.ok and all(run.sim_time == pytest.approx(result.scenario.stop_time) for run in result)


COMMANDS = [(page, line) for page, lang, code in RUN for line in commands(lang, code) or ()]


@pytest.mark.parametrize("page, line", [pytest.param(p, line, marks=[pytest.mark.slow] * (
                                            "--ci" not in shlex.split(line, comments=True))) for p, line in COMMANDS],
                         ids=[f"{p.name}-{i}" for i, (p, _) in enumerate(COMMANDS)])
def test_a_command_of_the_docs_runs_clean(page, line, fresh):
    """A `movingbase ...` line, in a folder holding its page's TOML files: exit status 0,
    nothing FLAGGED or FAILED. Without --ci it runs at full length (charts and report
    too): slow."""
    for _, code in [t for t in TOMLS if t[0] == page]:
        _written(fresh, code)
    done = subprocess.run([sys.executable, "-m", "movingbase", *shlex.split(line, comments=True)[1:]],
                          capture_output=True, text=True, cwd=fresh, timeout=600)
    said = done.stdout + done.stderr
    assert done.returncode == 0 and "FLAGGED" not in said and "FAILED" not in said, f"{line}\n{said[-3000:]}"
