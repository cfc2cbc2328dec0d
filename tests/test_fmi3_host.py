"""The FMI 3.0 FMUs under a second FMI 3.0 host, independent of fmpy: fmi-sim (the
command-line simulator of rust-fmi, a pure-Rust importer; .ci/fmi3_host.sh builds it
from crates.io and runs this file). Each native FMI 3.0 FMU runs with its default start
values; every output fmi-sim records equals fmpy's simulate_fmu of the same FMU at the
same communication points (fmi-sim 0.7 cannot record array outputs: see the test),
to 1e-12 relative: fmi-sim adds the step to the time while fmpy multiplies, so a step
can differ in its last bit, and a model with substeps sees that.

Skipped where fmi-sim is not built (MB_FMI_SIM names it, or fmi-sim on PATH), unless
MB_REQUIRE_FMI3_HOST=1 (the CI script), where a missing host is a failure."""
import csv
import os
import shutil
import subprocess

import numpy as np
import pytest
from fmpy import read_model_description, simulate_fmu

from movingbase.fmu_src import builder, native_build

HOST = os.environ.get("MB_FMI_SIM") or shutil.which("fmi-sim")
if HOST is None and os.environ.get("MB_REQUIRE_FMI3_HOST") != "1":
    pytest.skip("fmi-sim is not built here (.ci/fmi3_host.sh builds it)", allow_module_level=True)

STOP, H = 0.1, 1e-3


@pytest.fixture(scope="module")
def fmi3():
    assert HOST is not None and os.access(HOST, os.X_OK), f"MB_REQUIRE_FMI3_HOST=1 but no fmi-sim at {HOST!r}"
    return native_build.ensure_native3(builder.available())


def fmi_sim(path, out):
    """fmi-sim's co-simulation of ``path`` from 0 to STOP in steps of H, every step
    recorded (fmi-sim 0.7 takes its step from -n, the number of output points, and
    ignores --step): the finished process (its log at level error on stderr)."""
    return subprocess.run([HOST, "--model", str(path), "--output-file", str(out), "co-simulation",
                           "-s", "0", "-f", repr(STOP), "-n", str(round(STOP / H))],
                          capture_output=True, text=True, timeout=300, env={**os.environ, "RUST_LOG": "error"})


def array_outputs(path):
    return [v.name for v in read_model_description(str(path)).modelVariables
            if v.causality == "output" and v.dimensions]


@pytest.mark.parametrize("script", builder.SCRIPTS)
def test_fmi_sim_runs_the_fmu_as_fmpy_does(fmi3, script, tmp_path):
    """Every output fmi-sim records equals fmpy's. fmi-sim 0.7 reads every output as a
    scalar: on an FMU with an array output (leg_force, leg_length, measured_length) it asks
    fmi3GetFloat64 for 1 value of a 6-element array, and our FMU answers fmi3Error with a
    line saying so (as FMI 3.0 says), which ends fmi-sim's run: checked as such."""
    path = fmi3[script]
    run = fmi_sim(path, tmp_path / "fmi-sim.csv")
    arrays = array_outputs(path)
    if arrays:
        assert run.returncode != 0 and "the value references cover 6 values, nValues is 1" in run.stderr, \
            f"fmi-sim on {path.name} (array outputs {arrays}):\n{run.stderr[-2000:]}"
        return
    assert run.returncode == 0, f"fmi-sim failed on {path.name}:\n{run.stdout[-2000:]}\n{run.stderr[-2000:]}"
    with open(tmp_path / "fmi-sim.csv", newline="") as f:
        rows = list(csv.reader(f))
    host = {name: np.array([float(r[k]) for r in rows[1:]]) for k, name in enumerate(rows[0])}
    step = host["time"][1] - host["time"][0]   # fmi-sim 0.7 chooses it (stop / 500), whatever -n and --step say
    ours = simulate_fmu(str(path), start_time=0.0, stop_time=STOP, output_interval=step)
    assert "time" in host and host["time"].size > 50
    compared = 0
    for name, values in host.items():
        if name == "time":
            continue
        times = np.intersect1d(np.round(host["time"], 9), np.round(ours["time"], 9))
        assert times.size > 50, name
        a = values[np.isin(np.round(host["time"], 9), times)]
        b = ours[name][np.isin(np.round(ours["time"], 9), times)]
        scale = max(1.0, float(np.max(np.abs(b))))
        assert np.max(np.abs(a - b)) <= 1e-12 * scale, name
        compared += 1
    assert compared > 0, f"no output of {path.name} in fmi-sim's columns {sorted(host)}"
