"""The 3T mechanism's settings refused before anything runs (issue 38, 6): an assembly mode
that is not +1/-1, a mode or initial position that does not assemble, and a slider
reference whose amplitude leaves the workspace over the run; each refusal names the key
and the range that does assemble, checked against eq. 11 in closed form. Nothing of the
model's own errors reaches the caller of movingbase.run."""
import math

import numpy as np
import pytest

import movingbase
from plant.mechanism3t import model
from scenarios import spec
from scenarios.cosim.fmi import description
from scenarios.runs.runner import fmu_paths, resolve
from tests.scenario_helpers import edited, refused

TEXT = resolve("mechanism3t_paper").read_text()
P = model.Mechanism3TParams.paper()
CENTRE = np.array(model.PAPER_REFERENCE_RHO_MM) * model.MM


def _eq11_x_range(y_a1, y_a3, mode):
    """x_A2 for which eq. 11's arccos argument (e - a - x_A2 + mode sqrt(l6^2 - N4^2))/l4 lies
    in [-1, 1], N4 = y_A1 + d - y_A3: the closed form, apart from the model's code."""
    root = math.sqrt(P.l6 ** 2 - (y_a1 + P.d - y_a3) ** 2)
    return P.e - P.a + mode * root - P.l4, P.e - P.a + mode * root + P.l4


@pytest.fixture(scope="module")
def descriptions():
    return {inst: description(p) for inst, p in fmu_paths(spec.parse(TEXT, "bad.toml")).items()}


def _bound(descriptions, *changes):
    return spec.bind(spec.parse(edited(TEXT, *changes), "ok.toml"), descriptions)


CONTROLLER = ('fmu = "slider_controller"\n', 'fmu = "slider_controller"\nparameters = {{ {} }}\n')
PLANT = ('fmu = "mechanism3t_plant"\n', 'fmu = "mechanism3t_plant"\nparameters = {{ {} }}\n')


def _with(change, values):
    return change[0], change[1].format(values)


def test_the_reach_along_the_paper_motion_is_eq_11_s(descriptions):
    low, high = _eq11_x_range(CENTRE[1], CENTRE[2], 1)      # the motion keeps N4: y_A1 and y_A3 move alike
    span = model.reach(P, CENTRE, 1)
    assert low - CENTRE[0] <= span[0] < low - CENTRE[0] + 1e-4      # the grid's 0.1 mm, inside
    assert high - CENTRE[0] - 1e-4 < span[1] <= high - CENTRE[0]
    assert model.reach(P, CENTRE, -1) is None               # mode -1 does not assemble the paper's centre
    largest = (CENTRE[0] - low) * 1e3                       # 104.12 mm: sin reaches -1 over the 25.1 s run
    message = refused(edited(TEXT, _with(CONTROLLER, f'amplitude = "{largest + 0.2:.1f} mm"')),
                      "fmus.controller.parameters.amplitude", descriptions=descriptions)
    assert "assembly mode +1" in message and "sin from -1 to 1 over 0..25.1 s" in message
    assert f"from {span[0] * 1e3:+.4g} to {span[1] * 1e3:+.4g} mm" in message
    assert f"at most {math.floor(largest * 10) / 10:.4g} mm" in message
    _bound(descriptions, _with(CONTROLLER, f'amplitude = "{largest - 0.2:.1f} mm"'))   # just inside: accepted


def test_the_amplitude_is_judged_over_the_run_s_own_times(descriptions):
    """1 s at 0.5 rad/s: sin runs 0 .. sin(0.5), upward only, so the upper end of the reach counts."""
    high = _eq11_x_range(CENTRE[1], CENTRE[2], 1)[1] - CENTRE[0]
    largest = high / math.sin(0.5)                          # 533.8 mm
    _bound(descriptions, ('stop_time = "25.1 s"', 'stop_time = "1 s"'),
           _with(CONTROLLER, f'amplitude = "{largest * 1e3 - 1:.0f} mm"'))
    message = refused(edited(TEXT, ('stop_time = "25.1 s"', 'stop_time = "1 s"'),
                             _with(CONTROLLER, f'amplitude = "{largest * 1e3 + 1:.0f} mm"')),
                      "fmus.controller.parameters.amplitude", "sin from 0 to 0.4794 over 0..1 s",
                      descriptions=descriptions)
    assert f"at most {largest * 1e3:.4g} mm" in message or f"at most {largest * 1e3 - 0.1:.4g} mm" in message


@pytest.mark.parametrize("change, key, parts", [
    (_with(PLANT, "mode = 0"), "fmus.plant.parameters.mode", ["plant.mode = 0: the assembly mode is +1 or -1"]),
    (_with(CONTROLLER, "mode = 0"), "fmus.controller.parameters.mode", ["controller.mode = 0: the assembly mode"]),
    (_with(PLANT, "mode = -1"), "fmus.plant.parameters.mode",
     ["plant.mode = -1: the 3T mechanism does not assemble at plant.initial_position = [94.25, -144.36, -47.68] mm "
      "(default)", "eq. 11", "mode -1 assembles x_A2 from", " to 49.8 mm", "mode +1 assembles it"]),
    (_with(CONTROLLER, "mode = -1"), "fmus.controller.parameters.mode", ["controller.mode = -1", "to 49.8 mm"]),
    (_with(PLANT, 'initial_position = ["400 mm", "-144.36 mm", "-47.68 mm"]'), "fmus.plant.parameters.initial_position",
     ["plant.initial_position = ['400 mm'", "assembly mode +1 (plant.mode)", "mode +1 assembles x_A2 from",
      " to 350.1 mm", "mode -1 does not either"]),
])
def test_modes_and_positions_that_do_not_assemble_are_refused_naming_key_and_range(descriptions, change, key, parts):
    refused(edited(TEXT, change), key, *parts, descriptions=descriptions)
    if "to 49.8 mm" in parts:       # eq. 11's own upper end for mode -1 at the paper's y_A1, y_A3: 49.87 mm
        assert _eq11_x_range(CENTRE[1], CENTRE[2], -1)[1] * 1e3 == pytest.approx(49.87, abs=0.01)


@pytest.mark.parametrize("given", [
    {"controller.amplitude": "0.3 m"}, {"controller.amplitude": "1e300 m"},   # (a grid of 1e304 points once)
    {"plant.mode": -1, "controller.mode": -1}, {"plant.mode": -1},
    {"plant.mode": 0}, {"controller.mode": 0}, {"controller.initial_position": [0.5, 0.1, 0.1]},
])
def test_movingbase_run_refuses_before_anything_runs(given, monkeypatch):
    from scenarios.runs import single
    monkeypatch.setattr(single, "run", lambda *a, **k: pytest.fail("a run started"))
    with pytest.raises(spec.ScenarioError) as info:
        movingbase.run("mechanism3t_paper", set=given, progress=False)
    key = next(iter(given))
    assert f"set['{key}']" in str(info.value) or "set['plant.mode']" in str(info.value)
