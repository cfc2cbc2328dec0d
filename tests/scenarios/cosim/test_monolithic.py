"""The monolithic C loop of benchmarks/ (the kernels stepped without FMI) against the
co-simulation of the native FMUs it mirrors: the same leg lengths bit for bit after
every macro step, so that the co-simulation / monolithic ratio benchmarks/bench_native.py
prints is a ratio of the same work."""
import dataclasses

import numpy as np
import pytest

from benchmarks.monolithic import Pair
from fmu_src import catalogue, native_build
from fmu_src import python_build as builder
from scenarios import spec
from scenarios.runs import runner


@pytest.fixture(scope="module")
def paper():
    """paper_manoeuvre (the full 8 s: rest, then the base and platform manoeuvre), its
    native FMUs and parameters per feedforward mode of its sweep."""
    scenario, _, descriptions, values = runner.prepare(runner.resolve("paper_manoeuvre"))
    native = native_build.ensure_native(builder.available())
    paths = {inst: native[catalogue.BY_KEY[f].script] for inst, f in scenario.fmus.items()}
    swept = {}
    for item in scenario.sweep[1]:
        inst, name, value = spec.sweep_value(scenario, descriptions, item)
        swept[item] = {i: {**v, **({name: value} if i == inst else {})} for i, v in values.items()}
    return scenario, paths, swept


def both(scenario, paths, values):
    """(co-simulation, monolithic) leg lengths after initialization and every step."""
    steps = round((scenario.stop_time - scenario.start_time) / scenario.step)
    pair = Pair(scenario, paths, values)
    try:
        (done_c, cosim), (done_m, mono) = pair.cosim(steps), pair.monolithic(steps)
    finally:
        pair.close()
    assert done_c == done_m == steps
    return cosim, mono


@pytest.mark.parametrize("feedforward", ["none", "fixed_base", "moving_base"])
def test_monolithic_loop_gives_the_co_simulations_leg_lengths_bit_for_bit(paper, feedforward):
    scenario, paths, swept = paper
    cosim, mono = both(scenario, paths, swept[feedforward])
    assert np.ptp(cosim, axis=0).min() > 1e-3   # the legs do move: the comparison sees the manoeuvre
    np.testing.assert_array_equal(mono, cosim)


def test_the_comparison_sees_the_exchange(paper):
    """Held inputs instead of extrapolated ones in both runs: equal again, and not the
    extrapolated run's lengths, so the loop does follow the master's exchange."""
    scenario, paths, swept = paper
    extrapolated = both(scenario, paths, swept["moving_base"])[0]
    cosim, mono = both(dataclasses.replace(scenario, extrapolation="none"), paths, swept["moving_base"])
    np.testing.assert_array_equal(mono, cosim)
    assert np.abs(cosim - extrapolated).max() > 1e-9


def test_a_scenario_of_other_fmus_is_refused(paper):
    scenario, paths, swept = paper
    with pytest.raises(ValueError, match="Jacobi telescope"):
        Pair(dataclasses.replace(scenario, master="gauss-seidel"), paths, swept["none"])
