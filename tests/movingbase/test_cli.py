"""The command line's dispatch (issue 39): a first word that is neither a command nor a
scenario is an unknown command with a did-you-mean, not a list of missing scenarios, and
its --help is not the help of `run`."""
import pytest

from movingbase import cli


def test_a_mistyped_command_is_told_as_one(capsys):
    with pytest.raises(SystemExit) as done:
        cli.main(["campain", "sky_slews"])
    said = str(done.value.code)
    assert said.startswith("movingbase: unknown command 'campain'; did you mean 'campaign'?\n  commands: run, ")
    with pytest.raises(SystemExit) as done:
        cli.main(["campain", "--help"])
    assert str(done.value.code).startswith("movingbase: unknown command 'campain'")
    assert capsys.readouterr().out == ""          # not run's help


def test_a_scenario_name_is_still_a_run_and_a_near_one_says_which(capsys):
    with pytest.raises(SystemExit) as done:
        cli.main(["telescope_slw"])
    said = str(done.value.code)
    assert "unknown command 'telescope_slw'\n" in said and "did you mean 'telescope_slew' for 'telescope_slw'" in said
    with pytest.raises(SystemExit) as done:       # a shipped name goes to run (here its --help)
        cli.main(["telescope_slew", "--help"])
    assert done.value.code == 0 and "usage: movingbase run" in capsys.readouterr().out
    with pytest.raises(SystemExit) as done:       # and so does the command's own name
        cli.main(["run", "--help"])
    assert done.value.code == 0 and "usage: movingbase run" in capsys.readouterr().out
