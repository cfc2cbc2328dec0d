"""The kit's verdict on random scenes against an independent judge of their records
(tests/judge.py): no miss, and no run the kit ran and flagged that the judge calls clean.

Measured on seeds 0-59 (this file): 42 agree, 0 misses, 18 refusals the judge cannot
confirm from its short runs (steps at 1.0-1.3x the predicted limit, or gains the kit
predicts unstable at any step): whether those loops grow needs longer runs than these
1.5-3 s, so they are counted and printed, not judged here."""
import warnings

import movingbase
import pytest

from . import judge

SEEDS = range(60)


@pytest.fixture(scope="module")
def agreement():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", movingbase.RunWarning)
        return judge.agreement(SEEDS)


def test_no_run_the_judge_calls_bad_passes_the_kit(agreement):
    print(f"{len(SEEDS)} scenes: {agreement['agree']} agree, misses {agreement['misses']}, "
          f"refusals not confirmed {agreement['false_alarms']}")
    assert agreement["misses"] == []


def test_no_run_the_kit_ran_is_flagged_where_the_judge_sees_nothing(agreement):
    # the kit's flags on runs it ran (not its refusals before running) all agree with the judge
    assert [alarm for alarm in agreement["false_alarms"] if alarm[3] != "refused"] == []
    assert all(ratio >= 1.0 or kind == "3t" for _, kind, ratio, _ in agreement["false_alarms"])


def test_the_judge_can_say_bad_and_clean():
    """The issue's sweep value (kp 4x at 1.6 ms, realistic slew), run anyway: the judge sees
    its actuator limit held; the same scene at 1x and 1 ms is clean."""
    scene = judge.Scene(0, "hexapod", "telescope_slew_realistic", {
        "controller.kp": 14905828.439005414, "plant.actuator_force_limit": "25 kN", "start_time": "3 s",
        "stop_time": "6 s", "sweep": {"parameter": "controller.feedforward", "values": ["fixed_base"]}}, 1.6e-3, 0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", movingbase.RunWarning)
        kit, verdict, why = judge.kit_and_judge(scene)
        assert (kit, verdict) == ("refused", "bad") and "limit" in why
        calm = judge.Scene(0, "hexapod", scene.file, {**scene.set, "controller.kp": 3726457.1097513568}, 1e-3, 0)
        assert judge.kit_and_judge(calm)[:2] == ("clean", "clean")
