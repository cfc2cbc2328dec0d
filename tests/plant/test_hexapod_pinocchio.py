"""The kit's Kane kernel against Pinocchio's constrained dynamics (tests/plant/pinocchio_hexapod.py):
inverse and forward dynamics over random states near home, fixed base and moving base."""
import dataclasses

import numpy as np
import pytest

from plant.hexapod.model import StewartParams, forward_dynamics, inverse_dynamics
from tests.plant.test_hexapod_truth import base_states, platform_states

pytest.importorskip("pinocchio")
from tests.plant.pinocchio_hexapod import PinocchioHexapod  # noqa: E402  (after the skip)

N = 40
RTOL = 1e-9   # relative to the state's largest |value|; measured ~1e-14


def relative(a, b):
    return np.max(np.abs(a - b)) / np.max(np.abs(b))


def _states(seed, moving):
    rng = np.random.default_rng(seed)
    pose, rate, acc = platform_states(rng, N)
    forces = rng.uniform(-3e4, 3e4, (N, 6))
    base = base_states(rng, N) if moving else (None, None, None)
    return pose, rate, acc, forces, base


@pytest.fixture(scope="module")
def params():
    return StewartParams.paper(d=0.2)   # joint circle off o_P: the platform's offsets enter


KIT = {"forward": forward_dynamics, "inverse": inverse_dynamics}


@pytest.mark.parametrize("solve", ["forward", "inverse"])
@pytest.mark.parametrize("moving", [False, True], ids=["fixed_base", "moving_base"])
def test_dynamics_agree(params, solve, moving):
    """Forward: accelerations under random leg forces; inverse: forces for random accelerations."""
    pose, rate, acc, forces, base = _states(1, moving)
    given = forces if solve == "forward" else acc
    kit = KIT[solve](params, pose, rate, given, *(b if moving else 0 for b in base))
    engine = getattr(PinocchioHexapod(params, moving_base=moving), f"{solve}_dynamics")
    worst = max(relative(engine(pose[k], rate[k], given[k], *(b[k] if moving else None for b in base)), kit[k])
                for k in range(N))
    assert worst < RTOL


def test_base_at_rest_is_the_fixed_base(params):
    """The root free-flyer held at identity by its constraint gives the tree hung from the universe."""
    pose, rate, _, forces, _ = _states(3, False)
    rest = np.zeros(6)
    fixed, moving = PinocchioHexapod(params), PinocchioHexapod(params, moving_base=True)
    for k in range(5):
        a = fixed.forward_dynamics(pose[k], rate[k], forces[k])
        assert relative(moving.forward_dynamics(pose[k], rate[k], forces[k], rest, rest, rest), a) < 1e-12


def test_comparison_sees_the_legs_axial_inertia(params):
    """The comparison can fail: without the legs' axial inertia (which the base's spin about a leg
    excites) Pinocchio's moving-base accelerations leave the kit's by far more than RTOL."""
    pose, rate, _, forces, base = _states(4, True)
    flat = dataclasses.replace(params, cylinder_inertia=params.cylinder_inertia * [0, 1, 1],
                               rod_inertia=params.rod_inertia * [0, 1, 1])
    kit = forward_dynamics(params, pose[0], rate[0], forces[0], *(b[0] for b in base))
    other = PinocchioHexapod(flat, moving_base=True).forward_dynamics(pose[0], rate[0], forces[0],
                                                                       *(b[0] for b in base))
    assert relative(other, kit) > 1e3 * RTOL
