"""The FMI 3.0 FMUs under FMI 3.0 hosts independent of fmpy, each against fmpy or our master.

- ecos 0.7.2 (NTNU's co-simulation engine, pip ``ecospy``, already a dev dependency; it
  loads FMI 3.0 FMUs through fmi4c and needs Debian's libtbb12, which .ci/hosts.sh
  installs): runs in CI with the default suite. Each FMU alone, every scalar output after
  every step, bit for bit against fmpy's FMU3Slave taking the same steps (ecos adds the
  step to its time, t += h, so the comparison does too); and the connected 3T scene
  (mechanism3t_paper) against our master. ecos 0.7.2 reads every FMI 3 variable as a
  scalar and skips Enumerations: what that does to the array FMUs is checked as such.
- fmi-sim 0.7.0 (rust-fmi; .ci/fmi3_host.sh builds it from crates.io, ~25 min): optional,
  skipped where it is not built (MB_FMI_SIM names it, or fmi-sim on PATH), unless
  MB_REQUIRE_FMI3_HOST=1 (that script), where a missing fmi-sim is a failure.

Skipped where ecospy cannot load (no libtbb12, another platform), as tests/hosts/test_ecos.py."""
import contextlib
import csv
import dataclasses
import os
import shutil
import subprocess

import numpy as np
import pytest
from fmpy import extract, read_model_description, simulate_fmu
from fmpy.fmi3 import FMU3Slave

from fmu_src import catalogue, native_build
from fmu_src import python_build as builder
from scenarios import spec
from scenarios.runs import runner, single

try:
    from ecospy import EcosLib, EcosSimulation, EcosSimulationStructure
    EcosLib.set_log_level("err")
    ECOS, ECOS_MISSING = EcosLib.version(), ""
except (ImportError, OSError) as exc:   # ecospy missing, or its library cannot load (libtbb12)
    ECOS, ECOS_MISSING = None, f"ecos unavailable: {exc}"

FMI_SIM = os.environ.get("MB_FMI_SIM") or shutil.which("fmi-sim")
REQUIRE_FMI_SIM = os.environ.get("MB_REQUIRE_FMI3_HOST") == "1"
needs_ecos = pytest.mark.skipif(ECOS is None, reason=ECOS_MISSING)
needs_fmi_sim = pytest.mark.skipif(FMI_SIM is None and not REQUIRE_FMI_SIM,
                                   reason="fmi-sim is not built here (.ci/fmi3_host.sh builds it)")

STEPS, H = 100, 1e-3
# A scalar input per FMU moved off its start (at the first step, and again half way), so
# that each run does something: (name, offset at step 0, offset at STEPS // 2). Telescope
# (no inputs) and Wind (gusts) move by themselves. LegController and LegSensor have only
# array outputs, which ecos cannot read (test_ecos_reads_an_array_as_one_value).
DRIVE = {
    "HexapodPlant": ("platform_wrench[3]", -50.0, 20.0),      # N on the platform
    "Mechanism3TPlant": ("slider_force[1]", 5.0, -5.0),       # N on a slider
    "BaseSensor": ("axis[1]", 0.3, 0.35),                     # rad
    "SliderController": ("slider_position[1]", 1e-3, -1e-3),  # m off the reference
    "Telescope": None,
    "Wind": None,
}
# FMUs whose only scalar outputs hold still unless a parameter switches them on: LegController's
# observer_state (a unit per element, so no array), its disturbance observer off by default;
# its array outputs are compared in test_ecos_reads_an_array_as_one_value
STILL = {"LegController": "observer_state"}


@pytest.fixture(scope="module")
def fmi3():
    """script -> the native FMI 3.0 FMU (build/fmu/native3, built when stale)."""
    return native_build.ensure_native3(builder.available())


def scalar_outputs(path):
    return [v for v in read_model_description(str(path)).modelVariables
            if v.causality == "output" and v.type == "Float64" and not v.dimensions]


def start(path, name):
    return float(next(v.start for v in read_model_description(str(path)).modelVariables if v.name == name) or 0.0)


@contextlib.contextmanager
def ecos_run(models, h, connections=()):
    """An initialised ecos simulation of ``models`` ({instance: FMU path}) with real
    connections [(source, sink)] of "inst::name" variables; terminated and freed after."""
    structure = EcosSimulationStructure()
    for inst, path in models.items():
        structure.add_model(inst, str(path))
    for source, sink in connections:
        structure.make_real_connection(source, sink)
    sim = EcosSimulation(structure=structure, step_size=h)
    try:
        assert sim.init(0.0)
        yield sim
    finally:
        sim.terminate()
        sim.free()
        structure.free()


def fmpy_rows(path, names, drive, steps, h):
    """The outputs ``names`` after every step of fmpy's FMU3Slave, stepped as ecos steps:
    doStep(t, h), then t += h; the drive input set before step 0 and at steps // 2."""
    md = read_model_description(str(path))
    vrs = {v.name: v.valueReference for v in md.modelVariables}
    folder = extract(str(path))
    fmu = FMU3Slave(guid=md.guid, unzipDirectory=folder, modelIdentifier=md.coSimulation.modelIdentifier,
                    instanceName="m")
    try:
        fmu.instantiate()
        fmu.enterInitializationMode(startTime=0.0)
        fmu.exitInitializationMode()
        t, rows = 0.0, []
        for k in range(steps):
            if drive and k in (0, steps // 2):
                fmu.setFloat64([vrs[drive[0]]], [start(path, drive[0]) + drive[1 if k == 0 else 2]])
            fmu.doStep(t, h)
            t += h
            rows.append(fmu.getFloat64([vrs[n] for n in names]))
        fmu.terminate()
        fmu.freeInstance()
    finally:
        shutil.rmtree(folder, ignore_errors=True)
    return np.array(rows)


# ------------------------------------------------------------------------------ ecos
@needs_ecos
@pytest.mark.parametrize("script", catalogue.SCRIPTS)
def test_ecos_runs_the_fmu_as_fmpy_does(fmi3, script):
    """Every scalar output of every FMU, after each of 100 ecos steps, equals fmpy's bit
    for bit. An FMU whose outputs are all arrays has none to compare (next test)."""
    path = fmi3[script]
    model = path.stem
    names = [v.name for v in scalar_outputs(path)]
    if model in STILL:
        assert names and all(n.startswith(STILL[model]) for n in names), names
        pytest.skip(f"{model}: its scalar outputs ({STILL[model]}) hold still by default")
    if model not in DRIVE:
        assert not names, f"{model} has scalar outputs: give it a DRIVE entry"
        pytest.skip(f"{model}: every output is an array (test_ecos_reads_an_array_as_one_value)")
    drive = DRIVE[model]
    with ecos_run({"m": path}, H) as sim:
        rows = []
        for k in range(STEPS):
            if drive and k in (0, STEPS // 2):
                sim.set_real("m::" + drive[0], start(path, drive[0]) + drive[1 if k == 0 else 2])
            sim.step()
            rows.append([sim.get_real("m::" + n) for n in names])
        assert sim.get_time() == sum([H] * STEPS)
    theirs, ours = np.array(rows), fmpy_rows(path, names, drive, STEPS, H)
    moving = [n for j, n in enumerate(names) if np.ptp(ours[:, j]) > 0]
    assert moving, f"no output of {model} moves: the comparison would prove nothing"
    different = [n for j, n in enumerate(names) if not np.array_equal(theirs[:, j], ours[:, j])]
    assert not different, f"ecos {ECOS} differs from fmpy on {different}"


@needs_ecos
@pytest.mark.parametrize("model, array, scalar_input", [("LegController", "leg_force", "reference_pose[3]"),
                                                        ("HexapodPlant", "leg_force", "platform_wrench[3]"),
                                                        ("LegSensor", "measured_length", None)])
def test_ecos_reads_an_array_as_one_value(fmi3, capfd, model, array, scalar_input):
    """What ecos 0.7.2 does with an FMI 3 array: it lists ``leg_force`` as one Real, asks
    fmi3GetFloat64 for 1 value of 6, our FMU answers fmi3Error with a log line (FMI 3.0:
    nValues must cover the arrays), and ecos shows that line only at its debug log level
    and returns a number that is not the FMU's (0.0, or one left in its buffers: -0.287 for
    LegController's leg_force here) with no error. Sets of an array fail the same way and
    are dropped as silently; ecos makes one fmi3SetFloat64 of every Real set before a step,
    so a scalar set in the same step (reference_pose[3]: 7 values, nValues 2) is lost with it."""
    path = next(p for p in fmi3.values() if p.stem == model)
    EcosLib.set_log_level("debug")
    try:
        with ecos_run({"m": path}, H) as sim:
            if scalar_input:
                sim.set_real("m::" + scalar_input, start(path, scalar_input) + 0.01)
            sim.set_real("m::" + array, 1.0)
            sim.step()
            value = sim.get_real("m::" + array)
    finally:
        EcosLib.set_log_level("err")
    log = capfd.readouterr().out
    print(f"ecos {ECOS}: {model}.{array} reads {value!r}, with no error")
    assert isinstance(value, float)
    assert "Error fmi3GetFloat64: the value references cover 6 values, nValues is 1" in log, log[-2000:]
    expected = "7 values, nValues is 2" if scalar_input else "6 values, nValues is 1"
    assert f"Error fmi3SetFloat64: the value references cover {expected}" in log, log[-2000:]


@needs_ecos
def test_ecos_steps_on_past_a_discard_and_errors(fmi3, capfd):
    """A step our FMU refuses (BaseSensor, an axis of 1e300: non-finite accelerations)
    answers fmi3Discard with terminateSimulation; ecos 0.7.2 steps on as with FMI 2.0
    (tests/hosts/test_ecos.py): every later fmi3DoStep answers fmi3Error (not allowed in
    StepDiscarded), ecos's time advances with no error, and the outputs stay those of the
    last accepted step. The lines show only at its debug log level."""
    path = next(p for p in fmi3.values() if p.stem == "BaseSensor")
    names = [v.name for v in scalar_outputs(path)]
    EcosLib.set_log_level("debug")
    try:
        with ecos_run({"m": path}, H) as sim:
            sim.set_real("m::axis[1]", 0.3)
            sim.step()
            accepted = [sim.get_real("m::" + n) for n in names]
            sim.set_real("m::axis[1]", 1e300)
            for _ in range(3):
                sim.step()
            time, after = sim.get_time(), [sim.get_real("m::" + n) for n in names]
    finally:
        EcosLib.set_log_level("err")
    log = capfd.readouterr().out
    assert "Discard NonFiniteOutputError at t=0.001 s" in log, log[-2000:]
    assert log.count("Error fmi3DoStep: not allowed in state StepDiscarded") == 2, log[-2000:]
    assert time == sum([H] * 4) and after == accepted and any(x != 0 for x in accepted)


def _elements(descriptions, reference):
    inst = reference.split(".", 1)[0]
    return [f"{inst}::{n}" for n in spec.expand({v.name for v in descriptions[inst].modelVariables}, reference)]


@needs_ecos
@pytest.mark.parametrize("step", [2.0 ** -10, 1e-3])
def test_ecos_runs_the_connected_3t_scene_as_our_master_does(step, tmp_path):
    """mechanism3t_paper ([ci], 1 s) with FMI 3.0 FMUs: the plant and the slider
    controller connected both ways (every connection a scalar, which ecos can connect),
    under ecos and under our Jacobi master. With a step of 2^-10 s both take the same
    communication points (ecos's t += h is k h exactly): every recorded variable is
    equal bit for bit. With 1 ms, ecos's summed time differs from our k h in the last bit
    from step 10 on; the controller's reference sin(0.5 t) sees that, and the runs
    differ by round-off (below 1e-12 of each vector's scale; the step printed)."""
    scenario, paths, descriptions, values = runner.prepare(runner.resolve("mechanism3t_paper"), ci=True,
                                                           fmi_version=3)
    assert all(not v for v in values.values()), "the scene sets parameters: ecos must get them too"
    record = ["plant.slider_position", "plant.platform_position", "controller.slider_force",
              "controller.reference_position"]
    steps = round(scenario.stop_time / step)
    scenario = dataclasses.replace(scenario, step=step, stop_time=steps * step, record_interval=step, record=record,
                                   metrics=[])
    assert scenario.master == "jacobi" and scenario.extrapolation == "none"
    ours = single.run(scenario, paths, {i: dict(v) for i, v in values.items()}, tmp_path, "ours").records
    names = list(ours.names)
    connections = [(a, b) for source, sinks in scenario.connections for sink in sinks
                   for a, b in zip(_elements(descriptions, source), _elements(descriptions, sink), strict=True)]
    assert len(connections) == 9
    with ecos_run(paths, step, connections) as sim:
        rows = [[sim.get_real(n.replace(".", "::", 1)) for n in names]]
        for _ in range(steps):
            sim.step()
            rows.append([sim.get_real(n.replace(".", "::", 1)) for n in names])
    theirs = np.array(rows)
    mine = np.array([ours[n] for n in names]).T
    assert theirs.shape == mine.shape == (steps + 1, len(names))
    assert np.ptp(mine[:, names.index("plant.platform_position[1]")]) > 1e-3   # the sliders move: 10 mm sines
    differ = np.flatnonzero(np.any(theirs != mine, axis=1))
    worst = max(np.max(np.abs(theirs[:, j] - mine[:, j])) / max(1e-300, np.max(np.abs(mine[:, j])))
                for j in range(len(names)))
    print(f"ecos {ECOS} vs our master, 3T scene, step {step:g} s: {len(differ)} of {steps + 1} rows differ "
          f"(first at step {differ[0] if differ.size else '-'}), largest difference {worst:.3g} of the scale")
    if step == 2.0 ** -10:
        assert differ.size == 0
    else:
        assert worst < 1e-12 and (differ.size == 0 or differ[0] >= 10)


# --------------------------------------------------------------------------- fmi-sim
STOP = 0.1


def fmi_sim(path, out):
    """fmi-sim's co-simulation of ``path`` from 0 to STOP (fmi-sim 0.7 takes its step from
    -n, the number of output points, and ignores --step): the finished process (its log at
    level error on stderr)."""
    return subprocess.run([FMI_SIM, "--model", str(path), "--output-file", str(out), "co-simulation",
                           "-s", "0", "-f", repr(STOP), "-n", str(round(STOP / H))],
                          capture_output=True, text=True, timeout=300, env={**os.environ, "RUST_LOG": "error"})


@needs_fmi_sim
@pytest.mark.parametrize("script", catalogue.SCRIPTS)
def test_fmi_sim_runs_the_fmu_as_fmpy_does(fmi3, script, tmp_path):
    """Every output fmi-sim records equals fmpy's simulate_fmu at the same points, to
    1e-12 relative (fmi-sim adds the step to the time while simulate_fmu multiplies). fmi-sim
    0.7 reads every output as a scalar: on an FMU with an array output it asks
    fmi3GetFloat64 for 1 value of 6, and our FMU answers fmi3Error with a line saying so,
    which ends fmi-sim's run: checked as such."""
    assert FMI_SIM is not None and os.access(FMI_SIM, os.X_OK), f"MB_REQUIRE_FMI3_HOST=1 but no fmi-sim at {FMI_SIM!r}"
    path = fmi3[script]
    run = fmi_sim(path, tmp_path / "fmi-sim.csv")
    arrays = [
        v.name for v in read_model_description(str(path)).modelVariables if v.causality == "output" and v.dimensions
    ]
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
    assert host["time"].size > 50
    compared = 0
    for name, values in host.items():
        if name == "time":
            continue
        times = np.intersect1d(np.round(host["time"], 9), np.round(ours["time"], 9))
        assert times.size > 50, name
        a = values[np.isin(np.round(host["time"], 9), times)]
        b = ours[name][np.isin(np.round(ours["time"], 9), times)]
        assert np.max(np.abs(a - b)) <= 1e-12 * max(1.0, float(np.max(np.abs(b)))), name
        compared += 1
    assert compared > 0, f"no output of {path.name} in fmi-sim's columns {sorted(host)}"
