"""Per-leg PID on leg length, vectorised over the legs, with explicit state.

The state is one array, the integral of the length error [m s] per leg, so an FMU can
save and restore it bit for bit. One step is

    e = reference_length - length,   de = reference_rate - rate
    I' = I + dt e                    (backward Euler: the current error counts)
    F = clip(feedforward + kp e + ki I' + kd de, -force_limit, +force_limit)

The derivative acts on measured leg rates (the actuator's velocity signal), never on a
differenced length, so noise on the lengths is not amplified by 1/dt.

Anti-windup: conditional integration (clamping). A leg's integral does not move on a
step where the unclamped force is beyond the limit and the error pushes it further out;
it keeps integrating when the error pulls the force back. Chosen over back-calculation
because it needs no tracking time constant, and because back-calculation's discrete
tracking gain dt/T_t would make the anti-windup behave differently (and overshoot once
dt approaches T_t) as the co-simulation master changes the communication step.

The force limit (default 50 kN per leg) is an assumption: the paper gives no actuator
rating; 50 kN is about ten times the static leg load (~5.2 kN) and three times the
largest load change the paper reports for its moving-base stress case (~14 kN).
"""
from dataclasses import dataclass

import numpy as np

from controller._kernel import ffi, lib

DEFAULT_FORCE_LIMIT = 50e3  # N per leg (assumed, see module docstring)


@dataclass(frozen=True)
class PIDGains:
    """The same gains on every leg (the hexapod is symmetric): kp [N/m], ki [N/(m s)],
    kd [N s/m], force_limit [N] (saturation at +-force_limit)."""

    kp: float
    ki: float
    kd: float
    force_limit: float = DEFAULT_FORCE_LIMIT

    def __post_init__(self):
        for name in ("kp", "ki", "kd"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value >= 0):
                raise ValueError(f"gain {name} must be finite and >= 0, got {value}")
        if not (np.isfinite(self.force_limit) and self.force_limit > 0):
            raise ValueError(f"force_limit must be finite and > 0, got {self.force_limit}")


def _signal(value, name):
    value = np.asarray(value, dtype=float)
    if not np.isfinite(value).all():
        raise ValueError(f"{name} contains NaN or inf: {value}")
    return value


def pid_step(gains, integral, reference_length, reference_rate, length, rate, feedforward, dt):
    """One controller step: returns (force, new_integral), both shaped like the legs.

    ``integral`` is the state (zeros at start); it is not modified in place."""
    if not (np.isfinite(dt) and dt > 0):
        raise ValueError(f"time step must be finite and > 0, got {dt}")
    integral = _signal(integral, "integral state")
    error = _signal(reference_length, "reference length") - _signal(length, "measured length")
    error_rate = _signal(reference_rate, "reference rate") - _signal(rate, "measured rate")
    arrays = np.broadcast_arrays(integral, error, error_rate, _signal(feedforward, "feedforward"))
    return pid_update(gains, *(np.ascontiguousarray(a) for a in arrays), dt)


def pid_update(gains, integral, error, error_rate, feedforward, dt):
    """pid_step on errors already formed and checked (the FMU checks all its inputs for
    NaN/inf at once), all float arrays of one shape: returns (force, new_integral).
    In C (controller/c/pid.c): the controller FMU calls it every step and numpy's cost per
    small-array operation (~0.5 µs, a dozen of them) was most of that step."""
    shape = np.shape(error)
    arrays = [_contiguous(a, shape, name) for a, name in
              ((integral, "integral"), (error, "error"), (error_rate, "error_rate"), (feedforward, "feedforward"))]
    force, new_integral = np.empty(shape), np.empty(shape)
    lib.mb_pid_update(gains.kp, gains.ki, gains.kd, gains.force_limit, force.size,
                      *(ffi.from_buffer("double[]", a) for a in arrays), dt,
                      ffi.from_buffer("double[]", force), ffi.from_buffer("double[]", new_integral))
    return force, new_integral


def _contiguous(a, shape, name):
    """``a`` as C-contiguous float64 (a copy only when it is not that already), checked
    to have the error's shape: C reads exactly that many values."""
    if not (type(a) is np.ndarray and a.dtype == np.float64 and a.flags.c_contiguous):
        a = np.ascontiguousarray(a, dtype=np.float64)
    if a.shape != shape:
        raise ValueError(f"{name} has shape {a.shape}, expected {shape} like the error")
    return a
