"""Rest-to-rest point-to-point motion: the quintic the paper's scenarios use."""
import numpy as np


def quintic(start, stop, duration, t):
    """Position, velocity, acceleration (n, dim) of s(tau) = 10 tau^3 - 15 tau^4 + 6 tau^5
    from ``start`` to ``stop`` over ``duration``; held at the ends outside [0, duration]."""
    start, stop = np.asarray(start, dtype=float), np.asarray(stop, dtype=float)
    if not duration > 0:
        raise ValueError(f"duration must be positive, got {duration}")
    tau = np.clip(np.asarray(t, dtype=float) / duration, 0.0, 1.0)[..., None]
    inside = (np.asarray(t)[..., None] > 0) & (np.asarray(t)[..., None] < duration)
    s = tau ** 3 * (10 - 15 * tau + 6 * tau ** 2)
    ds = 30 * tau ** 2 * (1 - tau) ** 2 / duration * inside
    dds = 60 * tau * (1 - tau) * (1 - 2 * tau) / duration ** 2 * inside
    delta = stop - start
    return start + s * delta, ds * delta, dds * delta
