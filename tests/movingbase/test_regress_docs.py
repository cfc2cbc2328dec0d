"""docs/regression.md's CI configurations run as written: the page's baseline command, then
every `movingbase` line of its GitHub Actions and GitLab CI files, in a folder holding the
page's scene; and the pytest plugin's fixture holds a scene in a user's own test suite."""
import pathlib
import re
import subprocess
import sys
from xml.etree import ElementTree

import pytest
import yaml

PAGE = pathlib.Path(__file__).resolve().parents[2] / "docs" / "regression.md"


def _blocks(language):
    return re.findall(rf"```{language}\n(.*?)```", PAGE.read_text(encoding="utf-8"), re.S)


def _ci_commands():
    """The movingbase lines of the page's CI files: GitHub's steps' run, GitLab's script."""
    github, gitlab = (yaml.safe_load(block) for block in _blocks("yaml"))
    lines = [step["run"] for job in github["jobs"].values() for step in job["steps"] if "run" in step]
    lines += [line for job in gitlab.values() for line in job["script"]]
    return [line for line in lines if line.startswith("movingbase ")]


def _shell(line, folder):
    """Run a command line of the docs as a shell runs it (the kit's command by this interpreter)."""
    return subprocess.run(line.replace("movingbase ", f"{sys.executable} -m movingbase ", 1), shell=True,
                          cwd=folder, capture_output=True, text=True, timeout=600)


@pytest.fixture(scope="module")
def repository(tmp_path_factory):
    """A user's repository: the page's scene and the baseline its first command stores."""
    folder = tmp_path_factory.mktemp("repository")
    (folder / "held_slew.toml").write_text(_blocks("toml")[0], encoding="utf-8")
    update = next(line.removeprefix("$ ") for line in _blocks("console")[0].splitlines() if "--update" in line)
    done = _shell(update, folder)
    assert done.returncode == 0, done.stdout + done.stderr
    return folder


def test_the_ci_files_commands_run_and_pass(repository):
    commands = _ci_commands()
    assert len(commands) == 2     # one per CI system
    for line in commands:
        done = _shell(line, repository)
        assert done.returncode == 0, f"{line}\n{done.stdout}{done.stderr}"
        assert "held_slew: pass (1 run" in done.stdout
        suite = ElementTree.parse(repository / "regress.xml").getroot().find("testsuite")
        assert (suite.get("name"), suite.get("tests"), suite.get("failures")) == ("held_slew", "1", "0")


def test_the_ci_files_command_fails_a_changed_scene(repository, tmp_path):
    changed = (repository / "held_slew.toml").read_text().replace('lever_arm = "25 m"', 'lever_arm = "25.5 m"')
    (tmp_path / "held_slew.toml").write_text(changed)
    (tmp_path / "baselines").symlink_to(repository / "baselines")
    done = _shell(_ci_commands()[0], tmp_path)
    assert done.returncode == 1, done.stdout + done.stderr
    assert "changed since the baseline: base.lever_arm 25.0 -> 25.5" in done.stdout
    assert (tmp_path / "regress-report" / "regress.md").is_file()


USER_TEST = '''
def test_held_slew(scene_regression):
    scene_regression.check("held_slew.toml", ci=True)
'''


@pytest.mark.slow   # 8 s: three pytest sessions over a scene (.ci/run runs it)
def test_the_pytest_fixture_stores_then_holds_then_catches(tmp_path):
    (tmp_path / "held_slew.toml").write_text(_blocks("toml")[0], encoding="utf-8")
    (tmp_path / "test_scenes.py").write_text(USER_TEST)
    command = [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "test_scenes.py"]

    def pytest_run(*extra):
        return subprocess.run(command + list(extra), cwd=tmp_path, capture_output=True, text=True, timeout=600)
    first = pytest_run()
    assert first.returncode == 1 and "no baseline of held_slew.toml" in first.stdout, first.stdout
    assert (tmp_path / "baselines" / "held_slew" / "baseline.json").is_file()
    assert pytest_run().returncode == 0
    scene = tmp_path / "held_slew.toml"
    scene.write_text(scene.read_text().replace('max_step = "1 ms",', 'max_step = "1 ms", payload_mass_error = '
                                                                    '"21.297 kg",'))
    caught = pytest_run("--regress-report", "report")
    assert caught.returncode == 1 and "held_slew: REGRESSION" in caught.stdout, caught.stdout
    assert "plant.payload_mass_error (the FMU's default) -> 21.297" in caught.stdout
    assert (tmp_path / "report" / "held_slew" / "regress.md").is_file()
    assert pytest_run("--regress-update").returncode == 0      # the change accepted: stored anew
    assert pytest_run().returncode == 0
