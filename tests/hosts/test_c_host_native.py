"""Native FMUs in a host that is not Python (tests/hosts/c_host: dlopen, the FMI 2 calling
sequence, exit): every run in a fresh process exits 0, with no libpython anywhere in the
process (the dynamic loader's own list of what it loaded, LD_DEBUG=libs), and the
outputs equal fmpy's run of the same FMU; bad input answers Discard in that host too."""
import math
import os

import numpy as np
import pytest

from scenarios.cosim.fmi import Instance
from tests.fmu_helpers import OPENED
from tests.hosts.c_host import HostFmu

RUNS = 5
CASES = {   # script: (parameters, Integer parameters, outputs watched)
    "hexapod_plant_fmu": ({"leg_force[1]": 5.2e3}, {"moving_base": 0}, ["pose[3]", "leg_length[1]"]),
    "telescope_fmu": ({}, {"profile": 2}, ["base_pose[5]", "reference_pose[3]"]),
    "leg_controller_fmu": ({"leg_length[2]": 3.0}, {}, ["leg_force[2]", "integral[2]"]),
    "mechanism3t_plant_fmu": ({"slider_force[1]": 20.0}, {}, ["platform_position[3]"]),
    "slider_controller_fmu": ({}, {}, ["slider_force[1]", "reference_position[1]"]),
    "leg_sensor_fmu": ({"leg_length[1]": 3.1, "noise": 1e-6, "resolution": 1e-7, "rate_cutoff": 200.0},
                       {"seed": 7, "delay_steps": 1}, ["measured_length[1]", "estimated_rate[1]"]),
}


def plain_env():
    """This process's environment without anything that would put Python into the host."""
    env = {k: v for k, v in os.environ.items() if k not in ("LD_PRELOAD", "PYTHONPATH", "PYTHONHOME")}
    env["LD_DEBUG"] = "libs"
    return env


@pytest.mark.parametrize("script", CASES)
def test_native_fmu_runs_in_a_c_host_and_exits_cleanly(native, script, tmp_path):
    reals, ints, watch = CASES[script]
    fmu = HostFmu(native[script], tmp_path / "fmu")
    runs = [fmu.run(steps=50, real=reals, integer=ints, out=watch, state=20, env=plain_env()) for _ in range(RUNS)]
    for run in runs:
        assert run.returncode == 0 and run.signal is None, run.stderr[-2000:]
        assert "done" in run.stdout.splitlines()
        loaded = [line for line in run.stderr.splitlines() if "calling init:" in line]
        assert any(script_so in line for line in loaded for script_so in (f"{fmu.md.coSimulation.modelIdentifier}.so",))
        assert not any("libpython" in line for line in loaded), loaded
    first = np.array(runs[0].lines("out"))
    for run in runs[1:]:   # every fresh process computes the same numbers
        assert np.array_equal(np.array(run.lines("out")), first)
    replay = np.array(runs[0].lines("replay"))   # get/set state in the C host: the tail again
    assert np.array_equal(replay[:, 1:], first[-len(replay):, 1:])

    inst = Instance(native[script], "fmpy")   # the same FMU under fmpy, same calls
    OPENED.append(inst)
    inst.initialize(0.0, {**ints, **reals})
    rows = [[inst.get_real(n) for n in watch]]
    for k in range(50):
        inst.do_step(k * 1e-3, 1e-3)
        rows.append([inst.get_real(n) for n in watch])
    assert np.array_equal(first[:, 1:], np.array(rows))


def test_c_host_sees_discard_for_nan_input(native, tmp_path):
    fmu = HostFmu(native["hexapod_plant_fmu"], tmp_path / "fmu")
    run = fmu.run(steps=10, integer={"moving_base": 0}, real_at={(3, "leg_force[2]"): math.nan}, out=["pose[3]"],
                  env=plain_env())
    assert run.returncode == 2 and run.signal is None
    assert ("fmi2DoStep", "Discard") in set(run.statuses())
    assert "leg forces input contains NaN or inf" in run.stderr
    assert "last_successful_time 0.0030000000000000001" in run.stdout
