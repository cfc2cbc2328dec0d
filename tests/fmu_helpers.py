"""Opening FMU instances in tests; conftest frees every one after each test (an unfreed
pythonfmu instance can corrupt the heap when the process exits)."""
import math
import re

import numpy as np
from fmpy.fmi2 import fmi2LastSuccessfulTime, fmi2Real

from fmu_src import python_build as builder
from fmu_src.slave import OUTPUT
from scenarios.cosim.fmi import Instance

OPENED = []


def open_fmu(path, name="a", **values):
    """An initialised instance (start time 0) with ``values`` set in initialization mode."""
    instance = Instance(path, name)
    OPENED.append(instance)
    instance.initialize(0.0, values)
    return instance


def free_all():
    while OPENED:
        OPENED.pop().terminate()


def opened(path, **values):
    """An instance after instantiate and setupExperiment, ``values`` set in initialization
    mode; exitInitializationMode's status is returned, not raised."""
    inst = Instance(path, "a")
    OPENED.append(inst)
    inst.call("setupExperiment", startTime=0.0)
    inst.call("enterInitializationMode")
    for name, value in values.items():
        inst.set(name, value)
    status = inst.raw("fmi2ExitInitializationMode")(inst.fmu.component)
    return inst, status


def step(inst, t, h):
    return inst.raw("fmi2DoStep")(inst.fmu.component, t, h, 1)


def reals(inst, names):
    return np.array([inst.get_real(n) for n in names])


def outputs(md):
    return [v.name for v in md.modelVariables if v.causality == "output"]


def failure_lines(inst):
    """Log lines that explain a failure: Error (initialization, misuse) or Discard (a step)."""
    return [line for line in inst.log if line.startswith(("[ERROR]", "[DISCARD]"))]


def _scales(columns):
    """Each column's scale: the largest magnitude over the elements of its vector with
    the same unit (plant.pose[1..3] in m, plant.pose[4..6] in rad), so that a component
    that stays near zero is compared at the precision of its vector."""
    group = lambda name: re.sub(r"\[\d+\]", "", name)
    peak = {}
    for name, values in columns.items():
        peak[group(name)] = max(peak.get(group(name), 0.0), np.max(np.abs(values)))
    return {name: peak[group(name)] for name in columns}


def _stepping_failure(fmus, native, script, values, inputs, steps=1, h=1e-3):
    """Set ``inputs`` then step until a Discard; checks the native contract (Discard,
    outputs and last successful time of the last accepted step, refusal afterwards) and
    that the failure reads as the python FMU's. Returns the failure text."""
    texts = []
    for paths in (fmus, native):
        inst, status = opened(paths[script], **values)
        assert status == OK, inst.log
        names = outputs(inst.md)
        for name, value in inputs.items():
            inst.set(name, value)
        t, before, result = 0.0, reals(inst, names), OK
        for k in range(steps):
            result = step(inst, t, h)
            if result != OK:
                break
            before, t = reals(inst, names), t + h
        assert result == DISCARD, (paths[script].parent.name, inst.log[-3:])
        texts.append(_failure(failure_lines(inst)[-1]))
        if paths is native:
            assert np.array_equal(reals(inst, names), before, equal_nan=True)
            last = fmi2Real()
            assert inst.raw("fmi2GetRealStatus")(inst.fmu.component, fmi2LastSuccessfulTime, last) == OK
            assert last.value == t
            assert step(inst, t, h) == DISCARD
            assert failure_lines(inst)[-1].startswith(f"[DISCARD] refusing doStep at t={t:.6g} s after: ")
    assert texts[0] == texts[1]
    return texts[1]


# per FMU: a non-finite value at initialization (an input; Telescope has none: a
# parameter) and a parameter outside its declared range, with what the log must say
BAD_INIT = {
    "hexapod_plant_fmu": ("base_acc[6]", "input base_acc[6] = {} at initialization: inputs must be finite",
                          "max_step", 0.0, "max_step = 0 s is outside its valid range >= 1e-09 s"),
    "telescope_fmu": ("start_elevation", "parameter start_elevation = {} rad is outside its valid range",
                      "target_elevation", math.radians(95.0),
                      "target_elevation = 1.65806 rad (95 deg) is outside its valid range [0, 1.5708] rad "
                      "([0, 90] deg)"),
    "leg_controller_fmu": ("leg_rate[2]", "input leg_rate[2] = {} at initialization: inputs must be finite",
                           "force_limit", 0.0, "force_limit = 0 N is outside its valid range >= 1e-09 N"),
    "mechanism3t_plant_fmu": ("slider_force[2]", "input slider_force[2] = {} at initialization: inputs must be finite",
                        "max_step", -1e-3, "max_step = -0.001 s is outside its valid range >= 1e-09 s"),
    "slider_controller_fmu": ("slider_rate[1]", "input slider_rate[1] = {} at initialization: inputs must be "
                              "finite", "kd", -5.0, "kd = -5 N.s/m is outside its valid range >= 0 N.s/m"),
    "leg_sensor_fmu": ("leg_length[4]", "input leg_length[4] = {} at initialization: inputs must be finite",
                       "noise", -1e-6, "noise = -1e-06 m is outside its valid range [0, 0.01] m"),
    "base_sensor_fmu": ("true_base_rate[2]", "input true_base_rate[2] = {} at initialization: inputs must be "
                        "finite", "rate_cutoff", -1.0,
                        "rate_cutoff = -1 1/s is outside its valid range [0, 10000] 1/s"),
    "wind_fmu": ("base_pose[4]", "input base_pose[4] = {} at initialization: inputs must be finite",
                 "mean_speed", 80.0, "mean_speed = 80 m/s is outside its valid range [0, 60] m/s"),
    "load_cell_fmu": ("leg_force[3]", "input leg_force[3] = {} at initialization: inputs must be finite",
                      "noise", -1.0, "noise = -1 N is outside its valid range [0, 10000] N"),
}


# Parameters away from their defaults, so that an output that ignored them would show it
# (the telescope has no inputs: its initial pointing comes from its parameters alone).
INIT_PARAMETERS = {"telescope_fmu": {"start_azimuth": math.radians(10.0), "start_elevation": math.radians(40.0)},
                   "hexapod_plant_fmu": {"initial_pose[3]": -2.67, "initial_pose[4]": 0.01},
                   "mechanism3t_plant_fmu": {"initial_rate[1]": 0.002}, "slider_controller_fmu": {"amplitude": 0.02}}


def output_starts(path):
    """The outputs' values before initialization, exactly: those of a fresh instance of
    the FMU's slave class (the XML has none: the outputs are initial="calculated")."""
    slave = builder.slave_instance(path)
    return [slave.get_real([v.value_reference])[0] for v in slave.vars.values() if v.causality == OUTPUT]


OK, DISCARD, ERROR = 0, 2, 3   # fmi2Status


def _failure(line):
    """The failure text without the status label."""
    return line.split("] ", 1)[1]
