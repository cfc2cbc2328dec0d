"""The charts the main job and the 3T study write: files appear, and the figures they
report agree with the models they are drawn from."""
import pathlib

import numpy as np
import pytest

from plant import mechanism3t as m3t
from plant.stewart import HOME_POSE, StewartParams, inverse_dynamics
from scenarios import mechanism3t_charts, paper_forces


def test_paper_leg_force_chart(tmp_path):
    path = paper_forces.main(tmp_path)
    assert path.exists() and path.stat().st_size > 10_000
    t, fixed, moving = paper_forces.paper_leg_forces(n=61)
    static = inverse_dynamics(StewartParams.paper(), HOME_POSE, np.zeros(6), np.zeros(6))
    np.testing.assert_allclose(fixed[0], static, rtol=1e-12)   # starts at rest at home
    np.testing.assert_allclose(moving[0], static, rtol=1e-12)  # the base starts at identity
    assert np.all(-fixed > 0)                                  # legs in tension with the base fixed
    assert np.all(-moving[-1][[2, 5]] < 0)                     # legs 3 and 6 end in compression


def test_mechanism3t_charts(tmp_path):
    result = mechanism3t_charts.write_charts(tmp_path)
    assert all(pathlib.Path(p).exists() for p in result["charts"].values())
    history = m3t.paper_example()
    assert result["peak_force_N"] == pytest.approx(np.abs(history.forces).max(), rel=1e-12)
    assert 0 < result["workspace_volume_m3"] < result["paper_criterion_volume_m3"]
