"""Throughput of the geometric tolerance pipeline (plant/hexapod/tolerance.py).

Samples per second of ``pose_errors`` (each sample its own perturbed geometry: real leg lengths,
batched Newton forward kinematics) for 10^5 to 10^6 samples of the 54 inputs at their default
tolerances, at the S-band pose; the analytic ``sensitivity`` and a Sobol analysis for scale.
Prints figures; asserts nothing (speed is not a test).

    python benchmarks/bench_tolerance.py [--sizes 100000 300000 1000000] [--sobol 1024]
"""
import argparse
import time

import numpy as np

from plant.hexapod import tolerance as tl
from plant.hexapod.model import S_BAND_POSE, StewartParams


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[100_000, 300_000, 1_000_000])
    parser.add_argument("--sobol", type=int, default=1024, help="Saltelli base samples n (0: skip)")
    args = parser.parse_args(argv)
    params = StewartParams.paper()
    inputs = tl.geometric_inputs()
    tol = np.array([i.tolerance for i in inputs])
    rng = np.random.default_rng(30)
    print(f"pose_errors, {len(inputs)} inputs, chunks of {tl.CHUNK}:")
    for n in args.sizes:
        samples = rng.uniform(-1, 1, (n, len(inputs))) * tol
        start = time.perf_counter()
        errors = tl.pose_errors(params, S_BAND_POSE, samples)
        took = time.perf_counter() - start
        print(f"  {n:>9,d} samples  {took:7.2f} s  {n / took:>11,.0f} samples/s   "
              f"std x,y,z {errors[:, :3].std(axis=0) * 1e6} um")
    start = time.perf_counter()
    tl.sensitivity(params, S_BAND_POSE)
    print(f"sensitivity (analytic, 6 x 54): {(time.perf_counter() - start) * 1e6:.0f} us")
    if args.sobol:
        start = time.perf_counter()
        found = tl.pose_error_sobol(params, S_BAND_POSE, inputs, n=args.sobol)
        took = time.perf_counter() - start
        print(f"pose_error_sobol n={args.sobol}: {found.evaluations:,d} evaluations, {took:.1f} s "
              f"(bootstrap included); widest 95 % interval of a first-order index {found.first_conf.max():.3f}")


if __name__ == "__main__":
    main()
