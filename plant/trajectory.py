"""Rest-to-rest point-to-point motion: the quintic the paper's scenarios use (computed by
plant/c/telescope.c, mb_tel_quintic, which the native FMUs share)."""
import numpy as np

from plant._kernel import ffi, lib


def _doubles(array):
    """A double* onto array (a contiguous float64 copy if it is not one; outputs are)."""
    return ffi.from_buffer("double[]", np.ascontiguousarray(array, dtype=float))


def quintic(start, stop, duration, t):
    """Position, velocity, acceleration (n, dim) of s(tau) = 10 tau^3 - 15 tau^4 + 6 tau^5
    from ``start`` to ``stop`` over ``duration``; held at the ends outside [0, duration].
    ``start`` and ``stop`` are vectors (or scalars) of one length; t has any shape, the
    results have shape t.shape + (dim,)."""
    start, stop = np.broadcast_arrays(np.atleast_1d(np.asarray(start, dtype=float)),
                                      np.atleast_1d(np.asarray(stop, dtype=float)))
    if start.ndim != 1:
        raise ValueError(f"start and stop must be vectors, got shape {start.shape}")
    if not duration > 0:
        raise ValueError(f"duration must be positive, got {duration}")
    t = np.asarray(t, dtype=float)
    pos, vel, acc = (np.empty(t.shape + start.shape) for _ in range(3))
    lib.mb_tel_quintic(start.size, _doubles(start), _doubles(stop), float(duration), t.size,
                       _doubles(t.ravel()), _doubles(pos), _doubles(vel), _doubles(acc))
    return pos, vel, acc
