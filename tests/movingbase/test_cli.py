"""The command line's dispatch (issue 39): a first word that is neither a command nor a
scenario is an unknown command with a did-you-mean, not a list of missing scenarios, and
its --help is not the help of `run`."""
import pytest

from movingbase import cli
from tests.scenario_helpers import interrupt_the_second_run


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


def test_ctrl_c_in_a_sweep_keeps_the_finished_runs_and_says_how_to_run_the_rest(tmp_path, monkeypatch):
    """The command's Ctrl-C: the first run's results kept, the lock file gone, and the
    rest said in the command line's words (the Python call's: tests/movingbase/test_api.py)."""
    interrupt_the_second_run(monkeypatch)
    with pytest.raises(SystemExit) as done:
        cli.main(["run", "paper_manoeuvre", "--ci", "--quiet", "--charts", "none", "--out", str(tmp_path)])
    folder = tmp_path / "paper_manoeuvre"
    assert str(done.value.code) == (
        f"interrupted: paper_manoeuvre interrupted during run 'fixed_base': runs finished: 'none': records, "
        f"metrics.json and a report marked interrupted in {folder}; not run to their end: 'fixed_base', "
        "'moving_base'; to run the rest: a copy of paper_manoeuvre.toml with [sweep] values = ['fixed_base', "
        "'moving_base'], run into another --out")
    assert sorted(p.name for p in folder.iterdir()) == ["metrics.json", "none.npz", "report.md"]
