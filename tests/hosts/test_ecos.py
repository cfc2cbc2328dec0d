"""A third master: NTNU's ecos (pip ecospy, which needs Debian's libtbb12; .ci/hosts.sh
installs both) runs the exported SSP of the shortened telescope slew (tests/scenarios/test_ssp.py)
and matches our Jacobi master, with the scenario's parameters applied.

ecos applies only the inline parameter sets named at its init (``init(parameter_set=)``):
when each Component's set carried its instance's name (before issue 18) no name applied
them all, and ecos ran on the FMUs' defaults without an error. The export now names every
set ssp.PARAMETER_SET. test_the_old_naming_ran_on_defaults measures what that cost.
Skipped where ecospy cannot load (no libtbb12, another platform)."""

import numpy as np
import pytest

from scenarios import ssp
from scenarios.cosim.fmi import FmuError
from scenarios.runs import single
from tests.fmu_helpers import _scales
from tests.ssp_helpers import RECORD, columns, configure, run_columns

try:
    from ecospy import EcosLib, EcosSimulation
    EcosLib.set_log_level("err")
except (ImportError, OSError) as exc:   # ecospy missing, or its library cannot load (libtbb12)
    pytest.skip(f"ecos unavailable: {exc}", allow_module_level=True)


def run_ecos(path, scenario, names, parameter_set=ssp.PARAMETER_SET):
    """Rows (steps, len(names)) of the names after every ecos step."""
    sim = EcosSimulation(ssp_path=str(path), step_size=scenario.step)
    try:
        assert sim.init(scenario.start_time, parameter_set)
        rows = []
        for _ in range(round((scenario.stop_time - scenario.start_time) / scenario.step)):
            sim.step()
            rows.append([sim.get_real(n.replace(".", "::", 1)) for n in names])
        return np.array(rows)
    finally:
        sim.terminate()
        sim.free()


def _compare(theirs, ours, names):
    """Largest difference of any column, as a fraction of its vector's scale."""
    scales = _scales({n: ours[n] for n in names})
    return max(np.max(np.abs(theirs[:, j] - ours[n][1:])) / scales[n] for j, n in enumerate(names))


@pytest.mark.parametrize("implementation", ["native", "python"])
def test_ecos_runs_the_exported_ssp_as_our_master_does(request, implementation, tmp_path):
    fmus = request.getfixturevalue("native" if implementation == "native" else "fmus")
    scenario, paths, descriptions, params = configure(fmus)
    path = ssp.export_ssp(scenario, paths, params, tmp_path / "slew.ssp")
    ours = run_columns(single.run(scenario, paths, params, tmp_path, "ours"))
    names = columns(scenario, descriptions, RECORD)
    theirs = run_ecos(path, scenario, names)
    assert theirs.shape == (round(scenario.stop_time / scenario.step), len(names))
    worst = _compare(theirs, ours, names)
    print(f"ecos vs our master, {implementation} FMUs, {len(theirs)} steps: largest difference {worst:.3g} "
          f"of the vector's scale")
    assert worst <= 1e-12
    # the run is not trivial: the base moves and the loop works
    assert np.ptp(ours["base.base_pose[2]"]) > 1e-4 and np.max(np.abs(ours["controller.leg_force[1]"])) > 1e3


def test_ecos_applies_a_choice_other_than_the_default(native, tmp_path):
    """feedforward = none (the default is moving_base): ecos must compute it, as ours does."""
    scenario, paths, descriptions, params = configure(native, "none", stop=0.05)
    path = ssp.export_ssp(scenario, paths, params, tmp_path / "none.ssp")
    ours = run_columns(single.run(scenario, paths, params, tmp_path, "ours"))
    names = columns(scenario, descriptions, ["controller.leg_force", "plant.pose"])
    assert _compare(run_ecos(path, scenario, names), ours, names) <= 1e-12


def test_the_old_naming_ran_on_defaults(native, tmp_path):
    """What the per-instance set names cost: ecos initialised without the set's name (as a
    user of the old export, whose sets had three different names) runs on the FMUs'
    defaults; the pose differs from the scenario's by the amount printed."""
    scenario, paths, descriptions, params = configure(native)
    path = ssp.export_ssp(scenario, paths, params, tmp_path / "slew.ssp")
    ours = run_columns(single.run(scenario, paths, params, tmp_path, "ours"))
    names = columns(scenario, descriptions, ["plant.pose"])
    unbound = run_ecos(path, scenario, names, parameter_set=None)
    bound = run_ecos(path, scenario, names)
    translation = [j for j, n in enumerate(names) if n in {f"plant.pose[{i}]" for i in (1, 2, 3)}]
    rms = lambda rows: np.sqrt(
        np.mean((rows[:, translation] - np.array([ours[n][1:] for n in names]).T[:, translation]) ** 2)
    )
    off = max(np.max(np.abs(unbound[:, j] - ours[names[j]][1:])) for j in translation)
    print(f"ecos without the parameter set: platform position up to {off * 1e3:.3g} mm off our master "
          f"(RMS {rms(unbound) * 1e6:.3g} um); with it: RMS {rms(bound) * 1e6:.3g} um")
    assert rms(bound) < 1e-12 and off > 1e-5


def test_ecos_steps_on_past_a_discard(native, tmp_path):
    """An unheld platform (no feedforward, zero gains) leaves its stroke at ~0.2 s and the
    plant answers fmi2Discard. Our master stops there, naming it; ecos 0.7.2 steps on to the
    stop time with no error, the plant's outputs frozen at its last accepted state (a
    host's behaviour to know: docs/defaults-and-masters.md)."""
    scenario, paths, descriptions, params = configure(native, "none", stop=0.5)
    params["controller"].update(kp=0.0, ki=0.0, kd=0.0)
    with pytest.raises(FmuError, match="status DISCARD"):
        single.run(scenario, paths, params, tmp_path, "ours")
    path = ssp.export_ssp(scenario, paths, params, tmp_path / "falling.ssp")
    rows = run_ecos(path, scenario, columns(scenario, descriptions, ["plant.pose"]))
    assert len(rows) == 500
    frozen = np.flatnonzero(np.any(np.diff(rows, axis=0) != 0, axis=1))[-1] + 2   # first row of the frozen tail
    print(f"ecos: the plant's pose stops changing after step {frozen} of 500 (t = {frozen * scenario.step:.3f} s); "
          f"ecos ran to {len(rows) * scenario.step:.3f} s")
    assert 100 < frozen < 400 and np.all(rows[frozen:] == rows[frozen])
