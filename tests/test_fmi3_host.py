"""The FMI 3.0 FMUs under a second FMI 3.0 host, independent of fmpy: fmi-sim (the
command-line simulator of rust-fmi, a pure-Rust importer; .ci/fmi3_host.sh builds it
from crates.io and runs this file). Each native FMI 3.0 FMU runs with its default start
values; every output fmi-sim records equals fmpy's simulate_fmu of the same FMU at the
same communication points (both hosts call the same binary, so equal bit for bit once
the CSV text is read back; 1e-15 relative allows the last printed digit).

Skipped where fmi-sim is not built (MB_FMI_SIM names it, or fmi-sim on PATH), unless
MB_REQUIRE_FMI3_HOST=1 (the CI script), where a missing host is a failure."""
import csv
import os
import shutil
import subprocess

import numpy as np
import pytest
from fmpy import simulate_fmu

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
    recorded: {column: values}."""
    run = subprocess.run([HOST, "--model", str(path), "--output-file", str(out), "co-simulation",
                          "-s", "0", "-f", repr(STOP), "--step", repr(H), "-n", "0"],
                         capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, f"fmi-sim failed on {path.name}:\n{run.stdout[-2000:]}\n{run.stderr[-2000:]}"
    with open(out, newline="") as f:
        rows = list(csv.reader(f))
    return {name: np.array([float(r[k]) for r in rows[1:]]) for k, name in enumerate(rows[0])}


@pytest.mark.parametrize("script", builder.SCRIPTS)
def test_fmi_sim_runs_the_fmu_as_fmpy_does(fmi3, script, tmp_path):
    path = fmi3[script]
    host = fmi_sim(path, tmp_path / "fmi-sim.csv")
    ours = simulate_fmu(str(path), start_time=0.0, stop_time=STOP, output_interval=H)
    assert "time" in host and host["time"].size > 50
    compared = 0
    for name, values in host.items():
        if name == "time" or name not in ours.dtype.names or ours[name].ndim != 1:
            continue
        times = np.intersect1d(np.round(host["time"], 9), np.round(ours["time"], 9))
        assert times.size > 50, name
        a = values[np.isin(np.round(host["time"], 9), times)]
        b = ours[name][np.isin(np.round(ours["time"], 9), times)]
        scale = max(1.0, float(np.max(np.abs(b))))
        assert np.max(np.abs(a - b)) <= 1e-15 * scale, name
        compared += 1
    assert compared > 0, f"no output of {path.name} in fmi-sim's columns {sorted(host)}"
