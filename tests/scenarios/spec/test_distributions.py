"""Uncertain inputs' distributions: the file's words, and samples against scipy.stats."""
import numpy as np
import pytest
from scipy import stats

from scenarios.spec import ScenarioError
from scenarios.spec.distributions import Distribution, parse


def test_parse_reads_units_and_kinds():
    d = parse("f", "leg_offset", {"distribution": "uniform", "half_width": "0.1 mm"}, "m")
    assert d == Distribution("uniform", pytest.approx(1e-4))
    assert parse("f", "m", {"distribution": "normal", "sd": "5 kg"}, "kg") == Distribution("normal", 5.0)


@pytest.mark.parametrize("value, words", [
    ({"distribution": "gauss", "sd": 1.0}, "distribution 'gauss' is not one of uniform, normal"),
    ({"distribution": "normal", "half_width": 1.0}, "a normal distribution takes exactly 'sd'"),
    ({"distribution": "uniform", "half_width": 1.0, "sd": 2.0}, "unknown key(s): sd"),
    ({"distribution": "uniform", "half_width": "0.1 deg"}, "f: x.half_width: '0.1 deg' is in rad"),
    ({"distribution": "uniform", "half_width": "-1 mm"}, "must be >= 0"),
    ("0.1 mm", "expected a table"),
])
def test_parse_names_the_problem(value, words):
    with pytest.raises(ScenarioError) as info:
        parse("f", "x", value, "m")
    assert words in str(info.value)


@pytest.mark.parametrize("d, truth", [(Distribution("uniform", 2.0), stats.uniform(-2.0, 4.0)),
                                      (Distribution("normal", 3.0), stats.norm(0.0, 3.0))])
def test_ppf_and_std_are_the_distributions(d, truth):
    u = np.linspace(0.01, 0.99, 99)
    np.testing.assert_allclose(d.ppf(u), truth.ppf(u), rtol=1e-12, atol=1e-12)
    assert d.std == pytest.approx(truth.std(), rel=1e-12)
