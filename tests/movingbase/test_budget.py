"""`movingbase budget FILE` and ``movingbase.budget``: one small budget through both, the same
numbers; a bad file refused with its file, key and problem; the BudgetResult's tables, charts,
report and reprs against the numbers it holds."""
import json
import pathlib

import numpy as np
import pytest

import movingbase
from movingbase import cli

TINY = """
name = "tiny"
samples = 2000
sobol_samples = 256
allocation_samples = 5000
seed = 1
[inputs]
leg_offset = { distribution = "uniform", half_width = "5 um" }
platform_joint = { distribution = "uniform", half_width = "5 um" }
[workspace]
z = ["-10 mm", "10 mm"]
elevation = ["30 deg", "90 deg"]
[targets]
focus = "10 um"
"""


def test_command_and_api_give_the_same_budget(tmp_path, capsys):
    path = tmp_path / "tiny.toml"
    path.write_text(TINY)
    cli.main(["budget", str(path), "--samples", "4000", "--out", str(tmp_path / "out"), "--quiet"])
    said = capsys.readouterr().out
    written = json.loads((tmp_path / "out" / "tiny.json").read_text())
    assert said.startswith("tiny: 4,000 samples, pose error at 99.7 %:") and "allocation" in said
    assert "Sobol total, z: " in said and written["samples"] == 4000
    assert said.rstrip().endswith("\nstatus: ok: every target met")
    result = movingbase.budget(path, samples=np.int64(4000), progress=False)
    assert result["quantiles"] == written["quantiles"]   # the same seeds: the same numbers
    focus = result["quantiles"]["focus"]
    assert f"{focus['value'] * 1e6:9.2f} um" in said
    assert result["allocation"]["verified"] and set(result["allocation"]["groups"]) == {"leg_offset", "platform_joint"}
    assert result["sobol"]["groups"] == ["leg_offset", "platform_joint", "workspace"]


def test_a_bad_file_is_refused_by_name(tmp_path):
    path = tmp_path / "bad.toml"
    path.write_text(TINY.replace('focus = "10 um"', 'focus = "-1 um"'))
    with pytest.raises(SystemExit, match=r"budget error: .*bad.toml: targets.focus: must be > 0"):
        cli.main(["budget", str(path), "--quiet"])
    with pytest.raises(movingbase.ScenarioError, match="targets.focus"):
        movingbase.budget(path, progress=False)


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    folder = tmp_path_factory.mktemp("tiny")
    path = folder / "tiny.toml"
    path.write_text(TINY)
    return path, movingbase.budget(path, out=folder / "out", progress=False)


def test_the_result_object_s_tables_carry_the_numbers_and_their_units(tiny):
    _, result = tiny
    assert isinstance(result, movingbase.BudgetResult) and result.status == "ok" and result.met == {"focus": True}
    q = result.quantiles()
    focus = result["quantiles"]["focus"]
    assert q.loc["focus", "value"] == pytest.approx(focus["value"] * 1e6, rel=1e-12)
    assert q.loc["focus", "high"] == pytest.approx(focus["high"] * 1e6, rel=1e-12) and q.loc["focus", "target"] == 10
    assert q.attrs["units"] == {"focus": "µm"} and q.loc["focus", "unit"] == "µm"
    sobol = result.sobol()
    z = result["sobol"]["components"].index("z")
    assert sobol.loc[("z", "platform_joint"), "total"] == result["sobol"]["total"][z][1]
    assert sobol.attrs["units"]["total"] == "1"
    allocation = result.allocation()
    for group, g in result["allocation"]["groups"].items():   # allocated = as given (5 um) x scale
        assert allocation.loc[group, "given"] == pytest.approx(5.0, rel=1e-12)
        assert allocation.loc[group, "allocated"] == pytest.approx(5.0 * g["scale"], rel=1e-12)
    assert allocation.attrs["units"] == {"leg_offset": "µm", "platform_joint": "µm"}
    assert result.leading()["input"].iloc[0] == result["leading_inputs"]["focus"][0][0]


def test_the_result_shows_its_verdict_first_and_writes_its_report(tiny):
    path, result = tiny
    assert repr(result).startswith("<BudgetResult 'tiny': ok, at 99.7 % (2,000 samples): focus met: ")
    assert result._repr_html_().startswith("<p><b>Budget tiny</b>: 2,000 samples, <span") and "every target met" in \
        result._repr_html_()
    folder = path.parent / "out"
    assert sorted(p.name for p in folder.iterdir()) == ["tiny.json", "tiny.md", "tiny_allocation.png",
                                                        "tiny_quantiles.png", "tiny_sobol.png"]
    report = (folder / "tiny.md").read_text()
    assert "**Status: ok**" in report and "![sobol](tiny_sobol.png)" in report
    assert f"| focus | {result['quantiles']['focus']['value'] * 1e6:.4g} µm |" in report
    charts = result.plot()
    assert len(charts) == 3 and "Sobol" in charts[1].axes[0].get_title()


def test_a_target_inside_the_interval_is_flagged(tmp_path):
    """The quantile below the target, the interval's upper end above it: not met, flagged."""
    path = tmp_path / "tiny.toml"
    path.write_text(TINY)
    first = movingbase.budget(path, progress=False)["quantiles"]["focus"]
    inside = (first["value"] + first["high"]) / 2 * 1e6
    path.write_text(TINY.replace('focus = "10 um"', f'focus = "{inside!r} um"'))
    result = movingbase.budget(path, progress=False)
    assert result.status == "flagged" and result.met == {"focus": False} and not result.ok
    assert result.flags[0].startswith("target focus not met: the upper end of the 99.7 % quantile's interval is ")
    assert "NOT met" in repr(result)


@pytest.mark.parametrize("samples, error, text", [
    ("2000", TypeError, "samples must be an integer"), (2e3, TypeError, "samples must be an integer"),
    (0, movingbase.ScenarioError, "samples: 0 samples cannot bound"),
])
def test_samples_is_named_in_every_refusal(tmp_path, samples, error, text):
    path = tmp_path / "tiny.toml"
    path.write_text(TINY)
    with pytest.raises(error, match=text):
        movingbase.budget(path, samples=samples, progress=False)


def test_jobs_takes_any_integer_and_is_refused_in_python_s_words():
    from scenarios.runs import estimates
    assert estimates.check_jobs(np.int64(1), "jobs") == ""
    with pytest.raises(TypeError, match=r"^jobs must be an integer \(the number of worker processes\) or None, not "
                                        r"str '1'$"):
        movingbase.campaign("sky_slews", jobs="1", progress=False)
    with pytest.raises(estimates.ResourceError, match=r"^jobs=0: the number"):
        estimates.check_jobs(0, "jobs")


def test_the_budget_needs_nothing_beyond_the_readme_s_first_install():
    """`pip install -e .` (no extras) gives SALib, which the Sobol indices import: it is a
    dependency, pinned in constraints.txt."""
    import tomllib
    root = pathlib.Path(__file__).resolve().parents[2]
    project = tomllib.loads((root / "pyproject.toml").read_text())["project"]
    assert any(d.replace(" ", "").startswith("SALib>=") for d in project["dependencies"])
    assert "SALib==" in (root / "constraints.txt").read_text()


@pytest.mark.parametrize("given, problem", [
    ("0", "samples: 0 samples cannot bound the 99.7 % quantile from above: its 95 % interval needs at least 1,228"),
    ("-5", "samples: -5 samples cannot bound"),
    ("1e9", "samples: 1,000,000,000 samples is more than the 100,000,000 a budget takes"),
])
def test_the_command_refuses_bad_sample_counts_by_name(tmp_path, given, problem):
    path = tmp_path / "tiny.toml"
    path.write_text(TINY)
    with pytest.raises(SystemExit, match="budget error: .*tiny.toml: " + problem.replace("(", r"\(").replace(
            ")", r"\)")):
        cli.main(["budget", str(path), "--samples", given, "--quiet"])
    with pytest.raises(SystemExit):
        cli.main(["budget", str(path), "--samples", "2.5", "--quiet"])   # argparse: --samples, a whole number
