"""Every code block of README.md and docs/*.md that the docs present as runnable runs, and
runs clean: Python blocks (a page's blocks in order, in one namespace, in a fresh folder),
TOML scenario and campaign files (written out and run at full length, every run
unflagged). A block the test does not run says why in an HTML comment right above it
(`<!-- not run: ... -->`), and every block is one or the other: the docs' own example
(my_slew, 101 s of slew in 40 s) was once flagged at full length and looked clean under
ci=True."""
import pathlib
import re
import tomllib
import warnings

import pytest

import movingbase

ROOT = pathlib.Path(__file__).resolve().parent.parent
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md")), *sorted((ROOT / "docs" / "conventions").glob("*.md"))]
BLOCK = re.compile(r"(?P<before>[^\n]*)\n```(?P<lang>[^\n`]*)\n(?P<code>.*?)\n```", re.S)
NOT_RUN = re.compile(r"<!-- not run: .+ -->")


def blocks(page):
    """(language, code, skipped) of each fenced block of ``page``, in order."""
    text = "\n" + page.read_text(encoding="utf-8")
    return [(m["lang"].strip(), m["code"], bool(NOT_RUN.fullmatch(m["before"].strip()))) for m in BLOCK.finditer(text)]


RUN = [(page, lang, code) for page in PAGES for lang, code, skipped in blocks(page) if not skipped]


def _setup(lang, code):
    """The README's two commands (and their copies): CI runs the test command on a clean
    clone, the first is tried from a fresh clone before each stop (docs/development.md)."""
    return lang == "sh" and all(line.startswith("python3 -m venv .venv") for line in code.splitlines())


def test_every_block_is_run_or_says_why_not():
    untold = [f"{page.relative_to(ROOT)}: ```{lang}" for page, lang, code in RUN
              if lang not in ("python", "toml") and not _setup(lang, code)]
    assert untold == []
    assert {page.name for page, _, _ in RUN} >= {"README.md", "python-api.md", "scenarios.md", "campaigns.md"}


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


TOMLS = [(page, code) for page, lang, code in RUN if lang == "toml"]


@pytest.mark.parametrize("page, code", TOMLS, ids=[f"{p.name}-{i}" for i, (p, _) in enumerate(TOMLS)])
def test_a_scenario_or_campaign_of_the_docs_runs_clean_at_full_length(page, code, fresh):
    data = tomllib.loads(code)
    path = fresh / f"{data['name']}.toml"
    path.write_text(code, encoding="utf-8")
    if "scenario" in data:         # a campaign file
        table = movingbase.campaign(path, out=fresh / "out", jobs=2, progress=False).table()
        assert list(table["status"]) == ["ok"] * len(table) and list(table["flags"]) == [""] * len(table), \
            table[["label", "flags"]].to_string()
        return
    result = movingbase.run(path, progress=False)
    assert result.ok and all(run.sim_time == pytest.approx(result.scenario.stop_time) for run in result)
