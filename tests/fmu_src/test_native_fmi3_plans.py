"""fmi3GetFloat64/fmi3SetFloat64 keep the last call's checked value references (a plan,
fmu_src/native/fmi3_layer.c) so that a host passing the same array every step is not
checked again. The plan must never let through what a fresh check refuses: a host that
rewrites its array in place, passes another nValues, or calls in another state gets the
same answer as with a new array (fmpy's raw calls on one ctypes buffer)."""
import ctypes

import pytest
from fmpy import extract, read_model_description
from fmpy.fmi3 import FMU3Slave

from fmu_src import native_build

OK, ERROR = 0, 3


@pytest.fixture(scope="module")
def plant():
    path = native_build.ensure_native3(["hexapod_plant_fmu"])["hexapod_plant_fmu"]
    md = read_model_description(str(path))
    lines = []
    slave = FMU3Slave(guid=md.guid, unzipDirectory=extract(str(path)), instanceName="plant",
                      modelIdentifier=md.coSimulation.modelIdentifier)
    slave.instantiate(logMessage=lambda env, status, category, message: lines.append(message.decode()))
    slave.lines = lines
    slave.vr = {v.name: v.valueReference for v in md.modelVariables}
    slave.stroke = float(next(v.start for v in md.modelVariables if v.name == "stroke"))
    yield slave
    slave.freeInstance()


def call(slave, function, vrs, values, n_values):
    """The status of one raw fmi3Get/SetFloat64 on the caller's own buffers (fmpy raises on Error)."""
    try:
        getattr(slave, function)(slave.component, vrs, len(vrs), values, n_values)
    except Exception as exc:   # fmpy's FMICallException
        return getattr(exc, "status", ERROR)
    return OK


def test_a_repeated_array_is_checked_as_a_new_one(plant):
    vrs = (ctypes.c_uint32 * 1)(plant.vr["stroke"])
    six = (ctypes.c_double * 7)(*[100.0] * 7)
    six[0] = plant.stroke   # its start value: in range
    plant.enterInitializationMode(startTime=0.0)
    assert call(plant, "fmi3SetFloat64", vrs, six, 1) == OK          # a parameter in initialization mode
    assert call(plant, "fmi3SetFloat64", vrs, six, 1) == OK          # the same array again: the plan
    plant.exitInitializationMode()
    assert call(plant, "fmi3SetFloat64", vrs, six, 1) == ERROR       # the same array, fixed now
    assert "parameter stroke is fixed after initialization" in plant.lines[-1], plant.lines

    vrs[0] = plant.vr["leg_force"]                                   # rewritten in place: an input of 6
    assert call(plant, "fmi3SetFloat64", vrs, six, 6) == OK
    assert call(plant, "fmi3SetFloat64", vrs, six, 6) == OK
    assert call(plant, "fmi3SetFloat64", vrs, six, 7) == ERROR       # the same array, another nValues
    assert "cover 6 values, nValues is 7" in plant.lines[-1], plant.lines
    vrs[0] = plant.vr["leg_length"]                                  # in place again: an output
    assert call(plant, "fmi3SetFloat64", vrs, six, 6) == ERROR
    assert "leg_length[1] is an output and cannot be set" in plant.lines[-1], plant.lines
    vrs[0] = plant.vr["time"]
    assert call(plant, "fmi3SetFloat64", vrs, six, 1) == ERROR
    assert "time is the independent variable" in plant.lines[-1], plant.lines

    vrs[0] = plant.vr["leg_length"]
    assert call(plant, "fmi3GetFloat64", vrs, six, 6) == OK
    assert call(plant, "fmi3GetFloat64", vrs, None, 6) == ERROR      # the same array, no values buffer
    assert "values is NULL" in plant.lines[-1], plant.lines
    vrs[0] = 999999
    assert call(plant, "fmi3GetFloat64", vrs, six, 1) == ERROR
    assert "no Float64 variable has value reference 999999" in plant.lines[-1], plant.lines
