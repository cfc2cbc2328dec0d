"""Throughput of the geometric tolerance pipeline (plant/hexapod/tolerance.py over plant/c/tolerance.c).

Side by side in one run, on the same samples (each its own perturbed geometry, commanded pose
over the default budget's workspace and elevation, clearance included): the C kernel per sample
(``pose_errors``, which includes the static leg forces that set the clearances' signs), and the
batched numpy Newton it replaced (kept in tests/plant/test_hexapod_tolerance.py as the second
method; here its batched form, on 10^5 samples, for the ratio). Then 10^6 samples through the C
kernel (the issue's goal: under a minute on 2 cores), the analytic ``sensitivity`` and a group
Sobol analysis of the default budget. Prints figures; asserts nothing (speed is not a test).

    python benchmarks/bench_tolerance.py [--sizes 100000 1000000] [--sobol 8192]
"""
import argparse
import time
from types import SimpleNamespace

import numpy as np

from plant.hexapod import tolerance as tl
from plant.hexapod.model import _legs, _to_pose_jacobian, _twist_jacobian, inverse_kinematics
from scenarios.runs import budget as bg


def numpy_pose_errors(params, poses, samples, signs):
    """The batched numpy Newton of the pipeline before the C kernel, all samples at once."""
    joints = samples[:, 18:54].reshape(-1, 2, 6, 3)
    geometry = SimpleNamespace(base_joints=params.base_joints + joints[:, 0],   # what the kinematics reads
                               platform_joints=params.platform_joints + joints[:, 1])
    home = params.home_lengths
    play = signs * (np.abs(samples[:, 54:60]) + np.abs(samples[:, 60:66]))
    lengths = (home + samples[:, :6] + (1 + samples[:, 6:12]) * (inverse_kinematics(params, poses) - home
                                                                  + samples[:, 12:18]) + play)
    x = poses.copy()
    for _ in range(20):
        _, rho, length, s = _legs(geometry, x)
        error = length[..., 0] - lengths
        if np.max(np.abs(error)) < 1e-13:
            break
        x -= np.linalg.solve(_to_pose_jacobian(_twist_jacobian(rho, s), x), error[..., None])[..., 0]
    return x - poses


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[100_000, 1_000_000])
    parser.add_argument("--sobol", type=int, default=8192, help="Saltelli base samples n (0: skip)")
    args = parser.parse_args(argv)
    budget = bg.load("default")
    params = bg.StewartParams.paper()
    rng = np.random.default_rng(30)
    for n in args.sizes:
        samples, poses, elevation = bg._map(budget, rng.random((n, bg._dimensions(budget))))
        start = time.perf_counter()
        errors = tl.pose_errors(params, poses, samples, elevation)
        c_time = time.perf_counter() - start
        line = f"  {n:>9,d} samples  C kernel {c_time:6.2f} s  {n / c_time:>10,.0f} samples/s"
        if n <= 200_000:
            start = time.perf_counter()
            signs = tl.load_signs(params, poses, elevation)
            load_time = time.perf_counter() - start
            start = time.perf_counter()
            reference = numpy_pose_errors(params, poses, samples, signs)
            np_time = time.perf_counter() - start
            line += (f" (of which the static loads {load_time:.2f} s)   numpy batched Newton {np_time:6.2f} s   "
                     f"Newton C / numpy speed {np_time / (c_time - load_time):.1f}x   largest difference "
                     f"{np.max(np.abs(errors - reference)):.1e}")
        print(line)
    start = time.perf_counter()
    tl.sensitivity(params, params.home_pose, 0.5)
    print(f"sensitivity (analytic, 6 x 66, with the static loads): {(time.perf_counter() - start) * 1e6:.0f} us")
    if args.sobol:
        start = time.perf_counter()
        found = bg.sobol(params, budget, args.sobol, 0)
        took = time.perf_counter() - start
        print(f"group Sobol n={args.sobol}: {found['evaluations']:,d} evaluations, {took:.1f} s (bootstrap included); "
              f"widest 95 % interval {2 * max(map(max, found['total_conf'] + found['first_conf'])):.3f}")


if __name__ == "__main__":
    main()
