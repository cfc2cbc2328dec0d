"""The FMUs under a careless or hostile C host (issues 18 and 20): tests/hosts/c_host/misuse.c
(FMI 2.0) and misuse3.c (FMI 3.0) run one script of calls in a fresh process per case and
print every answer; each is held against what FMI 2.0 / FMI 3.0 and the Reference FMUs answer. No case may crash (a
signal), hang
(the timeout), or draw a sanitizer report (.ci/sanitize.sh runs this file on builds with
-fsanitize=address,undefined; MOVINGBASE_MISUSE_FMUS and MOVINGBASE_MISUSE_FMUS3 name its
folders of extracted FMI 2.0 and FMI 3.0 FMUs).

Every run also checks the log: each call that did not answer OK was explained by the
log line just before it, at the status the call returned."""
import math
import os
import shutil

import pytest
from fmpy import read_model_description

from tests.hosts.c_host import INIT, INIT3, MISUSE3, MODELS, run, run3

STATUS = ("OK", "Warning", "Discard", "Error", "Fatal")
MAX_SUBSTEPS = 1_000_000   # MB_MAX_SUBSTEPS, fmu_src/native/model.h


# ------------------------------------------------------------------ every native FMU
@pytest.mark.parametrize("model", MODELS)
def test_host_strings_with_conversions_are_printed_not_read(extracted, model):
    """A GUID, an instance name or a log category holding printf conversions ("%s", "%n")
    crashed the host: the FMU passed them inside the logger's format. Now the host's
    printf prints them as they are."""
    fmu = extracted[model]
    guid = "%s%s%s%s%n%n{guid}"
    answers = run(fmu, "inst", guid, "-")
    assert answers.lines[0] == "fmi2Instantiate NULL" or "fmi2Instantiate NULL" in answers.lines
    assert any(f"GUID '{guid}'" in line for line in answers.logs), answers.logs
    answers = run(fmu, "inst", "-", "%s%n%s", "log", "%s%s%n%n%s")
    assert answers.statuses("fmi2SetDebugLogging") == ["Error"]
    assert any("'%s%s%n%n%s'" in line for line in answers.logs), answers.logs


SEQUENCES = {   # FMI 2.0 call sequence: script, then the statuses every call answers in order
    "GetReal before initialization": (("getr", "OUT"), ["Error"]),
    "Terminate before initialization": (("term",), ["Error"]),
    "Terminate in initialization mode": (("setup", 0.0, "enter", "term"), ["OK", "OK", "Error"]),
    "Terminate twice": ((*INIT, "term", "term"), ["OK"] * 3 + ["OK", "Error"]),
    "SetReal after Terminate": ((*INIT, "term", "setr", "IN", 0.0), ["OK"] * 4 + ["Error"]),
    "GetReal after Terminate": ((*INIT, "term", "getr", "OUT"), ["OK"] * 5),
    "doStep before initialization": (("step", 0.0, 1e-3), ["Error"]),
    "doStep in initialization mode": (("setup", 0.0, "enter", "step", 0.0, 1e-3), ["OK", "OK", "Error"]),
    "doStep after Terminate": ((*INIT, "term", "step", 0.0, 1e-3), ["OK"] * 4 + ["Error"]),
    "ExitInitializationMode without Enter": (("setup", 0.0, "exit"), ["OK", "Error"]),
    "EnterInitializationMode twice": (("setup", 0.0, "enter", "enter"), ["OK", "OK", "Error"]),
    "SetupExperiment after initialization": ((*INIT, "setup", 0.0), ["OK"] * 3 + ["Error"]),
    "Reset after Terminate starts over": ((*INIT, "step", 0.0, 1e-3, "term", "reset", *INIT, "step", 0.0, 1e-3),
                                         ["OK"] * 10),
    "doStep forward of the FMU's time": ((*INIT, "step", 5.0, 1e-3), ["OK"] * 3 + ["Error"]),
    "doStep back to an earlier time": ((*INIT, "step", 0.0, 1e-3, "step", 0.0, 1e-3), ["OK"] * 4 + ["Error"]),
    "doStep before the start": ((*INIT, "step", -5.0, 1e-3), ["OK"] * 3 + ["Error"]),
    "a step of 0": ((*INIT, "step", 0.0, 0.0), ["OK"] * 3 + ["Error"]),
    "a negative step": ((*INIT, "step", 0.0, -1e-3), ["OK"] * 3 + ["Error"]),
    "a NaN step": ((*INIT, "step", 0.0, math.nan), ["OK"] * 3 + ["Error"]),
    "an infinite step": ((*INIT, "step", 0.0, math.inf), ["OK"] * 3 + ["Error"]),
    "a step below the time's resolution": (("setup", 1e300, "enter", "exit", "step", 1e300, 1e-3),
                                           ["OK"] * 3 + ["Error"]),
    "a step past the stopTime": (("setup-stop", 0.0, 2e-3, "enter", "exit", "step", 0.0, 1e-3, "step", 1e-3, 1e-3,
                                  "step", 2e-3, 1e-3), ["OK"] * 5 + ["Error"]),
    "a stopTime before the startTime": (("setup-stop", 1.0, 0.5), ["Error"]),
    "a refused step leaves the time as it was": ((*INIT, "step", 0.0, 0.0, "step", 0.0, 1e-3),
                                                 ["OK"] * 3 + ["Error", "OK"]),
    "an FMU state restores the time": ((*INIT, "step", 0.0, 1e-3, "save", "step", 1e-3, 1e-3, "restore",
                                        "step", 1e-3, 1e-3, "step", 1e-3, 1e-3, "drop"),
                                       ["OK"] * 8 + ["Error", "OK"]),
}


# The call-sequence table on three FMUs in the default run (one shared layer answers it:
# a plant, a source, a sensor); on all eight in the slow run and in .ci/sanitize.sh.
SEQUENCE_MODELS = [m if m in ("HexapodPlant", "Telescope", "LegSensor") else pytest.param(m, marks=pytest.mark.slow)
                   for m in MODELS]


def named(fmu, script):
    """A sequence script with "OUT" and "IN" (alone: their value reference; in a tuple:
    their name) standing for the FMU's first output and first input (or parameter)."""
    names = {"OUT": fmu.first("output"), "IN": fmu.first("input") or fmu.first("parameter")}
    return [(w[0], names[w[1]], *w[2:]) if isinstance(w, tuple) and w[1] in names
            else ("vr", names[w]) if isinstance(w, str) and w in names else w for w in script]


@pytest.mark.parametrize("model", SEQUENCE_MODELS)
@pytest.mark.parametrize("case", SEQUENCES)
def test_call_sequence_answers_as_fmi2_specifies(extracted, model, case):
    fmu = extracted[model]
    script, expected = SEQUENCES[case]
    script = named(fmu, script)
    answers = run(fmu, "inst", "-", "-", *script)
    assert [status for _, status in answers.calls[1:]] == expected, answers.lines


@pytest.mark.parametrize("model", MODELS)
def test_a_failed_instance_refuses_steps_and_sets(extracted, model):
    """After a Discard (the step size 10 s on a plant past its work bound, or a NaN input
    elsewhere) doStep answers Discard again, SetReal Error, Terminate OK."""
    fmu = extracted[model]
    bad = {"HexapodPlant": ("setr", ("vr", "leg_force[1]"), math.nan),
           "Mechanism3TPlant": ("setr", ("vr", "slider_force[1]"), math.nan),
           "Telescope": ()}.get(model, ("setr", ("vr", fmu.first("input") or ""), math.nan))
    if model == "Telescope":
        script = ("setr", ("vr", "servo_bandwidth"), 10.0, *INIT, "step", 0.0, 1e9)
    else:
        script = (*INIT, *bad, "step", 0.0, 1e-3)
    answers = run(fmu, "inst", "-", "-", *script, "step", 0.0, 1e-3, "setr", ("vr", fmu.first("input") or
                                                                          fmu.first("parameter")), 1.0, "last", "term")
    assert answers.statuses("fmi2DoStep") == ["Discard", "Discard"], answers.lines
    assert answers.statuses("fmi2SetReal")[-1] == "Error" and answers.statuses("fmi2Terminate") == ["OK"]
    assert "last 0" in answers.lines


# --------------------------------------------------------------- work bound, overflow
@pytest.mark.parametrize("model, name, value, h", [
    ("HexapodPlant", "max_step", 1e-9, 10.0),        # 1e10 substeps: an int overflow that integrated nothing
    ("HexapodPlant", None, None, 1e6),               # 1e9 substeps: hours, unstoppable
    ("Mechanism3TPlant", "max_step", 1e-9, 10.0),
    ("Telescope", "servo_bandwidth", 10.0, 1e8),  # axes of -2.27e28 rad
])
def test_a_step_past_the_work_bound_is_refused_at_once(extracted, model, name, value, h):
    fmu = extracted[model]
    out = fmu.first("output")
    setting = ("setr", ("vr", name), value) if name else ()
    answers = run(fmu, "inst", "-", "-", *setting, *INIT, "getr", ("vr", out), "step", 0.0, h, "getr", ("vr", out),
                  timeout=30)
    assert answers.statuses("fmi2DoStep") == ["Discard"]
    assert any(line.startswith("Discard logStatusDiscard: WorkBoundError at t=0 s") and
               f"more than the {MAX_SUBSTEPS} a doStep may take" in line for line in answers.logs), answers.logs
    assert answers.statuses("fmi2GetReal") == ["OK", "OK"]   # the outputs of the last accepted state
    assert len(set(answers.lines[k] for k, line in enumerate(answers.lines) if line.startswith("value "))) == 1


@pytest.mark.parametrize("model, name, value, h", [
    ("HexapodPlant", "max_step", 1e-9, 10.0),
    ("HexapodPlant", None, None, 1e6),
    ("Mechanism3TPlant", "max_step", 1e-9, 10.0),
    ("Telescope", "servo_bandwidth", 10.0, 1e8),
])
def test_pythonfmu_step_past_the_work_bound_is_refused_at_once(python_fmus, model, name, value, h):
    """The same bound in the pythonfmu FMUs (plant.integrators.MAX_SUBSTEPS): refused at
    once, not hours of substeps or an overflowed servo count."""
    test_a_step_past_the_work_bound_is_refused_at_once(python_fmus, model, name, value, h)


@pytest.mark.parametrize("substeps, status", [(MAX_SUBSTEPS + 1, "Discard"),
                                               pytest.param(MAX_SUBSTEPS, "OK", marks=pytest.mark.slow)])
def test_the_work_bound_is_exact(extracted, substeps, status):
    """A step of exactly MB_MAX_SUBSTEPS substeps runs (5-8 s here); one more is refused."""
    h = 0.05
    answers = run(extracted["Mechanism3TPlant"], "inst", "-", "-", "setr", ("vr", "max_step"), h / substeps, *INIT,
                  "step", 0.0, h, timeout=120)
    assert answers.statuses("fmi2DoStep") == [status], answers.logs


# ---------------------------------------------------------------- non-finite outputs
@pytest.mark.parametrize("model, name, value", [
    ("LegSensor", "leg_length[1]", math.nan),
    ("LegSensor", "leg_length[1]", math.inf),
    ("BaseSensor", "axis[1]", 1e300),
    ("LegController", "reference_rate[1]", 1e300),
    ("LegController", "base_rate[4]", 1e300),
])
def test_no_ok_with_a_non_finite_output(extracted, model, name, value):
    """Each passed NaN/inf to an output with fmi2OK; now Discard, naming the input."""
    fmu = extracted[model]
    out = fmu.first("output")
    answers = run(fmu, "inst", "-", "-", *INIT, "getr", ("vr", out), "setr", ("vr", name), value, "step", 0.0, 1e-3,
                  "getr", ("vr", out))
    assert answers.statuses("fmi2DoStep") == ["Discard"], answers.lines
    line = answers.logs[-1]
    assert "NonFiniteOutputError at t=0 s" in line and f"largest magnitude is {name} = " in line, line
    values = [line for line in answers.lines if line.startswith("value ")]
    assert len(values) == 2 and values[0] == values[1] and "nan" not in values[1] and "inf" not in values[1]


def test_a_non_finite_output_at_initialization_is_an_error(extracted):
    """SliderController's amplitude has no declared max: 1e300 gave NaN forces with OK.
    The refused initialization leaves them NaN: fmi2GetReal read them back with fmi2OK;
    now fmi2Error naming the output (an input or parameter reads back as set)."""
    fmu = extracted["SliderController"]
    out = fmu.first("output")
    answers = run(fmu, "inst", "-", "-", "setr", ("vr", "amplitude"), 1e300, *INIT, "getr", ("vr", out),
                  "getr", ("vr", "amplitude"), timeout=120)
    assert answers.statuses("fmi2ExitInitializationMode") == ["Error"]
    assert "largest magnitude is amplitude = 1e+300" in answers.logs[-2], answers.logs
    assert answers.statuses("fmi2GetReal") == ["Error", "OK"] and answers.values == {fmu.vr("amplitude"): 1e300}
    assert answers.logs[-1].startswith(f"Error logStatusError: fmi2GetReal: output {out} is nan, not finite (after: "
                                       "NonFiniteOutputError in initialization: "), answers.logs


# --------------------------------------------------------- threads, instances, memory
BUILDS = ["extracted", "native3"]   # the session fixtures of the FMI 2.0 and the FMI 3.0 builds


@pytest.mark.parametrize("build", BUILDS)
@pytest.mark.parametrize("model", MODELS)
def test_eight_threads_give_identical_results(request, build, model):
    answers = run(request.getfixturevalue(build)[model], "threads", 8, 20, 1e-3)
    results = [line.split()[2:] for line in answers.lines if line.startswith("thread ")]
    assert len(results) == 8 and all(r == results[0] for r in results) and results[0][0] == "OK", results


@pytest.mark.parametrize("build", BUILDS)
@pytest.mark.parametrize("model", MODELS)
def test_ten_thousand_instances(request, build, model):
    answers = run(request.getfixturevalue(build)[model], "many", 10_000, timeout=120)
    assert "many 10000 of 10000" in answers.lines


@pytest.mark.skipif(shutil.which("valgrind") is None, reason="valgrind is not installed")
@pytest.mark.parametrize("model", MODELS)
def test_saved_states_hold_no_uninitialised_bytes(extracted, model):
    """Wind's state held stack padding (valgrind: a conditional jump on an uninitialised
    value at the checksum). Every FMU's state is serialised under memcheck."""
    if os.environ.get("MOVINGBASE_MISUSE_FMUS"):
        pytest.skip("sanitizer builds: ASan and valgrind do not mix")
    fmu = extracted[model]
    answers = run(fmu, "inst", "-", "-", *INIT, "step", 0.0, 1e-3, "save", "bytes", "restore", "step", 1e-3, 1e-3,
                  wrapper=("valgrind", "-q", "--error-exitcode=99"), timeout=120)
    assert answers.statuses("fmi2SerializeFMUstate") == ["OK"]


# ------------------------------------------------------------------ pythonfmu FMUs
# Through the shim in front of pythonfmu's wrapper (fmu_src/pythonfmu_shim.c): the same
# call sequence, the same doStep time and step rules. Each run starts a Python, so the
# whole table runs on LegSensor by default and on every FMU with the slow tests.
PYTHON_MODELS = [m if m == "LegSensor" else pytest.param(m, marks=pytest.mark.slow) for m in MODELS]


@pytest.mark.parametrize("model", PYTHON_MODELS)
def test_pythonfmu_host_strings_with_conversions_are_printed_not_read(python_fmus, model):
    """The pythonfmu wrapper passes every message as the format; the shim doubles the '%'.
    A missing resource location crashed the wrapper (it finds no slave class): the shim
    refuses it."""
    fmu = python_fmus[model]
    answers = run(fmu, "inst", "-", "%s%n%s", "log", "%s%s%n%n%s", *INIT, "step", 0.0, 1e-3, "term", timeout=120)
    assert answers.statuses("fmi2DoStep") == ["OK"]
    answers = run(fmu, "nores", "inst", "-", "-", timeout=120)
    assert "fmi2Instantiate NULL" in answers.lines
    assert any("fmuResourceLocation ''" in line for line in answers.logs), answers.logs


@pytest.mark.parametrize("model", PYTHON_MODELS)
@pytest.mark.parametrize("case", SEQUENCES)
def test_pythonfmu_call_sequence_answers_as_fmi2_specifies(python_fmus, model, case):
    test_call_sequence_answers_as_fmi2_specifies(python_fmus, model, case)


def test_pythonfmu_failed_instance_refuses_steps_and_sets(python_fmus):
    fmu = python_fmus["LegSensor"]
    answers = run(fmu, "inst", "-", "-", *INIT, "setr", ("vr", "leg_length[1]"), math.nan, "step", 0.0, 1e-3,
                  "step", 0.0, 1e-3, "setr", ("vr", "leg_length[1]"), 1.0, "last", "term", timeout=120)
    assert answers.statuses("fmi2DoStep") == ["Discard", "Discard"], answers.lines
    assert answers.statuses("fmi2SetReal") == ["OK", "Error"] and answers.statuses("fmi2Terminate") == ["OK"]
    assert "last 0" in answers.lines


def test_pythonfmu_a_non_finite_output_at_initialization_is_an_error(python_fmus):
    """The same through the shim: GuardedSlave.get_real names the output, the shim answers fmi2Error."""
    test_a_non_finite_output_at_initialization_is_an_error(python_fmus)


def test_pythonfmu_no_ok_with_a_non_finite_output(python_fmus):
    """GuardedSlave checks every output after each step, as the native layer does."""
    fmu = python_fmus["BaseSensor"]
    answers = run(fmu, "inst", "-", "-", *INIT, "setr", ("vr", "axis[1]"), 1e300, "step", 0.0, 1e-3, timeout=120)
    assert answers.statuses("fmi2DoStep") == ["Discard"], answers.lines
    assert "NonFiniteOutputError at t=0 s" in answers.logs[-1] and "axis[1] = 1e+300" in answers.logs[-1]


def test_fmi3_build_was_used(native3):
    """The FMI 3.0 host runs FMI 3.0 binaries (a guard against testing the FMI 2.0 ones)."""
    assert set(native3) == set(MODELS)
    assert all(fmu.md.fmiVersion == "3.0" and fmu.host == MISUSE3 for fmu in native3.values())


@pytest.mark.parametrize("model", MODELS)
def test_fmi3_host_strings_with_conversions_are_text(native3, model):
    """An instantiation token, an instance name or a log category holding printf
    conversions reaches the host's log as text (FMI 3.0's message is not a format; the
    inner FMI 2.0 layer doubles '%' for its own format and fmi3_layer.c formats it back)."""
    fmu = native3[model]
    token = "%s%s%s%s%n%n{token}"
    answers = run(fmu, "inst", token, "-")
    assert "fmi3InstantiateCoSimulation NULL" in answers.lines
    assert any(f"instantiationToken '{token}'" in line for line in answers.logs), answers.logs
    answers = run(fmu, "inst", "-", "%s%n%s", "log", "%s%s%n%n%s")
    assert answers.statuses("fmi3SetDebugLogging") == ["Error"]
    assert any("'%s%s%n%n%s'" in line for line in answers.logs), answers.logs


SEQUENCES3 = {   # FMI 3.0 call sequence: script, then the statuses every call answers in order
    "GetFloat64 when Instantiated": ((("get", "OUT"),), ["Error"]),
    "GetFloat64 in initialization mode": (("enter", 0.0, ("get", "OUT")), ["OK", "OK"]),
    "Terminate when Instantiated": (("term",), ["Error"]),
    "Terminate in initialization mode": (("enter", 0.0, "term"), ["OK", "Error"]),
    "Terminate twice": ((*INIT3, "term", "term"), ["OK", "OK", "OK", "Error"]),
    "SetFloat64 after Terminate": ((*INIT3, "term", ("set", "IN", 0.0)), ["OK"] * 3 + ["Error"]),
    "GetFloat64 after Terminate": ((*INIT3, "term", ("get", "OUT")), ["OK"] * 4),
    "doStep when Instantiated": (("step", 0.0, 1e-3), ["Error"]),
    "doStep in initialization mode": (("enter", 0.0, "step", 0.0, 1e-3), ["OK", "Error"]),
    "doStep after Terminate": ((*INIT3, "term", "step", 0.0, 1e-3), ["OK"] * 3 + ["Error"]),
    "ExitInitializationMode without Enter": (("exit",), ["Error"]),
    "EnterInitializationMode twice": (("enter", 0.0, "enter", 0.0), ["OK", "Error"]),
    "EnterInitializationMode in step mode": ((*INIT3, "enter", 0.0), ["OK", "OK", "Error"]),
    "Reset after Terminate starts over": ((*INIT3, "step", 0.0, 1e-3, "term", "reset", *INIT3, "step", 0.0, 1e-3),
                                         ["OK"] * 8),
    "Reset in step mode starts over": ((*INIT3, "step", 0.0, 1e-3, "reset", *INIT3, "step", 0.0, 1e-3), ["OK"] * 7),
    "doStep forward of the FMU's time": ((*INIT3, "step", 5.0, 1e-3), ["OK", "OK", "Error"]),
    "doStep back to an earlier time": ((*INIT3, "step", 0.0, 1e-3, "step", 0.0, 1e-3), ["OK"] * 3 + ["Error"]),
    "a step of 0": ((*INIT3, "step", 0.0, 0.0), ["OK", "OK", "Error"]),
    "a negative step": ((*INIT3, "step", 0.0, -1e-3), ["OK", "OK", "Error"]),
    "a NaN step": ((*INIT3, "step", 0.0, math.nan), ["OK", "OK", "Error"]),
    "an infinite step": ((*INIT3, "step", 0.0, math.inf), ["OK", "OK", "Error"]),
    "a step below the time's resolution": (("enter", 1e300, "exit", "step", 1e300, 1e-3), ["OK", "OK", "Error"]),
    "a NaN start time": (("enter", math.nan), ["Error"]),
    "a step past the stopTime": (("enter-stop", 0.0, 2e-3, "exit", "step", 0.0, 1e-3, "step", 1e-3, 1e-3,
                                  "step", 2e-3, 1e-3), ["OK"] * 4 + ["Error"]),
    "a stopTime before the startTime": (("enter-stop", 1.0, 0.5), ["Error"]),
    "a refused step leaves the time as it was": ((*INIT3, "step", 0.0, 0.0, "step", 0.0, 1e-3),
                                                 ["OK", "OK", "Error", "OK"]),
    "doStep with NULL out arguments": ((*INIT3, "step-null", 0.0, 1e-3), ["OK", "OK", "Error"]),
    "an FMU state restores the time": ((*INIT3, "step", 0.0, 1e-3, "save", "step", 1e-3, 1e-3, "restore",
                                        "step", 1e-3, 1e-3, "step", 1e-3, 1e-3, "drop"),
                                       ["OK"] * 7 + ["Error", "OK"]),
    "an FMU state saved before initialization": (("save", *INIT3, "step", 0.0, 1e-3, "restore", "step", 0.0, 1e-3,
                                                  *INIT3), ["OK"] * 5 + ["Error", "OK", "OK"]),
    "an FMU state saved in initialization mode": (("enter", 0.0, "save", "exit", "step", 0.0, 1e-3, "restore",
                                                   "exit", "step", 0.0, 1e-3), ["OK"] * 7),
    "GetFMUState and SetFMUState with NULL": ((*INIT3, "save-null", "restore-null"), ["OK", "OK", "Error", "Error"]),
    "FreeFMUState twice": ((*INIT3, "save", "drop", "drop"), ["OK"] * 5),
    "calls this FMU does not offer": ((*INIT3, "unsupported"), ["OK", "OK"] + ["Error"] * 9),
    "types this FMU has no variable of": ((*INIT3, "getbool", 0, "getstring", 0, "getbinary", 0),
                                          ["OK", "OK", "Error", "Error", "Error"]),
    "GetFloat64 with NULL arrays": ((*INIT3, "getf-null-vr", "getf-null-values", ("vr", "OUT"), 1),
                                    ["OK", "OK", "Error", "Error"]),
    "an unknown value reference": ((*INIT3, "getf", 999999, 1, "geti32", 999999, "seti64", 4294967295, 0),
                                   ["OK", "OK", "Error", "Error", "Error"]),
    "FreeInstance(NULL)": (("free-null", *INIT3), ["OK", "OK"]),
}


# The table on three FMUs by default (one shared layer answers it: a plant, a source, a
# sensor); on all eight in the slow run and in .ci/sanitize.sh.
@pytest.mark.parametrize("model", SEQUENCE_MODELS)
@pytest.mark.parametrize("case", SEQUENCES3)
def test_fmi3_call_sequence_answers_as_fmi3_specifies(native3, model, case):
    fmu = native3[model]
    script, expected = SEQUENCES3[case]
    answers = run3(fmu, "inst", "-", "-", *named(fmu, script))
    assert [status for _, status in answers.calls[1:]] == expected, answers.lines


@pytest.mark.parametrize("model", ["HexapodPlant", "Telescope", "LegSensor"])
def test_fmi3_a_state_saved_in_terminated_restores_terminated(native3, model):
    """FMI 3.0 restores the state a state was saved in (the Reference FMUs copy it back):
    one saved in Terminated was restored in StepMode, where the inner layer, restored
    Terminated, refused the step under a line that named no FMI 3 state. Its time, outputs
    and the stopTime come back with it."""
    fmu = native3[model]
    out = ("get", fmu.first("output"))
    answers = run3(fmu, "inst", "-", "-", "enter-stop", 0.0, 1.0, "exit", "step", 0.0, 1e-3, out, "term", "save",
                   "reset", *INIT3, "step", 0.0, 1e-3, "step", 1e-3, 1e-3, "restore", out, "getf", fmu.vr("time"), 1,
                   "step", 1e-3, 1e-3, "term", "reset")
    assert [status for _, status in answers.calls[1:]] == ["OK"] * 14 + ["Error", "Error", "OK"], answers.lines
    assert answers.logs[-2:] == ["Error logStatusError: fmi3DoStep: not allowed in state Terminated",
                                 "Error logStatusError: fmi3Terminate: not allowed in state Terminated"], answers.logs
    saved, restored, time = answers.vectors
    assert restored == saved and time == [1e-3], answers.lines


@pytest.mark.parametrize("model", ["HexapodPlant", "LegSensor", "Mechanism3TPlant"])
def test_fmi3_the_time_and_the_arrays_by_value_reference(native3, model):
    """The independent variable reads the start time, then each step's end; it cannot be
    set. An array answers only with nValues of all its elements (not 1, not one more), a
    later element's value reference is no variable, a Float64 call on an Enumeration (or an
    Int64 call on a Float64) is an error, and an Enumeration outside Int32 is refused."""
    fmu = native3[model]
    time, first = fmu.vr("time"), fmu.first("output")
    n = fmu.count(first)
    enum = next((v.name for v in fmu.md.modelVariables if v.type == "Enumeration"), None)
    answers = run3(fmu, "inst", "-", "-", "enter", 0.25, "getf", time, 1, "exit", "step", 0.25, 1e-3,
                   "getf", time, 1, "setf", time, 1, 0.0, "getf", ("vr", first), n,
                   "getf", ("vr", first), n + 1, "getf", ("vr", first), max(n - 1, 0),
                   "geti64", ("vr", first), *(("getf", fmu.vr(first) + 1, 1) if n > 1 else ()))
    assert answers.statuses("fmi3GetFloat64") == ["OK", "OK", "OK", "Error", "Error"] + ["Error"] * (n > 1), \
        answers.lines
    assert answers.vectors[0] == [0.25] and answers.vectors[1] == [0.25 + 1e-3] and len(answers.vectors[2]) == n
    assert answers.statuses("fmi3SetFloat64") == ["Error"] and answers.statuses("fmi3GetInt64") == ["Error"]
    if n > 1:
        assert any(f"cover {n} values, nValues is {n + 1}" in line for line in answers.logs), answers.logs
    if enum:
        answers = run(fmu, "inst", "-", "-", "seti64", ("vr", enum), 2 ** 40, "getf", ("vr", enum), 1, *INIT3,
                      "geti64", ("vr", enum), "geti32", ("vr", enum), "seti64", ("vr", enum), 0)
        assert answers.statuses("fmi3SetInt64") == ["Error", "Error"] and "outside the Int32 range" in answers.logs[0]
        # a fixed parameter after initialization: the inner layer's line under the call's own name
        assert answers.logs[-1].startswith(f"Error logStatusError: fmi3SetInt64: parameter {enum} is fixed"), \
            answers.logs
        assert answers.statuses("fmi3GetFloat64") == ["Error"] and answers.statuses("fmi3GetInt64") == ["OK"]
        assert answers.statuses("fmi3GetInt32") == ["Error"]


@pytest.mark.parametrize("model", MODELS)
def test_fmi3_instantiation_this_fmu_cannot_serve_is_refused(native3, model):
    """Model exchange, scheduled execution, event mode and intermediate variables: NULL
    with a log line (the FMU declares none of them). A NULL resource path, a NULL logger
    and a NULL instance name are not needed to run: the instance steps."""
    fmu = native3[model]
    answers = run(fmu, "inst-me", "inst-se", "inst-events", "inst-required")
    assert [line.split()[1] for line in answers.lines if line.startswith("fmi3Instantiate")] == ["NULL"] * 4
    answers = run(fmu, "nores", "nolog", "inst", "-", "NULL", *INIT3, "step", 0.0, 1e-3, "term")
    assert [s for _, s in answers.calls] == ["instance"] + ["OK"] * 4 and not answers.logs


@pytest.mark.parametrize("model", MODELS)
def test_fmi3_serialized_states_round_trip_and_garbage_is_refused(native3, model):
    """A state serialised, deserialised into a new slot and restored gives the outputs of
    the step it was taken at; a buffer one byte short, the bytes less one, one byte of the
    block flipped (the checksum) and bytes of a pattern are refused with fmi3Error. With
    ASan (.ci/sanitize.sh) the exact-size buffers catch any access past them."""
    fmu = native3[model]
    out = ("get", fmu.first("output"))
    answers = run3(fmu, "inst", "-", "-", *INIT3, "step", 0.0, 1e-3, out, "save", "bytes", "short", "drop",
                   "step", 1e-3, 1e-3, out, "load-truncated", "load-flipped", "load-garbage", 3, "load-garbage", 5000,
                   "load", "restore", out, "step", 1e-3, 1e-3)
    assert answers.statuses("fmi3SerializeFMUState") == ["OK", "Error"], answers.lines
    assert answers.statuses("fmi3DeserializeFMUState") == ["Error"] * 4 + ["OK"], answers.lines
    assert answers.statuses("fmi3SetFMUState") == ["OK"] and answers.statuses("fmi3DoStep") == ["OK"] * 3
    first, _, restored = answers.vectors
    assert restored == first
    # the inner FMI 2.0 layer's lines under the FMI 3.0 names
    assert any(line.startswith("Error logStatusError: fmi3SerializeFMUState: ") for line in answers.logs), answers.logs
    assert any(line.startswith("Error logStatusError: fmi3DeserializeFMUState: ") for line in answers.logs)
    assert not any("FMUstate" in line for line in answers.logs), answers.logs


# ----------------------------------------------------- FMI 3.0: refused steps, bounds
@pytest.mark.parametrize("model", MODELS)
def test_fmi3_a_failed_instance_is_step_discarded(native3, model):
    """After a Discard (terminateSimulation true) the instance is StepDiscarded: doStep
    and SetFloat64 answer fmi3Error (FMI 3.0 allows neither there), the outputs are those
    of the last accepted state, the time reads the last accepted step's end, Terminate OK."""
    fmu = native3[model]
    first_in = fmu.first("input")
    if model == "Telescope":
        bad = ("setf", ("vr", "servo_bandwidth"), 1, 10.0, *INIT3, "step", 0.0, 1e9)
        again = ("setf", ("vr", "servo_bandwidth"), 1, 1.0)
    else:
        name = {"HexapodPlant": "leg_force", "Mechanism3TPlant": "slider_force[1]"}.get(model, first_in)
        bad = (*INIT3, ("set", name, math.nan), "step", 0.0, 1e-3)
        again = (("set", name, 1.0),)
    out = ("get", fmu.first("output"))
    answers = run3(fmu, "inst", "-", "-", *bad, out, "step", 0.0, 1e-3, *again, "getf", fmu.vr("time"), 1, "term")
    assert answers.statuses("fmi3DoStep") == ["Discard", "Error"], answers.lines
    assert "stepout 1 0 0" in answers.lines   # terminateSimulation, no early return, last time 0
    assert answers.statuses("fmi3SetFloat64")[-1] == "Error" and answers.statuses("fmi3Terminate") == ["OK"]
    assert answers.vectors[-1] == [0.0] and not any(math.isnan(x) for x in answers.vectors[0])
    assert any("not allowed in state StepDiscarded" in line for line in answers.logs), answers.logs


BAD_VALUES = [math.nan, math.inf, -math.inf, 1e300, -1e300, 5e-324]


@pytest.mark.parametrize("model", MODELS)
def test_fmi3_no_ok_with_a_non_finite_output_for_any_bad_value(native3, model):
    """Every Float64 parameter and input (an array: every element) set to NaN, +-inf,
    +-1e300 or the smallest subnormal, then initialization, two steps and every output
    read: no call answers OK with a non-finite output, every other answer follows a log
    line. It found: after an initialization refused for NaN outputs (SliderController's
    amplitude 1e300, LegSensor's resolution 5e-324, BaseSensor's axis_rate 1e300, ...),
    fmi3GetFloat64 read the NaN outputs back with fmi3OK (FMI 2.0's GetReal still does)."""
    fmu = native3[model]
    outputs = [v.name for v in fmu.md.modelVariables if v.causality == "output"]
    settable = [v.name for v in fmu.md.modelVariables if v.causality in ("parameter", "input") and v.type == "Float64"]
    refused = 0
    for name in settable:
        for value in BAD_VALUES:
            answers = run3(fmu, "inst", "-", "-", "setf", ("vr", name), fmu.count(name), *[value] * fmu.count(name),
                           *INIT3, "step", 0.0, 1e-3, "step", 1e-3, 1e-3, *(("get", o) for o in outputs))
            assert all(math.isfinite(x) for v in answers.vectors for x in v), (name, value, answers.lines)
            refused += any(status != "OK" for _, status in answers.calls[1:])
    assert refused > 0   # the values do reach the model


@pytest.mark.parametrize("model", MODELS)
def test_fmi3_integers_and_enumerations_outside_their_range_are_refused(native3, model):
    """Every Int32 and Enumeration parameter one below its min, one above its max and at
    the Int32 extremes (Set answers OK: a value is checked with the others at
    initialization): fmi3ExitInitializationMode answers fmi3Error naming the parameter."""
    fmu = native3[model]
    integers = [v for v in fmu.md.modelVariables if v.type in ("Int32", "Enumeration") and v.causality == "parameter"]
    for v in integers:
        call = "seti64" if v.type == "Enumeration" else "seti32"
        low, high = int(v.min), int(v.max)
        for value in sorted(x for x in {low - 1, high + 1, -2 ** 31, 2 ** 31 - 1} if not low <= x <= high):
            answers = run(fmu, "inst", "-", "-", call, ("vr", v.name), value, *INIT3)
            assert answers.statuses("fmi3ExitInitializationMode") == ["Error"], (v.name, value, answers.lines)
            assert f"parameter {v.name} = " in answers.logs[-1] and "outside its valid range" in answers.logs[-1]


@pytest.mark.parametrize("model", MODELS)
def test_fmi3_a_huge_step_is_served_or_refused(native3, model):
    """A step of 1e300 s: a model that integrates (the plants, the telescope's servo, the
    controller's integral) refuses it with Discard past its work bound or a non-finite
    output; a memoryless one (the sensors, the wind) serves it. Either way: no hang, the
    time is the last accepted step's end, every output finite."""
    fmu = native3[model]
    out = ("get", fmu.first("output"))
    answers = run3(fmu, "inst", "-", "-", *INIT3, "step", 0.0, 1e300, out, "getf", fmu.vr("time"), 1, timeout=30)
    [status] = answers.statuses("fmi3DoStep")
    assert status in ("OK", "Discard"), answers.lines
    assert answers.vectors[-1] == ([1e300] if status == "OK" else [0.0])
    assert all(math.isfinite(x) for x in answers.vectors[0]), answers.lines


@pytest.mark.parametrize("model, name, value, h", [
    ("HexapodPlant", "max_step", 1e-9, 10.0),
    ("Mechanism3TPlant", "max_step", 1e-9, 10.0),
    ("Telescope", "servo_bandwidth", 10.0, 1e8),
])
def test_fmi3_a_step_past_the_work_bound_is_refused_at_once(native3, model, name, value, h):
    fmu = native3[model]
    out = ("get", fmu.first("output"))
    answers = run3(fmu, "inst", "-", "-", "setf", ("vr", name), 1, value, *INIT3, out, "step", 0.0, h, out, timeout=30)
    assert answers.statuses("fmi3DoStep") == ["Discard"]
    assert any(line.startswith("Discard logStatusDiscard: WorkBoundError at t=0 s") and
               f"more than the {MAX_SUBSTEPS} a doStep may take" in line for line in answers.logs), answers.logs
    assert answers.vectors[0] == answers.vectors[1]


@pytest.mark.parametrize("model, name, element, value", [
    ("LegSensor", "leg_length", 0, math.nan),
    ("LegSensor", "leg_length", 5, math.inf),
    ("BaseSensor", "axis[1]", 0, 1e300),
    ("LegController", "reference_rate[1]", 0, 1e300),
])
def test_fmi3_no_ok_with_a_non_finite_output(native3, model, name, element, value):
    """As in FMI 2.0: Discard naming the input, the outputs of the last accepted state.
    An array input is set whole (nValues 6), one element non-finite."""
    fmu = native3[model]
    out = ("get", fmu.first("output"))
    values = [1.0] * fmu.count(name) if fmu.count(name) > 1 else [0.0]
    values[element] = value
    answers = run3(fmu, "inst", "-", "-", *INIT3, out, ("get", name), "step", 0.0, 1e-3, out)
    starts = answers.vectors[1]
    starts[element] = value
    answers = run3(fmu, "inst", "-", "-", *INIT3, out, "setf", ("vr", name), len(starts), *starts, "step", 0.0, 1e-3,
                   out)
    assert answers.statuses("fmi3DoStep") == ["Discard"], answers.lines
    line = answers.logs[-1]
    element_name = f"{name}[{element + 1}]" if fmu.count(name) > 1 else name
    assert "NonFiniteOutputError at t=0 s" in line and f"largest magnitude is {element_name} = " in line, line
    assert answers.vectors[0] == answers.vectors[1] and all(math.isfinite(x) for x in answers.vectors[1])


# ------------------------------------------------------------ FMI 3.0: memory
@pytest.mark.skipif(shutil.which("valgrind") is None, reason="valgrind is not installed")
@pytest.mark.parametrize("model", MODELS)
def test_fmi3_saved_states_hold_no_uninitialised_bytes(native3, model):
    """The FMI 3.0 state adds 8 bytes (the instance state) before the FMI 2.0 layer's
    serialised block: under memcheck, no byte of it is uninitialised."""
    if os.environ.get("MOVINGBASE_MISUSE_FMUS3"):
        pytest.skip("sanitizer builds: ASan and valgrind do not mix")
    answers = run(native3[model], "inst", "-", "-", *INIT3, "step", 0.0, 1e-3, "save", "bytes", "load", "restore",
                  "step", 1e-3, 1e-3, wrapper=("valgrind", "-q", "--error-exitcode=99"), timeout=120)
    assert answers.statuses("fmi3SerializeFMUState") == ["OK"] and answers.statuses("fmi3DoStep") == ["OK", "OK"]


@pytest.mark.parametrize("implementation, version", [("python", 2), ("native", 2), ("native", 3)])
def test_a_guid_that_is_a_prefix_an_extension_or_empty_makes_no_instance(implementation, version, tmp_path):
    """The GUID (FMI 3: instantiation token) must be the FMU's, whole: the pythonfmu shim's
    check compared a prefix; the fuzzer's wrong GUIDs were never prefixes."""
    from fmpy import extract
    from fmpy.fmi2 import FMU2Slave
    from fmpy.fmi3 import FMU3Slave

    import movingbase
    path = movingbase.fmus("leg_sensor", implementation=implementation, fmi_version=version)["leg_sensor"]
    md = read_model_description(str(path))
    folder = extract(str(path), str(tmp_path / "x"))
    slave_type = FMU3Slave if version == 3 else FMU2Slave
    for guid in (md.guid[:-1], md.guid[:1], "", md.guid + "0"):
        slave = slave_type(guid=guid, unzipDirectory=folder, modelIdentifier=md.coSimulation.modelIdentifier)
        with pytest.raises(Exception, match="(?i)instantiate"):
            slave.instantiate()
        slave.freeLibrary()
    right = slave_type(guid=md.guid, unzipDirectory=folder, modelIdentifier=md.coSimulation.modelIdentifier)
    right.instantiate()      # the whole GUID: an instance
    right.freeInstance()
    right.freeLibrary()


# ------------------------------------------------------------- the telescope's replay table
def test_telescope_replays_a_prepared_table_from_its_resources(extracted):
    """The native Telescope under a C host: a NULL string is refused with a line and changes
    nothing; replay_table "resource:<name>" is read from the folder the file:// URI
    fmuResourceLocation names; after a state restore the instance's table is evaluated (the
    state holds none): both steps to t = 2 s give the azimuth plant.telescope's replay_track
    gives, bit for bit. A table that is not there: fmi2Error with a line, no crash."""
    import numpy as np

    from fmu_src import replay_table
    from plant.telescope import model as tm
    from plant.telescope import replay
    fmu = extracted["Telescope"]
    p, deg, t = tm.TelescopeParams.tianma(), np.pi / 180, np.arange(0.0, 6.0, 0.05)
    axes = tm.slew(p, (0.0, 30 * deg), (20 * deg, 45 * deg), t - 1.0)
    resources = fmu.folder / "resources"
    resources.mkdir(exist_ok=True)
    log = resources / "misuse_replay.csv"
    np.savetxt(log, np.column_stack([t, np.degrees(axes.azimuth), np.degrees(axes.E)]), delimiter=",",
               header="time [s],azimuth [deg],elevation [deg]", comments="", fmt="%.17g")
    replay_table.write(log, resources / "misuse_replay.mbreplay", p)
    table = ("vr", "replay_table")
    answers = run(fmu, "inst", "-", "-", "setup", 0.0, "enter", "sets", table, "resource:misuse_replay.mbreplay",
                  "sets", table, "NULL", "gets", table, "seti", ("vr", "profile"), 3, "exit", "save",
                  "step", 0.0, 2.0, "getr", ("vr", "axis[1]"), "restore", "step", 0.0, 2.0, "getr", ("vr", "axis[1]"),
                  "drop", "free")
    answers.check_log_states_status()
    assert answers.statuses("fmi2SetString") == ["OK", "Error"]
    assert "fmi2SetString: the value of replay_table is NULL" in answers.logs[0], answers.logs
    assert f"string {fmu.vr('replay_table')} 'resource:misuse_replay.mbreplay'" in answers.lines
    assert answers.statuses("fmi2ExitInitializationMode") == ["OK"]
    truth = tm.replay_track(p, replay.load(log, p), [2.0]).azimuth[0]
    assert answers.vectors == [[truth], [truth]]
    answers = run(fmu, "inst", "-", "-", "setup", 0.0, "enter", "sets", table, "resource:none.mbreplay",
                  "seti", ("vr", "profile"), 3, "exit", "free")
    assert answers.statuses("fmi2ExitInitializationMode") == ["Error"]
    assert "replay table '" in answers.logs[-1] and "resources/none.mbreplay' cannot be opened" in answers.logs[-1]
