"""The SSP cross-checks' scenario and columns, shared by the SSP tests and the other masters' (libcosim, ecos)."""
import dataclasses

from fmu_src import catalogue
from scenarios import spec
from scenarios.cosim.fmi import unpack
from scenarios.runs import runner

RECORD = ["plant.pose", "plant.leg_length", "controller.leg_force", "base.base_pose", "base.reference_pose"]

STOP, START_DELAY = 1.0, 0.5


def configure(fmus, feedforward="moving_base", stop=STOP):
    """Scenario, FMU paths, model descriptions and parameters of the shortened slew."""
    path = runner.resolve("telescope_slew")
    scenario = spec.load(path)
    scenario = spec.load(path, overrides=scenario.ci)
    paths = {inst: fmus[catalogue.BY_KEY[fmu].script] for inst, fmu in scenario.fmus.items()}
    descriptions = {inst: unpack(p)[0] for inst, p in paths.items()}
    values = spec.bind(scenario, descriptions)
    # fmpy's SSP master is plain Jacobi: compare with ours without input extrapolation
    scenario = dataclasses.replace(scenario, stop_time=stop, record_interval=scenario.step, record=RECORD,
                                   metrics=[], master="jacobi", extrapolation="none")
    params = {inst: dict(v) for inst, v in values.items()}
    inst, name, value = spec.sweep_value(scenario, descriptions, feedforward)
    params[inst][name] = value
    params["base"]["start_delay"] = START_DELAY
    return scenario, paths, descriptions, params


def columns(scenario, descriptions, references):
    names = []
    for reference in references:
        inst = reference.split(".", 1)[0]
        variables = {v.name for v in descriptions[inst].modelVariables}
        names += [f"{inst}.{n}" for n in spec.expand(variables, reference)]
    return names


def run_columns(run):
    """Columns by name ("time", "inst.var") of one of our runs."""
    records = run.records
    return {"time": records.time, **{name: records[name] for name in records.names}}
