"""No more model than a scene needs: for each telescope scene, the error each hexapod
fidelity level adds, next to its speed gain.

Per scene and level: the largest leg-force error against the full model along the
scene's motion (scenarios.runs.auto_fidelity, what the "auto" rule uses), the largest deviation of
the co-simulated platform pose from the full-fidelity co-simulation (same scene,
moving-base feedforward), and the plant FMU's cost per doStep relative to full fidelity.
Writes docs/fidelity.md and prints it.

    python -m studies.fidelity [--ci]
"""
import argparse
import dataclasses
import pathlib
import statistics
import time

import numpy as np

from plant.hexapod.model import FIDELITIES, HOME_POSE, StewartParams, inverse_dynamics
from scenarios.cosim.fmi import Instance, RealPort
from scenarios.cosim.records import run_records
from scenarios.runs import auto_fidelity, runner, single

SCENES = ("paper_manoeuvre", "telescope_slew", "keyhole_tracking")
OUT = pathlib.Path(__file__).resolve().parent.parent / "docs" / "fidelity.md"


def plant_cost(path, level, steps=3000):
    """Median µs per doStep of the plant FMU at a fidelity, holding a moving base still."""
    base = np.array([0.0, 0.0, 25.0, 0.5, 0.0, 0.3])
    forces = inverse_dynamics(StewartParams.paper(), HOME_POSE, np.zeros(6), np.zeros(6), base, fidelity=level)
    instance = Instance(path, f"cost-{level}")
    try:
        instance.initialize(0.0, {"fidelity": FIDELITIES.index(level)})
        RealPort(instance, [f"leg_force[{i + 1}]" for i in range(6)] + [f"base_pose[{i + 1}]" for i in range(6)]
                 ).write(np.r_[forces, base])
        runs = []
        for repeat in range(5):
            start = time.perf_counter()
            for k in range(steps):
                instance.do_step((repeat * steps + k) * 1e-3, 1e-3)
            runs.append((time.perf_counter() - start) / steps * 1e6)
    finally:
        instance.terminate()
    return statistics.median(runs)


def pose_deviation(name, ci):
    """Largest platform-pose position deviation [µm] of each level from full fidelity."""
    scenario, paths, _, values = runner.prepare(runner.resolve(name), ci=ci)
    scenario = dataclasses.replace(scenario, metrics=[], record=["plant.pose"])
    values["controller"]["feedforward"] = 2
    poses = {}
    for level in FIDELITIES:
        values["plant"]["fidelity"] = FIDELITIES.index(level)
        run = single.run(scenario, paths, values, None, level, [])   # records in memory only
        poses[level] = run_records(run).values[:, :3]
    return {level: float(np.linalg.norm(poses[level] - poses["full"], axis=1).max() * 1e6) for level in FIDELITIES}


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--ci", action="store_true", help="short [ci] versions of the scenes")
    args = parser.parse_args(argv)
    plant_path = runner.prepare(runner.resolve(SCENES[0]), ci=True)[1]["plant"]
    cost = {level: plant_cost(plant_path, level) for level in FIDELITIES}
    lines = ["# Model fidelity per scene", "",
             "What each hexapod fidelity level drops is in plant/hexapod/model.py. Force error: largest leg-force "
             "difference from the full model along the scene's motion (what `fidelity = \"auto\"` compares "
             "with the scenario's tolerance). Pose deviation: largest platform-position difference of the "
             "co-simulation (moving-base feedforward) from the full-fidelity one. Cost: plant FMU doStep "
             "(RK4, 1 ms) under fmpy, and its speed gain over full fidelity.", "",
             "| scene | level | force error [N] | pose deviation [µm] | plant doStep [µs] | speed gain |",
             "|---|---|---|---|---|---|"]
    for name in SCENES:
        scenario, paths, _, values = runner.prepare(runner.resolve(name), ci=args.ci)
        errors = auto_fidelity.fidelity_errors(auto_fidelity.scene_motion(scenario, paths, values, "base"))
        deviation = pose_deviation(name, args.ci)
        for level in FIDELITIES:
            lines.append(f"| {name} | {level} | {errors[level]:.3g} | {deviation[level]:.3g} | "
                         f"{cost[level]:.1f} | {cost['full'] / cost[level]:.2f}x |")
    text = "\n".join(lines) + "\n"
    OUT.parent.mkdir(parents=True, exist_ok=True)
    OUT.write_text(text)
    print(text)
    print(f"written to {OUT}")


if __name__ == "__main__":
    main()
