"""What the telescope's FMI 3 output derivatives buy the master: extrapolation =
"derivatives" (the base and reference inputs fed the mean over the coming step of the
telescope's Taylor polynomial, u + h/2 u' + h^2/6 u'', from fmi3GetOutputDerivatives)
against "linear" (u + (u - u_prev)/2 from past samples), Jacobi, on the shipped slew
with every FMU FMI 3.0, at communication steps h.

Coupling error of the telescope's connection: the plant's held base inputs against the
exact mean of the telescope's outputs over the step they are held for. What it does to
the platform: the largest difference of the leg lengths [nm] and of the platform
pose (position [nm], rotation [nrad]) from a reference run of the same scene at
H_REF (both extrapolations agree there to the figure printed), on the common record grid;
tracking: the scene's pose-error metric. The stability limit: the leg loop's own signals
have no derivatives and are extrapolated linearly either way (scenarios/runs/flags.py), so
the predicted limit is that of "linear".

    python -m studies.fmi3_derivatives [--stop SECONDS]
"""
import argparse
import dataclasses

import numpy as np

from plant.telescope import model as telescope
from scenarios import spec
from scenarios.runs import flags, metrics, runner, single

STEPS = (0.5e-3, 1e-3, 2e-3, 4e-3)
H_REF = 0.1e-3
RECORD = ["plant.leg_length", "plant.pose", "plant.base_pose", "plant.base_rate", "plant.base_acc"]
INPUTS = ("base_pose", "base_rate", "base_acc")
GAUSS = np.polynomial.legendre.leggauss(5)   # nodes and weights on [-1, 1]: a step's mean to O(h^10)


def run(extrapolation, h, stop):
    """One run of the slew (moving-base feedforward), every FMU FMI 3: (records, metrics,
    predicted step limit, the telescope's parameters)."""
    scenario, paths, descriptions, values = runner.prepare(runner.resolve("telescope_slew"), fmi_version=3)
    scenario = dataclasses.replace(scenario, extrapolation=extrapolation, step=h, stop_time=stop,
                                   record=RECORD, record_interval=0.02)
    values = spec.bind(scenario, descriptions)
    inst, name, value = spec.sweep_value(scenario, descriptions, "moving_base")
    values[inst][name] = value
    result = single.run(scenario, paths, values, None, f"{extrapolation}-{h}",
                        [metrics.make(m) for m in scenario.metrics])
    return result.records, result.metrics, flags.predict(scenario, paths, descriptions, values).limit, values["base"]


def input_errors(records, h, base):
    """Largest difference, over the record points after the slew starts, of the plant's
    held base inputs from their exact mean over the step they were held for (the step
    ending at the record point; the telescope's outputs by plant.telescope.model, Gauss-Legendre):
    {input: (translation [nm, nm/s, nm/s2], rotation [nrad, ...])}."""
    params = dataclasses.replace(telescope.TelescopeParams.tianma(), lever_arm=base["lever_arm"])
    profile = telescope.motion_profile("slew", (base["start_azimuth"], base["start_elevation"]),
                                       (base["target_azimuth"], base["target_elevation"]),
                                       start_delay=base["start_delay"])
    t = records.time[records.time > base["start_delay"] + h]
    nodes, weights = GAUSS
    times = (t[:, None] - h / 2 + h / 2 * nodes[None, :]).ravel()
    exact = (telescope.fmu_outputs(params, profile, times).reshape(t.size, nodes.size, 60)
             * weights[None, :, None]).sum(axis=1) / 2
    rows = np.isin(records.time, t)
    out = {}
    for column, name in zip((0, 6, 12), INPUTS):
        fed = np.column_stack([records[f"plant.{name}[{k}]"][rows] for k in range(1, 7)])
        diff = np.abs(fed - exact[:, column:column + 6])
        out[name] = (np.max(diff[:, :3]) * 1e9, np.max(diff[:, 3:]) * 1e9)
    return out


def errors(records, reference):
    """Largest differences [nm, nm, nrad]: leg lengths, platform position, rotation."""
    legs = max(np.max(np.abs(records[f"plant.leg_length[{k}]"] - reference[f"plant.leg_length[{k}]"]))
               for k in range(1, 7))
    position = max(np.max(np.abs(records[f"plant.pose[{k}]"] - reference[f"plant.pose[{k}]"])) for k in range(1, 4))
    rotation = max(np.max(np.abs(records[f"plant.pose[{k}]"] - reference[f"plant.pose[{k}]"])) for k in range(4, 7))
    return legs * 1e9, position * 1e9, rotation * 1e9


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--stop", type=float, default=20.0, help="stop time [s] (the slew starts at 5 s)")
    args = parser.parse_args(argv)
    reference = run("derivatives", H_REF, args.stop)[0]
    other = run("linear", H_REF, args.stop)[0]
    print(f"telescope_slew to {args.stop:g} s, Jacobi, FMI 3 FMUs; reference h = {H_REF * 1e3:g} ms "
          f"(linear vs derivatives there: legs {errors(other, reference)[0]:.3g} nm)")
    print("1. the plant's held base inputs against their exact mean over the step, largest over the slew "
          "(translation nm.., rotation nrad..; base_acc has no derivative: linear in both)")
    print("2. the platform against the reference: legs, position [nm], rotation [nrad]; the pose-error metric")
    for h in STEPS:
        for extrapolation in ("linear", "derivatives"):
            records, found, limit, base = run(extrapolation, h, args.stop)
            fed = input_errors(records, h, base)
            legs, position, rotation = errors(records, reference)
            inputs = "  ".join(f"{name} {a:.3g}/{b:.3g}" for name, (a, b) in fed.items())
            print(f"h {h * 1e3:g} ms {extrapolation:>11}: 1. {inputs}")
            print(f"{'':>27}2. legs {legs:.4g}, position {position:.4g}, rotation {rotation:.4g}; pose error "
                  f"peak {found['pose error']['peak']:.6g} {found['pose error']['unit']} (predicted limit "
                  f"{limit * 1e3:.4g} ms)", flush=True)


if __name__ == "__main__":
    main()
