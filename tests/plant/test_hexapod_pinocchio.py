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


COM = np.array([0.05, -0.03, 0.4])   # [m] in {P}: off o_P on every axis, the subreflector's height above it


@pytest.fixture(scope="module")
def offset(params):
    return dataclasses.replace(params, platform_com=COM)


@pytest.mark.parametrize("solve", ["forward", "inverse"])
@pytest.mark.parametrize("moving", [False, True], ids=["fixed_base", "moving_base"])
def test_dynamics_agree_with_the_payload_off_centre(offset, solve, moving):
    """The centre-of-mass offset c: Pinocchio's platform body carries it as its inertia's lever."""
    test_dynamics_agree(offset, solve, moving)


def test_comparison_sees_the_offset(params, offset):
    """The offset changes the dynamics by far more than RTOL: a kernel that ignored it would fail."""
    pose, rate, _, forces, base = _states(5, True)
    kit = forward_dynamics(params, pose[0], rate[0], forces[0], *(b[0] for b in base))
    other = PinocchioHexapod(offset, moving_base=True).forward_dynamics(pose[0], rate[0], forces[0],
                                                                         *(b[0] for b in base))
    assert relative(other, kit) > 1e3 * RTOL


def test_static_moment_of_the_offset(params, offset):
    """At rest the leg forces' moment about o_P, less that of a centred payload, is m g x R c: the
    offset weight's moment, balanced (numpy statics, no dynamics of the kit's)."""
    rng = np.random.default_rng(6)
    pose, _, _ = platform_states(rng, 5)
    zero = np.zeros((5, 6))
    for k in range(5):
        moments, pushes = [], []
        for p in (offset, params):
            forces = inverse_dynamics(p, pose[k], zero[k], zero[k])
            R = _rotation(pose[k, 3:])
            rho = (R @ p.platform_joints.T).T
            legs = pose[k, :3] + rho - p.base_joints
            s = legs / np.linalg.norm(legs, axis=1)[:, None]
            moments.append(np.sum(np.cross(rho, forces[:, None] * s), axis=0))
            pushes.append(forces @ s)
        g = np.array([0.0, 0.0, -params.gravity])
        expected = np.cross(params.platform_mass * g, _rotation(pose[k, 3:]) @ COM)
        assert np.allclose(moments[0] - moments[1], expected, rtol=1e-9, atol=1e-9 * np.abs(expected).max())
        assert np.allclose(pushes[0], pushes[1], rtol=1e-9, atol=1e-6)   # the same weight: the same push


def _rotation(rpy):
    """Rz(yaw) Ry(pitch) Rx(roll), as the kit's poses."""
    (cr, cp, cy), (sr, sp, sy) = np.cos(rpy), np.sin(rpy)
    Rx = np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]])
    Ry = np.array([[cp, 0, sp], [0, 1, 0], [-sp, 0, cp]])
    Rz = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]])
    return Rz @ Ry @ Rx
