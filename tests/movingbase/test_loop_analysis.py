"""movingbase.loop_analysis (issue 39): a scenario's control loop as python-control
objects, with the numbers the guard refuses a run by (its step limit, its observer
limit), each checked against the closed loop's poles computed apart (python-control's
feedback of each mode's loop, not the guard's characteristic polynomial)."""
import re

import control
import numpy as np
import pytest

import movingbase
from controller import design


def _radius(analysis, step, model=None):
    """The largest closed-loop pole radius over every mode at ``step``."""
    loops = [design.mode_loop(m, analysis.gains, step, model or analysis.model) for m in analysis.masses]
    return max(np.abs(control.feedback(one).poles()).max() for one in loops)


def test_the_step_limit_is_the_guard_s_and_the_poles_cross_there():
    analysis = movingbase.loop_analysis("telescope_slew", ci=True)
    assert analysis.stable and analysis.step == 1e-3 and analysis.observer_limit is None
    with pytest.raises(movingbase.ScenarioError) as refused:
        movingbase.run("telescope_slew", ci=True, progress=False, set={"step": "5 ms"})
    said = re.search(r"beyond the predicted stability limit ([0-9.]+) ms", str(refused.value))
    assert float(said.group(1)) == float(f"{analysis.step_limit * 1e3:.4g}")
    # the limit found by bisection to 1e-3: stable 1 % below it, unstable 1 % above
    assert _radius(analysis, 0.99 * analysis.step_limit) < 1 < _radius(analysis, 1.01 * analysis.step_limit)
    assert repr(analysis).startswith("<LoopAnalysis 'telescope_slew' 'controller': step 1 ms, predicted limit 2 ms "
                                     "(stable); 6 modes")


def test_the_margins_are_those_of_the_loop_s_frequency_response():
    analysis = movingbase.loop_analysis("telescope_slew", ci=True)
    found = analysis.margins()
    heaviest = analysis.open_loop()                 # the heaviest mode, as the design is set on it
    z = np.exp(1j * 2 * np.pi * found.crossover_hz * analysis.step)
    assert abs(heaviest(z)) == pytest.approx(1.0, abs=2e-3)           # |L| = 1 at the crossover
    assert 180 + np.degrees(np.angle(heaviest(z))) == pytest.approx(found.phase_margin_deg, abs=0.2)
    table = analysis.table()
    assert table["phase margin"].min() == pytest.approx(found.modal_phase_margin_deg)
    assert (table["pole radius"] < 1).all() and table.attrs["units"]["crossover"] == "Hz"
    assert list(table["mass"]) == sorted(table["mass"]) and table["mass"].iloc[-1] == found.design_mass


def test_the_observer_limit_is_the_guard_s_and_the_poles_cross_there():
    """The shipped observer (32 Hz, its mass per leg-space mode, issue 41) at 1 ms: the guard's
    limit is 340 Hz (the scalar 2000 kg's was 253 Hz), so 440 Hz (1.3x) is refused naming it."""
    analysis = movingbase.loop_analysis("telescope_slew_observer", ci=True)
    limit = analysis.observer_limit
    assert analysis.model.observer_leg_space
    assert limit == pytest.approx(340.5, rel=0.02) and limit < 440.0
    with pytest.raises(movingbase.ScenarioError) as refused:
        movingbase.run("telescope_slew_observer", ci=True, progress=False,
                       set={"sweep": {"parameter": "controller.observer_bandwidth", "values": ["440 Hz"]}})
    assert f"beyond its predicted limit {limit:.3g} Hz at this step" in str(refused.value)
    below, above = (design.LoopModel(**{**vars(analysis.model), "observer_bandwidth": f * limit}) for f in (0.97, 1.03))
    assert _radius(analysis, analysis.step, below) < 1 < _radius(analysis, analysis.step, above)
