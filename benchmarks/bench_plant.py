"""Hexapod plant speed: batched and single-state inverse dynamics, single forward
dynamics, on one core. Prints figures; it asserts nothing (speed is not a test)."""
import os
import timeit

os.environ.setdefault("NUMBA_NUM_THREADS", "1")
import numpy as np

from plant import stewart
from plant.stewart import HOME_POSE, StewartParams


def per_call(fn, number):
    fn()
    return min(timeit.repeat(fn, number=number, repeat=5)) / number


def main():
    p = StewartParams.paper()
    rng = np.random.default_rng(0)
    n = 100_000
    pose = HOME_POSE + rng.normal(size=(n, 6)) * 0.02
    rate, acc = rng.normal(size=(n, 6)) * 0.1, rng.normal(size=(n, 6))
    base = (np.array([0, 0, 25.0, 0.7, 0, 0.5]), rng.normal(size=6), rng.normal(size=6))
    forces = stewart.inverse_dynamics(p, pose[0], rate[0], acc[0])
    rows = [
        ("inverse dynamics, batched 1e5, fixed base [poses/s]",
         1 / per_call(lambda: stewart.inverse_dynamics(p, pose, rate, acc), 1) * n),
        ("inverse dynamics, batched 1e5, moving base [poses/s]",
         1 / per_call(lambda: stewart.inverse_dynamics(p, pose, rate, acc, *base), 1) * n),
        ("inverse dynamics, one state, fixed base [us]",
         1e6 * per_call(lambda: stewart.inverse_dynamics(p, pose[0], rate[0], acc[0]), 2000)),
        ("inverse dynamics, one state, moving base [us]",
         1e6 * per_call(lambda: stewart.inverse_dynamics(p, pose[0], rate[0], acc[0], *base), 2000)),
        ("forward dynamics, one state, fixed base [us]",
         1e6 * per_call(lambda: stewart.forward_dynamics(p, pose[0], rate[0], forces), 2000)),
        ("forward dynamics, one state, moving base [us]",
         1e6 * per_call(lambda: stewart.forward_dynamics(p, pose[0], rate[0], forces, *base), 2000)),
    ]
    for name, value in rows:
        print(f"{name:55s} {value:12,.1f}")


if __name__ == "__main__":
    main()
