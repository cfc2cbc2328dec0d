"""The FMUs under a careless or hostile C host (issue 18): tests/c_host/misuse.c runs one
script of FMI 2.0 calls in a fresh process per case and prints every answer; each is held
against what FMI 2.0 and the Reference FMUs answer. No case may crash (a signal), hang
(the timeout), or draw a sanitizer report (.ci/sanitize.sh runs this file on builds with
-fsanitize=address,undefined; MOVINGBASE_MISUSE_FMUS names its folder of extracted FMUs).

Every run also checks the log: each call that did not answer fmi2OK was explained by the
log line just before it, at the status the call returned."""
import math
import os
import pathlib
import re
import shutil
import subprocess

import pytest
from fmpy import read_model_description

from tests.c_host import MISUSE, compile_host, extract, pythonfmu_env

MODELS = ["BaseSensor", "HexapodPlant", "LegController", "LegSensor", "Mechanism3TPlant", "SliderController",
          "TelescopeBase", "Wind"]
STATUS = ("OK", "Warning", "Discard", "Error", "Fatal")
MAX_SUBSTEPS = 1_000_000   # MB_MAX_SUBSTEPS, fmu_src/native/model.h


class Fmu:
    """An extracted FMU: folder, model description, value references by name."""

    def __init__(self, folder, env=None):
        self.folder = pathlib.Path(folder)
        self.md = read_model_description(str(self.folder / "modelDescription.xml"))
        self.id = self.md.coSimulation.modelIdentifier
        self.vars = {v.name: v for v in self.md.modelVariables}
        self.env = env

    def vr(self, name):
        return self.vars[name].valueReference

    def first(self, causality):
        """The first Real variable of a causality, or None."""
        return next((v.name for v in self.md.modelVariables if v.causality == causality and v.type == "Real"), None)


class Answers:
    """What one run printed: calls with their statuses, log lines, values."""

    def __init__(self, stdout):
        self.lines = stdout.splitlines()
        self.calls = [tuple(line.split()) for line in self.lines if re.fullmatch(r"fmi2\w+ \w+", line)]
        self.logs = [line[4:] for line in self.lines if line.startswith("log ")]
        self.values = {int(line.split()[1]): float(line.split()[2]) for line in self.lines if line.startswith("value ")}

    def statuses(self, call):
        return [status for name, status in self.calls if name == call]

    def check_log_states_status(self):
        """Each call that did not answer OK follows a log line of its own status."""
        for k, line in enumerate(self.lines):
            match = re.fullmatch(r"(fmi2\w+) (Warning|Discard|Error|Fatal|NULL)", line)
            if match:
                expected = "Error" if match[2] == "NULL" else match[2]
                assert k > 0 and self.lines[k - 1].startswith(f"log {expected} "), (line, self.lines[max(0, k - 2):k])


def run(fmu, *script, timeout=60, wrapper=()):
    """Run misuse.c on ``fmu`` with ``script`` (words; a ("vr", name) pair is the value
    reference of name); asserts the process ended by itself, cleanly."""
    words = []
    for word in script:
        words.append(str(fmu.vr(word[1])) if isinstance(word, tuple) else repr(word) if isinstance(word, float)
                     else str(word))
    args = [*wrapper, str(compile_host(source=MISUSE)), str(fmu.folder), fmu.id, fmu.md.guid, *words]
    p = subprocess.run(args, capture_output=True, text=True, timeout=timeout, env=fmu.env)
    assert p.returncode == 0, (p.returncode, p.stdout[-2000:], p.stderr[-3000:])
    assert "runtime error" not in p.stderr and "Sanitizer" not in p.stderr, p.stderr[-3000:]
    answers = Answers(p.stdout)
    assert answers.lines and answers.lines[-1] == "done", p.stdout[-2000:]
    answers.check_log_states_status()
    return answers


INIT = ("setup", 0.0, "enter", "exit")


@pytest.fixture(scope="session")
def native(request, tmp_path_factory):
    """The native FMUs, extracted, by model identifier: built from the session's pythonfmu
    FMUs, or those of MOVINGBASE_MISUSE_FMUS (sanitizer builds of .ci/sanitize.sh)."""
    given = os.environ.get("MOVINGBASE_MISUSE_FMUS")
    if given:
        return {model: Fmu(pathlib.Path(given) / model) for model in MODELS}
    out = tmp_path_factory.mktemp("misuse")
    found = {}
    for fmu in request.getfixturevalue("native_fmus").values():
        model = fmu.stem
        found[model] = Fmu(extract(fmu, out / model))
    return found


@pytest.fixture(scope="session")
def python_fmus(fmus, tmp_path_factory):
    """The pythonfmu FMUs, extracted, with the environment a C host needs for them."""
    out = tmp_path_factory.mktemp("misuse-python")
    env = pythonfmu_env()
    return {path.stem: Fmu(extract(path, out / path.stem), env) for path in fmus.values()}


# ------------------------------------------------------------------ every native FMU
@pytest.mark.parametrize("model", MODELS)
def test_host_strings_with_conversions_are_printed_not_read(native, model):
    """A GUID, an instance name or a log category holding printf conversions ("%s", "%n")
    crashed the host: the FMU passed them inside the logger's format. Now the host's
    printf prints them as they are."""
    fmu = native[model]
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
    "a refused step leaves the time as it was": ((*INIT, "step", 0.0, 0.0, "step", 0.0, 1e-3),
                                                 ["OK"] * 3 + ["Error", "OK"]),
    "an FMU state restores the time": ((*INIT, "step", 0.0, 1e-3, "save", "step", 1e-3, 1e-3, "restore",
                                        "step", 1e-3, 1e-3, "step", 1e-3, 1e-3, "drop"),
                                       ["OK"] * 8 + ["Error", "OK"]),
}


# The call-sequence table on three FMUs in the default run (one shared layer answers it:
# a plant, a source, a sensor); on all eight in the slow run and in .ci/sanitize.sh.
SEQUENCE_MODELS = [m if m in ("HexapodPlant", "TelescopeBase", "LegSensor") else pytest.param(m, marks=pytest.mark.slow)
                   for m in MODELS]


@pytest.mark.parametrize("model", SEQUENCE_MODELS)
@pytest.mark.parametrize("case", SEQUENCES)
def test_call_sequence_answers_as_fmi2_specifies(native, model, case):
    fmu = native[model]
    script, expected = SEQUENCES[case]
    names = {"OUT": fmu.first("output"), "IN": fmu.first("input") or fmu.first("parameter")}
    script = [("vr", names[w]) if w in names else w for w in script]
    answers = run(fmu, "inst", "-", "-", *script)
    assert [status for _, status in answers.calls[1:]] == expected, answers.lines


@pytest.mark.parametrize("model", MODELS)
def test_a_failed_instance_refuses_steps_and_sets(native, model):
    """After a Discard (the step size 10 s on a plant past its work bound, or a NaN input
    elsewhere) doStep answers Discard again, SetReal Error, Terminate OK."""
    fmu = native[model]
    bad = {"HexapodPlant": ("setr", ("vr", "leg_force[1]"), math.nan),
           "Mechanism3TPlant": ("setr", ("vr", "slider_force[1]"), math.nan),
           "TelescopeBase": ()}.get(model, ("setr", ("vr", fmu.first("input") or ""), math.nan))
    if model == "TelescopeBase":
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
    ("TelescopeBase", "servo_bandwidth", 10.0, 1e8),  # axes of -2.27e28 rad
])
def test_a_step_past_the_work_bound_is_refused_at_once(native, model, name, value, h):
    fmu = native[model]
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
    ("TelescopeBase", "servo_bandwidth", 10.0, 1e8),
])
def test_pythonfmu_step_past_the_work_bound_is_refused_at_once(python_fmus, model, name, value, h):
    """The same bound in the pythonfmu FMUs (plant.integrators.MAX_SUBSTEPS): refused at
    once, not hours of substeps or an overflowed servo count."""
    test_a_step_past_the_work_bound_is_refused_at_once(python_fmus, model, name, value, h)


@pytest.mark.parametrize("substeps, status", [(MAX_SUBSTEPS + 1, "Discard"),
                                               pytest.param(MAX_SUBSTEPS, "OK", marks=pytest.mark.slow)])
def test_the_work_bound_is_exact(native, substeps, status):
    """A step of exactly MB_MAX_SUBSTEPS substeps runs (5-8 s here); one more is refused."""
    h = 0.05
    answers = run(native["Mechanism3TPlant"], "inst", "-", "-", "setr", ("vr", "max_step"), h / substeps, *INIT,
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
def test_no_ok_with_a_non_finite_output(native, model, name, value):
    """Each passed NaN/inf to an output with fmi2OK; now Discard, naming the input."""
    fmu = native[model]
    out = fmu.first("output")
    answers = run(fmu, "inst", "-", "-", *INIT, "getr", ("vr", out), "setr", ("vr", name), value, "step", 0.0, 1e-3,
                  "getr", ("vr", out))
    assert answers.statuses("fmi2DoStep") == ["Discard"], answers.lines
    line = answers.logs[-1]
    assert "NonFiniteOutputError at t=0 s" in line and f"largest magnitude is {name} = " in line, line
    values = [line for line in answers.lines if line.startswith("value ")]
    assert len(values) == 2 and values[0] == values[1] and "nan" not in values[1] and "inf" not in values[1]


def test_a_non_finite_output_at_initialization_is_an_error(native):
    """SliderController's amplitude has no declared max: 1e300 gave NaN forces with OK."""
    fmu = native["SliderController"]
    answers = run(fmu, "inst", "-", "-", "setr", ("vr", "amplitude"), 1e300, *INIT)
    assert answers.statuses("fmi2ExitInitializationMode") == ["Error"]
    assert "largest magnitude is amplitude = 1e+300" in answers.logs[-1], answers.logs


# --------------------------------------------------------- threads, instances, memory
@pytest.mark.parametrize("model", MODELS)
def test_eight_threads_give_identical_results(native, model):
    answers = run(native[model], "threads", 8, 20, 1e-3)
    results = [line.split()[2:] for line in answers.lines if line.startswith("thread ")]
    assert len(results) == 8 and all(r == results[0] for r in results) and results[0][0] == "OK", results


@pytest.mark.parametrize("model", MODELS)
def test_ten_thousand_instances(native, model):
    answers = run(native[model], "many", 10_000, timeout=120)
    assert "many 10000 of 10000" in answers.lines


@pytest.mark.skipif(shutil.which("valgrind") is None, reason="valgrind is not installed")
@pytest.mark.parametrize("model", MODELS)
def test_saved_states_hold_no_uninitialised_bytes(native, model):
    """Wind's state held stack padding (valgrind: a conditional jump on an uninitialised
    value at the checksum). Every FMU's state is serialised under memcheck."""
    if os.environ.get("MOVINGBASE_MISUSE_FMUS"):
        pytest.skip("sanitizer builds: ASan and valgrind do not mix")
    fmu = native[model]
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
    pythonfmu checks no GUID: a wrong one is accepted. A missing resource location crashed
    the wrapper (it finds no slave class): the shim refuses it."""
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


def test_pythonfmu_no_ok_with_a_non_finite_output(python_fmus):
    """GuardedSlave checks every output after each step, as the native layer does."""
    fmu = python_fmus["BaseSensor"]
    answers = run(fmu, "inst", "-", "-", *INIT, "setr", ("vr", "axis[1]"), 1e300, "step", 0.0, 1e-3, timeout=120)
    assert answers.statuses("fmi2DoStep") == ["Discard"], answers.lines
    assert "NonFiniteOutputError at t=0 s" in answers.logs[-1] and "axis[1] = 1e+300" in answers.logs[-1]
