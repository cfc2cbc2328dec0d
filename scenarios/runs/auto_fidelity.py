"""No more model than a scene needs: the error each hexapod fidelity level adds along a
scene's motion, and the rule behind ``fidelity = "auto"``.

The error of a level is the largest leg-force difference from the full model, by inverse
dynamics along the scene's reference motion and base motion (what the plant will be
asked to follow), sampled at SAMPLES points. The telescope FMU of the scene is stepped
alone to get both motions, so the rule sees exactly what the co-simulation will.

The rule: the cheapest level whose error stays within the scenario's
``fidelity_tolerance`` (a force). Cheapest is by the plant's measured cost per RK4 step
(benchmarks/bench_plant.py: massless legs ~6.4 µs, then no_base, base_gravity and full
at ~8.3 µs; ties go to the level that models less), so the choice is deterministic.
"""
import numpy as np

from fmu_src import replay_table
from plant.hexapod.model import FIDELITIES, StewartParams, inverse_dynamics
from scenarios.cosim.fmi import Instance, RealPort

COST_ORDER = ("massless_legs", "no_base", "base_gravity", "full")
SAMPLES = 400


def _vector(name):
    return [f"{name}[{i + 1}]" for i in range(6)]


def scene_motion(scenario, fmu_paths, values, telescope, axes=False):
    """Reference motion and base motion (6 arrays (n, 6)) of the telescope instance; with
    ``axes``, also the antenna axes' rates (n, 2): the slew's own motion, without the sway
    of a flexible feed support that base_rate carries."""
    instance = Instance(fmu_paths[telescope], f"{telescope}-fidelity")
    names = ["reference_pose", "reference_rate", "reference_acc", "base_pose", "base_rate", "base_acc"]
    port = RealPort(instance, [v for n in names for v in _vector(n)] + (["axis_rate[1]", "axis_rate[2]"] * axes))
    try:
        instance.initialize(scenario.start_time, replay_table.for_fmu(values.get(telescope, {})))
        h = (scenario.stop_time - scenario.start_time) / SAMPLES
        rows = [port.read().copy()]
        for k in range(SAMPLES):
            instance.do_step(scenario.start_time + k * h, h)
            rows.append(port.read().copy())
    finally:
        instance.terminate()
    data = np.array(rows)
    motion = [data[:, 6 * i:6 * i + 6] for i in range(6)]
    return (motion, data[:, 36:]) if axes else motion


def fidelity_errors(motion, params=None):
    """{fidelity: largest |leg force - full model's| [N]} along the motion."""
    params = params or StewartParams.paper()
    ref, base = motion[:3], motion[3:]
    full = inverse_dynamics(params, *ref, *base)
    return {f: float(np.abs(inverse_dynamics(params, *ref, *base, fidelity=f) - full).max()) for f in FIDELITIES}


def choose(errors, tolerance):
    """The cheapest fidelity whose error is within tolerance [N]."""
    return next(f for f in COST_ORDER if errors[f] <= tolerance)
