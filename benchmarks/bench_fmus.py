"""Per-doStep cost of each FMU under fmpy next to an empty pythonfmu FMU (the floor).
The 3T plant runs at its default 5 ms internal step, the others at 1 ms (max_step).

Prints, per FMU: doStep alone, and doStep with its per-step inputs written and outputs
read through preallocated buffers (what the scenario master does), in µs and as a
ratio to the empty FMU's doStep. Median of repeated runs of 2000 steps at h = 1 ms."""
import pathlib
import statistics
import tempfile
import time

import numpy as np
from pythonfmu.builder import FmuBuilder

from fmu_src import python_build as builder
from plant.hexapod.model import HOME_POSE, StewartParams, inverse_dynamics
from plant.mechanism3t import model as m3t
from scenarios.cosim.fmi import Instance, RealPort

HERE = pathlib.Path(__file__).resolve().parent
STEPS, H = 2000, 1e-3


def vector(name, n=6):
    return [f"{name}[{i + 1}]" for i in range(n)]


def time_steps(instance, inputs=None, outputs=None, repeats=5, steps=STEPS):
    runs, t = [], 0.0
    for _ in range(repeats):
        start = time.perf_counter()
        for _ in range(steps):
            if inputs:
                inputs[0].write(inputs[1])
            instance.do_step(t, H)
            if outputs:
                outputs.read()
            t += H
        runs.append((time.perf_counter() - start) / steps * 1e6)
    return statistics.median(runs)


def main():
    out = pathlib.Path(tempfile.mkdtemp())
    empty = FmuBuilder.build_FMU(HERE / "empty_fmu.py", dest=out)
    fmus = builder.ensure_built(builder.available(), out)
    floor = Instance(empty, "empty")
    floor.initialize(0.0)
    floor_us = time_steps(floor)
    print(f"{'FMU':28s} {'doStep [us]':>12s} {'x floor':>8s} {'with I/O [us]':>14s} {'x floor':>8s}")
    print(f"{'empty pythonfmu (floor)':28s} {floor_us:12.1f} {1.0:8.1f}")
    static = inverse_dynamics(StewartParams.paper(), HOME_POSE, np.zeros(6), np.zeros(6))
    rho = np.array(m3t.PAPER_REFERENCE_RHO_MM) * m3t.MM
    slider_static = m3t.slider_forces(m3t.Mechanism3TParams.paper(), rho, np.zeros(3), np.zeros(3))
    cases = {   # name: (parameters, inputs written every step, their values, outputs read every step)
        "hexapod_plant_fmu": ({}, vector("leg_force") + vector("base_pose") + vector("base_rate") + vector("base_acc"),
                              np.r_[static, np.zeros(18)], vector("leg_length") + vector("leg_rate")),
        "telescope_fmu": ({}, [], None, vector("base_pose") + vector("base_rate") + vector("base_acc")
                          + vector("reference_pose") + vector("reference_rate") + vector("reference_acc")),
        "leg_controller_fmu": ({}, vector("leg_length") + vector("leg_rate"),
                               np.r_[StewartParams.paper().home_lengths, np.zeros(6)], vector("leg_force")),
        "mechanism3t_plant_fmu": ({}, vector("slider_force", 3), slider_static, vector("slider_position", 3)),
        "slider_controller_fmu": ({}, vector("slider_position", 3) + vector("slider_rate", 3),
                                  np.r_[rho, np.zeros(3)], vector("slider_force", 3)),
        "leg_sensor_fmu": ({"resolution": 1e-7, "noise": 2e-8, "rate_cutoff": 200.0}, vector("leg_length"),
                           StewartParams.paper().home_lengths, vector("measured_length") + vector("estimated_rate")),
    }
    for name, (params, ins, values, outs) in cases.items():
        if name not in fmus:
            continue
        inst = Instance(fmus[name], name)
        inst.initialize(0.0, params)
        port_in = (RealPort(inst, ins), values) if ins else None
        if port_in:
            port_in[0].write(values)    # hold the platform at rest
        steps = 200 if name == "mechanism3t_plant_fmu" else STEPS   # open-loop unstable: short runs
        bare = time_steps(inst, steps=steps)
        io = time_steps(inst, port_in, RealPort(inst, outs), steps=steps)
        print(f"{name:28s} {bare:12.1f} {bare / floor_us:8.1f} {io:14.1f} {io / floor_us:8.1f}")


if __name__ == "__main__":
    main()
