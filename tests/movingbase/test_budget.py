"""`movingbase budget FILE` and ``movingbase.budget``: one small budget through both, the same
numbers; a bad file refused with its file, key and problem."""
import json

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
    result = movingbase.budget(path, samples=4000, progress=False)
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
