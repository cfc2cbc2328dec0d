"""Disturbance observer on the controller's model of a leg (the equations: controller/c/observer.c).

The moving-base model already predicts the leg forces the reference motion needs; a load
cell says what the legs really push with. Their gap, corrected by the leg-space mass times
the measured acceleration off the reference, is the force the plant got from elsewhere (the
wind), which the controller subtracts from its command through the low-pass Q at
``observer_bandwidth``. The mass is a leg-space matrix (observer_mass_matrix): one scalar on
the diagonal, as before, or the controller's model matrix, whose every mode then meets its own
mass. One C function for the pythonfmu FMU and its native twin, so both
give the same numbers bit for bit; its state (two filter states and two past length errors per leg) is explicit so an
FMU saves it with its state.
"""
import numpy as np

from controller._kernel import ffi, lib

STATES_PER_LEG = lib.MB_OBSERVER_STATES


def observer_start(length_error):
    """The state at the start: filters at rest, the length-error history at ``length_error``
    (so the second difference starts at 0)."""
    state = np.empty(STATES_PER_LEG * len(length_error))
    buf = lambda a: ffi.from_buffer("double[]", a)
    lib.mb_observer_start(len(length_error), buf(length_error), buf(state))
    return state


def observer_mass_matrix(mass, model, leg_space):
    """The observer's leg-space mass matrix (n, n) [kg]: ``mass`` I (``leg_space`` false), or
    ``model`` (the controller's leg-space mass matrix, (n, n)) shifted on its diagonal so that
    its mean diagonal is ``mass`` (its modes keep their shapes and spread)."""
    model = np.ascontiguousarray(model, dtype=float)
    out = np.empty_like(model)
    lib.mb_observer_mass(len(model), int(bool(leg_space)), mass, ffi.from_buffer("double[]", model),
                         ffi.from_buffer("double[]", out))
    return out


def observer_update(bandwidth, mass, state, force_gap, length_error, dt):
    """One step: (estimate (n,), new_state (4 n,)) from the state before the step, the force
    gap f_model(ref) - f_measured [N] and the length error l_measured - l_reference [m]
    (float64 arrays of n legs, C-contiguous), ``bandwidth`` [Hz] > 0, ``mass`` the leg-space
    mass matrix (n, n) [kg] (observer_mass_matrix), ``dt`` [s] > 0."""
    n = len(length_error)
    estimate, new_state = np.empty(n), np.empty(STATES_PER_LEG * n)
    buf = lambda a: ffi.from_buffer("double[]", a)
    mass = np.ascontiguousarray(mass, dtype=float)
    if mass.shape != (n, n):
        raise ValueError(f"observer mass matrix must be ({n}, {n}), got {mass.shape}")
    if not 1 <= n <= lib.MB_OBSERVER_MAX_LEGS:
        raise ValueError(f"the observer takes 1 to {lib.MB_OBSERVER_MAX_LEGS} legs, got {n}")
    lib.mb_observer_update(n, bandwidth, buf(mass), dt, buf(state), buf(force_gap), buf(length_error), buf(estimate),
                           buf(new_state))
    return estimate, new_state
