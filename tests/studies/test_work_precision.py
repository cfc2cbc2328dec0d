"""The work-precision study: its reference is converged and sees what the FMUs see, the
co-simulation converges to it at first order in the communication step, the Pareto
front is right, and (slow) the shipped default sits on or near the front."""
import dataclasses

import numpy as np
import pytest

from scenarios.runs import single
from studies import reference
from studies import work_precision as W

STOP = 4.0            # the paper manoeuvre cut to 2 s of rest and the first 2 s of the manoeuvre
STEPS = (2e-3, 1e-3, 0.5e-3)


@pytest.fixture(scope="module")
def paper():
    prep = W.prepare("paper_manoeuvre", stop_time=STOP)
    return prep, reference.solve(prep.scene())


@pytest.fixture(scope="module")
def errors_by_step(paper, tmp_path_factory):
    prep, ref = paper
    tmp = tmp_path_factory.mktemp("work_precision")
    out = {}
    for master_, extrapolation in W.MASTERS:
        for h in STEPS:
            _, times, pose, forces = W.cosimulate(prep, W.Config(h, master_, extrapolation), tmp)
            out[(master_, extrapolation, h)] = reference.compare(ref, times, pose, forces, prep.window)
    return out


def test_reference_is_converged(paper, errors_by_step):
    """Halving the tolerances (relative and absolute), or another method (explicit DOP853
    at rtol 1e-12), moves the reference by less than 1e-3 of the smallest co-simulation
    error it judges here (it moves by ~1e-7 µm and ~1e-6 N; the errors are 0.07 µm and
    0.34 N and up)."""
    prep, ref = paper
    times = np.arange(prep.window[0], prep.window[1] + 1e-9, W.RECORD_INTERVAL)
    smallest = {key: min(e[key] for e in errors_by_step.values())
                for key in ("pose_rms_um", "rot_rms_urad", "force_rms_N")}
    assert not ref.saturated
    for other in (reference.solve(ref.scene, rtol=ref.rtol / 2, atol_scale=0.5),
                  reference.solve(ref.scene, rtol=1e-12, method="DOP853")):
        moved = reference.difference(ref, other, times)
        assert moved["pose_max_um"] < 1e-3 * smallest["pose_rms_um"], moved
        assert moved["rot_max_urad"] < 1e-3 * smallest["rot_rms_urad"], moved
        assert moved["force_max_N"] < 1e-3 * smallest["force_rms_N"], moved


@pytest.mark.parametrize("name", list(W.SCENES))
def test_reference_sees_the_motion_the_telescope_fmu_outputs(name, tmp_path):
    """The reference's base and reference motion is the telescope FMU's, to rounding."""
    prep = W.prepare(name)
    start = prep.scenario.start_time
    signals = ["base.base_pose", "base.base_rate", "base.base_acc", "base.reference_pose",
               "base.reference_rate", "base.reference_acc"]
    scenario = dataclasses.replace(prep.scenario, step=1e-3, stop_time=start + 3.0, record=signals,
                                   record_interval=0.1)
    run = single.run(scenario, prep.paths, prep.values, tmp_path, "signals")
    data = np.column_stack([run.records.time, run.records.values])
    expected = prep.scene().motion(data[:, 0])
    for k, name_ in enumerate(reference.SIGNALS):
        np.testing.assert_allclose(data[:, 1 + 6 * k: 7 + 6 * k], expected[name_], rtol=1e-13, atol=1e-13,
                                   err_msg=name_)


@pytest.mark.parametrize("master_", W.MASTERS, ids=lambda m: W.MASTER_LABELS[m])
def test_error_shrinks_at_first_order_with_the_step(errors_by_step, master_):
    """Hold, delay and extrapolation are all first order: halving h halves the error."""
    for key in ("pose_rms_um", "force_rms_N"):
        errors = np.array([errors_by_step[(*master_, h)][key] for h in STEPS])
        orders = np.log2(errors[:-1] / errors[1:])
        assert np.all((orders > 0.85) & (orders < 1.15)), (key, errors, orders)


def test_pareto_front_on_hand_made_points():
    costs = np.array([1, 2, 3, 4, 2, 5, np.nan, 3, 8], dtype=float)
    errors = np.array([5, 3, 3.5, 1, 3, 0.5, 0.1, 1, 0.4])
    #   (3, 3.5) is beaten by (2, 3); (4, 1) by (3, 1) at equal error; the twin (2, 3)s do not
    #   beat each other; a NaN (failed run) is never on the front.
    expected = [True, True, False, False, True, True, False, True, True]
    assert W.pareto_front(costs, errors).tolist() == expected
    assert W.pareto_front([1.0], [1.0]).tolist() == [True]

    d = W.front_distance(costs, errors, 2)           # (3, 3.5): front between (1, 5) and (2, 3)
    assert not d["on_front"]
    assert d["cost_ratio"] == pytest.approx(3 / 2 ** (np.log(5 / 3.5) / np.log(5 / 3)))
    assert d["error_ratio"] == pytest.approx(3.5)    # the front at cost 3 is (3, 1)
    assert d["attainable_cost_ratio"] == pytest.approx(1.5)
    assert d["attainable_error_ratio"] == pytest.approx(3.5)
    d = W.front_distance(costs, errors, 3)           # (4, 1): the front at error 1 is (3, 1)
    assert d["cost_ratio"] == pytest.approx(4 / 3)
    assert d["error_ratio"] == pytest.approx(1 / 0.5 ** (np.log(4 / 3) / np.log(5 / 3)))
    assert not W.near_front(d)
    d = W.front_distance(costs, errors, 7)
    assert d["on_front"] and d["cost_ratio"] == d["error_ratio"] == 1.0 and W.near_front(d)

    near = W.front_distance(np.r_[costs, 2.1], np.r_[errors, 3.0], 9)   # 5 % dearer than (2, 3)
    assert not near["on_front"] and near["cost_ratio"] == pytest.approx(1.05) and W.near_front(near)


@pytest.mark.slow
def test_shipped_default_is_on_or_near_the_front_for_the_paper_manoeuvre():
    """The whole sweep (a few minutes): the shipped default (1 ms, Jacobi, rk4 x1, full
    fidelity) is on the position-error front or within 10 % of it in cost at equal error."""
    results, _ = W.study("paper_manoeuvre", W.sweep(), repeats=3, progress=False)
    v = W.verdict(results, "pose_rms_um")
    assert v is not None, "the default failed or was not run"
    assert W.near_front(v), W.describe(v, "position RMS") + "\n" + W.table(results)
