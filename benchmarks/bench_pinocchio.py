"""The kit's forward dynamics against Pinocchio's constrained dynamics on the same states.

Per state, fixed base and moving base, timed in one run (medians of rounds that alternate):
  kit, batched   plant.hexapod.model.forward_dynamics on all states in one call, per state;
  kit, one call  the same, one (6,) state per call (what a caller pays per step);
  pin, solve     pin.constraintDynamics alone, on the tree's (q, v, tau) prepared beforehand;
  pin, state     tests/plant/pinocchio_hexapod.py's forward_dynamics: the tree's state built
                 from the pose (U joints placed along the legs), the solve, the RPY read-out.
Then the ratios, and the largest relative difference of the accelerations (per state, relative
to its largest |value|). Prints figures; asserts nothing (speed is not a test).

    python benchmarks/bench_pinocchio.py [--states 2000] [--rounds 5]
"""
import argparse
import statistics
import time

import numpy as np

from plant.hexapod.model import StewartParams, forward_dynamics
from tests.plant.pinocchio_hexapod import PinocchioHexapod, pin
from tests.plant.test_hexapod_truth import base_states, platform_states


def per_state(call, n, rounds):
    """Median over ``rounds`` of the time of ``call()`` divided by n [s]."""
    times = []
    for _ in range(rounds):
        start = time.perf_counter()
        call()
        times.append((time.perf_counter() - start) / n)
    return statistics.median(times)


def case(params, moving, n, rounds, rng):
    pose, rate, _ = platform_states(rng, n)
    forces = rng.uniform(-3e4, 3e4, (n, 6))
    base = base_states(rng, n) if moving else [np.zeros((n, 6))] * 3
    engine = PinocchioHexapod(params, moving_base=moving)
    kit = forward_dynamics(params, pose, rate, forces, *base)
    ours = np.array([engine.forward_dynamics(pose[k], rate[k], forces[k], *(b[k] for b in base)) for k in range(n)])
    worst = max(np.max(np.abs(ours[k] - kit[k])) / np.max(np.abs(kit[k])) for k in range(n))

    prepared = []   # pin's (q, v, tau); the solve's cost does not depend on the U placements last set
    for k in range(n):
        q, v = engine.state(pose[k], rate[k], *(b[k] for b in base[:2]))
        tau = np.zeros(engine.model.nv)
        tau[engine.v_prismatic] = forces[k]
        prepared.append((q, v, tau))
    model, data, constraints, cdata, settings = (engine.model, engine.data, engine.constraints,
                                                 engine.constraint_data, engine.settings)

    def pin_solve():
        for q, v, tau in prepared:
            pin.constraintDynamics(model, data, q, v, tau, constraints, cdata, settings)

    def pin_state():
        for k in range(n):
            engine.forward_dynamics(pose[k], rate[k], forces[k], *(b[k] for b in base))

    def kit_one():
        for k in range(n):
            forward_dynamics(params, pose[k], rate[k], forces[k], base[0][k], base[1][k], base[2][k])

    calls = {"kit, batched": lambda: forward_dynamics(params, pose, rate, forces, *base), "kit, one call": kit_one,
             "pin, solve": pin_solve, "pin, state": pin_state}
    rounds_of = {name: [] for name in calls}
    for _ in range(rounds):   # alternate, so that the machine's load falls on all alike
        for name, call in calls.items():
            rounds_of[name].append(per_state(call, n, 1))
    return {name: statistics.median(t) for name, t in rounds_of.items()}, worst


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--states", type=int, default=2000)
    parser.add_argument("--rounds", type=int, default=5)
    args = parser.parse_args(argv)
    if pin is None:
        raise SystemExit("this benchmark needs Pinocchio: pip install -c constraints.txt -e '.[dev]'")
    params = StewartParams.paper(d=0.2)
    rng = np.random.default_rng(30)
    print(f"pinocchio {pin.__version__}; {args.states} random states near home; medians of {args.rounds} rounds")
    for moving in (False, True):
        times, worst = case(params, moving, args.states, args.rounds, rng)
        print(f"\n{'moving' if moving else 'fixed'} base: max relative acceleration difference {worst:.2e}")
        for name, t in times.items():
            print(f"  {name:14s} {t * 1e6:9.2f} us/state")
        print(f"  pin solve / kit batched   {times['pin, solve'] / times['kit, batched']:7.1f}x")
        print(f"  pin solve / kit one call  {times['pin, solve'] / times['kit, one call']:7.2f}x")
        print(f"  pin state / kit one call  {times['pin, state'] / times['kit, one call']:7.2f}x")


if __name__ == "__main__":
    main()
