"""The SSP from Python (issue 39): movingbase.export_ssp and Result.to_ssp write what
``movingbase run --ssp`` writes, and movingbase.simulate_ssp runs it in fmpy's own SSP
master (fmpy.ssp.simulate_ssp, which as it is stops at t = 0: tests/scenarios/test_ssp.py)
to the numbers of this kit's master run as fmpy's is (Jacobi, no extrapolation)."""
import zipfile

import numpy as np
import pytest

import movingbase
from movingbase import cli

NAME = "paper_manoeuvre"     # [ci]: 4 s at 1 ms, three FMUs, a sweep of the feedforward
JACOBI = {"master": "jacobi", "extrapolation": "none"}     # fmpy's master


def _contents(path):
    """{name: bytes} of a zip: the SSD and its FMUs (the zip's own time stamps aside)."""
    with zipfile.ZipFile(path) as z:
        return {name: z.read(name) for name in z.namelist()}


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    folder = tmp_path_factory.mktemp("ssp")
    return movingbase.export_ssp(NAME, folder / "paper.ssp", ci=True, set=JACOBI, value="moving_base"), folder


def test_python_writes_the_command_s_ssp(exported, tmp_path, capsys):
    """The command exports the first sweep value; Python picks one (value=) or takes the
    first, from a name or from a Result: the same SSD and FMUs byte for byte."""
    path, folder = exported
    cli.main([NAME, "--ci", "--ssp", str(tmp_path / "cli.ssp")])
    assert capsys.readouterr().out.startswith("SSP written to")
    first = movingbase.export_ssp(NAME, tmp_path / "first.ssp", ci=True)
    assert _contents(first) == _contents(tmp_path / "cli.ssp")
    ssd = _contents(path)["SystemStructure.ssd"].decode()
    assert '<ssv:Parameter name="feedforward">\n' in ssd and 'algorithm="jacobi"' in ssd
    with pytest.raises(movingbase.ScenarioError, match=r"value: 'moving base' is not one of the sweep's values "
                                                       r"\(controller.feedforward: 'none', 'fixed_base'"):
        movingbase.export_ssp(NAME, tmp_path / "bad.ssp", ci=True, value="moving base")
    assert not (tmp_path / "bad.ssp").exists()


def test_simulate_ssp_runs_the_export_in_fmpy_as_our_master_does(exported):
    """fmpy's loop with the SSD's parameters and the initial exchange gives our Jacobi
    master's series: equal to 1e-12 m and rad (the telescope is evaluated at fmpy's
    times, accumulated by repeated addition: they differ from ours in the last bits)."""
    path, folder = exported
    rows = movingbase.simulate_ssp(path)
    assert len(rows) == 4000 and rows["time"][-1] == pytest.approx(4.0)
    ours = movingbase.run(NAME, ci=True, set=JACOBI, progress=False)["moving_base"]
    index = np.searchsorted(rows["time"], ours.time[1:] - 1e-9)     # fmpy has no row at t = 0
    np.testing.assert_allclose(rows["time"][index], ours.time[1:], rtol=0, atol=1e-12)
    theirs = np.column_stack([rows[f"plant.pose[{k}]"][index] for k in range(1, 7)])
    assert np.abs(theirs - ours["plant.pose"][1:]).max() < 1e-12
    assert abs(ours["plant.pose"][-1, 2] + 2.68) < 0.01     # the platform's height: a run, not zeros


def test_a_result_exports_the_run_asked_for(exported, tmp_path):
    path, folder = exported
    result = movingbase.run(NAME, ci=True, set={**JACOBI, "stop_time": "2.5 s"}, progress=False)
    written = result.to_ssp(tmp_path / "r.ssp", run="moving_base")
    ssd = _contents(written)["SystemStructure.ssd"].decode()
    assert 'stopTime="2.5"' in ssd
    assert ssd.replace('stopTime="2.5"', 'stopTime="4.0"') == _contents(path)["SystemStructure.ssd"].decode()
    with pytest.raises(KeyError, match="no run 'moving base'; runs: none, fixed_base, moving_base"):
        result.to_ssp(tmp_path / "x.ssp", run="moving base")
