"""Every FMU of the kit in a host that is not Python: tests/hosts/c_host/fmi2_host.c, compiled
here and run in a fresh process per case (tests/hosts/c_host.py). The process must exit 0 after
the full FMI calling sequence, every time (issue 10: SIGSEGV/SIGABRT in Py_FinalizeEx at
exit), and the FMI statuses must say what the FMU did."""
import math

import numpy as np
import pytest

from fmu_src.catalogue import SCRIPTS
from plant.hexapod.model import HOME_POSE, StewartParams, inverse_dynamics
from tests.fmu_helpers import BAD_INIT, INIT_PARAMETERS, output_starts
from tests.hosts.c_host import HostFmu, compile_host

STATIC = inverse_dynamics(StewartParams.paper(), HOME_POSE, np.zeros(6), np.zeros(6))


@pytest.fixture(scope="module")
def hosted(fmus, tmp_path_factory):
    """Each FMU extracted once, by script name."""
    compile_host()   # a compile error fails here, once
    return {script: HostFmu(fmus[script], tmp_path_factory.mktemp(script)) for script in SCRIPTS}


def _outputs(fmu, n=4):
    return [v.name for v in fmu.md.modelVariables if v.causality == "output"][:n]


@pytest.mark.parametrize("script", SCRIPTS)
@pytest.mark.parametrize("dlclose", [True, False], ids=["dlclose", "no-dlclose"])
def test_a_c_host_runs_the_fmu_and_exits_0(hosted, script, dlclose):
    """Instantiate, initialise, 20 doSteps with a get/set state replay, terminate, free:
    every call OK, the replay bit-identical, and the process exits 0 (twice, fresh)."""
    fmu = hosted[script]
    for _ in range(2):
        run = fmu.run(steps=20, out=_outputs(fmu), state=9, dlclose=dlclose)
        assert (run.returncode, run.signal, run.statuses()) == (0, None, []), run.stderr[-2000:]
        assert run.stdout.endswith("done\n")
        out, replay = run.lines("out"), run.lines("replay")
        assert len(out) == 21 and len(replay) == 10
        assert replay == out[-10:]   # same times, same values, after fmi2SetFMUstate


@pytest.mark.parametrize("integrator", [1, 2], ids=["euler", "radau"])
def test_plant_integrators_in_a_c_host_exit_0(hosted, integrator):
    """Radau pulls scipy's solve_ivp into the process while stepping (the import that
    used to be enough for the crash)."""
    fmu = hosted["hexapod_plant_fmu"]
    run = fmu.run(steps=5, integer={"integrator": integrator, "moving_base": 0}, out=["pose[3]"])
    assert (run.returncode, run.signal, run.statuses()) == (0, None, []), run.stderr[-2000:]


def _assert_refused_with_error(run, text):
    """fmi2ExitInitializationMode answered fmi2Error (not fmi2Fatal: fmu_src/pythonfmu_shim.c),
    the host stopped there, freed the instance and exited normally with 3 = fmi2Error."""
    assert (run.returncode, run.signal) == (3, None), run.stderr[-2000:]
    assert run.statuses() == [("fmi2ExitInitializationMode", "Error")]
    assert run.stdout.endswith("done\n") and not run.lines("out")
    assert text in run.stderr, run.stderr[-2000:]
    errors = [line for line in run.stderr.splitlines() if line.startswith("[")]
    assert errors[-1].startswith("[Error] host logStatusError: InvalidInputError in initialization: ")
    assert "Fatal" not in run.stderr   # the wrapper's fatal line ("Fatal py exception ...") is dropped


@pytest.mark.parametrize("script", SCRIPTS)
@pytest.mark.parametrize("value, dlclose", [(math.nan, True), (math.inf, False)], ids=["nan-dlclose",
                                                                                      "inf-no-dlclose"])
def test_non_finite_value_at_initialization_is_fmi2_error_in_a_c_host(hosted, script, value, dlclose):
    """The failure surfaces at fmi2ExitInitializationMode, not at the first doStep, as
    fmi2Error, and the process exits normally with that status."""
    name, text = BAD_INIT[script][:2]
    run = hosted[script].run(steps=3, real={name: value}, dlclose=dlclose)
    _assert_refused_with_error(run, text.format(value))


@pytest.mark.parametrize("script", SCRIPTS)
@pytest.mark.parametrize("dlclose", [True, False], ids=["dlclose", "no-dlclose"])
def test_out_of_range_parameter_is_fmi2_error_in_a_c_host(hosted, script, dlclose):
    name, value, text = BAD_INIT[script][2:]
    run = hosted[script].run(steps=3, real={name: value}, dlclose=dlclose)
    _assert_refused_with_error(run, f"parameter {text}")


@pytest.mark.parametrize("value", [math.nan, math.inf, -math.inf], ids=["nan", "inf", "-inf"])
def test_every_non_finite_input_value_is_refused_the_same_way(hosted, value):
    fmu = hosted["leg_controller_fmu"]
    run = fmu.run(steps=3, real={"leg_rate[2]": value}, real_init={"leg_rate[3]": 0.5})
    _assert_refused_with_error(run, f"input leg_rate[2] = {value} at initialization: inputs must be finite")


def test_discarded_step_keeps_the_last_accepted_outputs_and_time(hosted):
    """A force pulse runs leg 1 past a 10 mm stroke: doStep answers Discard, the outputs
    read afterwards are those of the last accepted step (not the rejected state) and
    fmi2GetRealStatus(fmi2LastSuccessfulTime) names that step's time."""
    fmu = hosted["hexapod_plant_fmu"]
    names = ["leg_length[1]", "leg_rate[1]", "pose[3]", "pose_rate[3]"]
    run = fmu.run(steps=40, integer={"moving_base": 0}, real={"stroke": 0.01, **{
        f"leg_force[{i + 1}]": STATIC[i] for i in range(6)}}, real_at={(10, "leg_force[1]"): 1e6}, out=names)
    assert run.signal is None and run.returncode == 2, run.stderr[-2000:]
    assert run.statuses() == [("fmi2DoStep", "Discard")]
    accepted, (discarded,) = run.lines("out"), run.lines("discarded")
    last = accepted[-1]
    assert accepted[-1][0] < discarded[0]          # the rejected step ends later ...
    assert discarded[1:] == last[1:]               # ... but the outputs are the accepted state's
    assert abs(last[1] - StewartParams.paper().home_lengths[0]) < 0.01   # inside the stroke
    (successful,), = run.lines("last_successful_time")
    assert successful == pytest.approx(last[0], abs=1e-12)
    assert "StrokeError" in run.stderr and "leg 1 length" in run.stderr


def test_a_missing_pythonfmu_wrapper_is_named_by_the_shim(fmus, tmp_path):
    """The shim (binaries/linux64/<id>.so) loads pythonfmu's wrapper from beside itself at
    fmi2Instantiate: without it, instantiate answers NULL and the log names the file."""
    fmu = HostFmu(fmus["telescope_fmu"], tmp_path)
    wrapper = fmu.folder / "binaries" / "linux64" / "Telescope.pythonfmu.so"
    wrapper.unlink()
    run = fmu.run(steps=1)
    assert (run.returncode, run.signal) == (12, None), run.stderr
    assert f"[Fatal] host logStatusFatal: pythonfmu shim: dlopen {wrapper}: " in run.stderr
    assert "No such file" in run.stderr


def _init_case(fmu, path):
    """Outputs, their values before initialization and the in-initialization input settings (every Real
    input moved from its start, as tests/fmu_src/test_python_fmus.py does) of one FMU."""
    variables = fmu.md.modelVariables
    outputs = [v.name for v in variables if v.causality == "output"]
    start = output_starts(path)
    inputs = [v for v in variables if v.causality == "input" and v.type == "Real"]
    return outputs, start, {v.name: float(v.start) + 1e-3 * (1 + k % 5) for k, v in enumerate(inputs)}


@pytest.mark.parametrize("script", SCRIPTS)
def test_outputs_read_in_initialization_mode_in_a_c_host(fmus, hosted, script):
    """In a host that is not Python, outputs read after setting the inputs in
    initialization mode are those initialization ends with (the "out" line right after
    fmi2ExitInitializationMode), not the start values; the process exits 0."""
    fmu = hosted[script]
    outputs, start, inputs = _init_case(fmu, fmus[script])
    run = fmu.run(steps=1, real=INIT_PARAMETERS.get(script, {}), real_init=inputs, out=outputs, init_out=True)
    assert (run.returncode, run.signal, run.statuses()) == (0, None, []), run.stderr[-2000:]
    (init,), after_exit = run.lines("init"), run.lines("out")[0]
    assert init == after_exit
    assert init[1:] != start


@pytest.mark.parametrize("script", SCRIPTS)
def test_a_bad_input_read_in_initialization_mode_still_ends_in_fmi2_error(fmus, hosted, script):
    """A NaN input (the telescope has none: a parameter) set in initialization mode and
    the outputs read then: the read answers OK with the outputs as they were before
    initialization (no log line), and fmi2ExitInitializationMode reports the bad value
    with fmi2Error as it does without the read; the process exits normally."""
    fmu = hosted[script]
    outputs, start, _ = _init_case(fmu, fmus[script])
    name, text = BAD_INIT[script][:2]
    run = fmu.run(steps=3, real_init={name: math.nan}, out=outputs, init_out=True)
    _assert_refused_with_error(run, text.format(math.nan))
    (init,) = run.lines("init")
    assert init[1:] == start
