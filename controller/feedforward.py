"""Model feedforward for the hexapod's leg forces, and reference leg lengths and rates.

The feedforward supplies the force the reference motion needs (gravity above all: about
5.2 kN of tension per leg at rest), so the PID only corrects model and tracking errors.
The mode says how much of the base motion the controller knows about:

* ``"none"``: zero; the PID's integrator has to find even the gravity load.
* ``"fixed_base"``: inverse dynamics with the base ignored (gravity fixed in {B}), the
  model a controller unaware of the telescope's motion would use.
* ``"moving_base"``: full inverse dynamics with the measured or commanded base motion.
"""
import numpy as np

from plant.hexapod.model import (
    StateInverseDynamics,
    inverse_dynamics,
    inverse_dynamics_terms,
    inverse_kinematics,
    pose_jacobian,
)

FEEDFORWARD_MODES = ("none", "fixed_base", "moving_base")


def model_fidelity(mode):
    """The plant fidelity a feedforward mode computes with (the base is ignored unless
    the mode is moving_base), or an error naming the modes."""
    if mode not in FEEDFORWARD_MODES:
        raise ValueError(f"unknown feedforward mode {mode!r}; choose one of {FEEDFORWARD_MODES}")
    return "full" if mode == "moving_base" else "no_base"


def feedforward_forces(params, mode, pose, pose_rate, pose_acc, base_pose=0, base_rate=0, base_acc=0):
    """Leg forces (..., 6) [N] for the reference motion (pose, rate, acc of {P} in {B}) and
    the base motion ({B} in {W}); positive extends the leg."""
    fidelity = model_fidelity(mode)
    if mode == "none":
        return np.zeros(np.shape(pose))
    if fidelity == "no_base":
        return inverse_dynamics(params, pose, pose_rate, pose_acc, fidelity=fidelity)
    return inverse_dynamics(params, pose, pose_rate, pose_acc, base_pose, base_rate, base_acc, fidelity=fidelity)


def reference_legs(params, pose, pose_rate):
    """Reference leg lengths and leg rates (..., 6) of a reference pose trajectory
    (pose and its RPY-angle rates, (..., 6)): l = IK(pose), dl/dt = dl/d(pose) @ rate."""
    pose_rate = np.asarray(pose_rate, dtype=float)
    if not np.isfinite(pose_rate).all():
        raise ValueError("pose_rate contains NaN or inf")
    lengths = inverse_kinematics(params, pose)
    rates = (pose_jacobian(params, pose) @ pose_rate[..., None])[..., 0]
    return lengths, rates


def feedforward_and_legs(params, mode, pose, pose_rate, pose_acc, base_pose=0, base_rate=0, base_acc=0):
    """(feedforward forces, reference leg lengths, reference leg rates) from one call of
    the compiled model: what the controller FMU needs every step."""
    fidelity = model_fidelity(mode)
    if fidelity == "no_base":
        forces, terms = inverse_dynamics_terms(params, pose, pose_rate, pose_acc, fidelity=fidelity)
    else:
        forces, terms = inverse_dynamics_terms(params, pose, pose_rate, pose_acc, base_pose, base_rate, base_acc,
                                               fidelity=fidelity)
    return (forces if mode != "none" else np.zeros_like(forces)), terms.leg_lengths, terms.leg_rates


class Feedforward:
    """feedforward_and_legs for one state at a time, on the plant's preallocated
    single-state path: what the controller FMU calls every step."""

    def __init__(self, params, mode):
        self.mode = mode
        self.model = StateInverseDynamics(params, model_fidelity(mode))

    def __call__(self, pose, pose_rate, pose_acc, base_pose, base_rate, base_acc):
        """(forces, reference leg lengths, reference leg rates), each (6,)."""
        forces, lengths, rates = self.model(pose, pose_rate, pose_acc, base_pose, base_rate, base_acc)
        return (forces[0] if self.mode != "none" else np.zeros(6)), lengths[0], rates[0]
