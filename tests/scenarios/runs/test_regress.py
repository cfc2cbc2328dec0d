"""movingbase regress: planted changes caught with the first thing outside its tolerance
named, no false failure (1 and 2 jobs, FMI 2 and 3, a fresh FMU build, numpy and glibc
without AVX-512 and FMA), the floors measured, the tube against its definition by brute
force, exit codes, JUnit and the report."""
import json
import math
import os
import subprocess
import sys
from xml.etree import ElementTree

import numpy as np
import pytest

from scenarios.cosim.fmi import description
from scenarios.output.regress_report import CHARTS_PER_RUN, write_junit, write_report
from scenarios.runs import regress, runner
from scenarios.spec import units

# telescope_slew at its [ci] length (8 s: settling, then the slew's start), one run
SCENE = runner.resolve("telescope_slew").read_text().replace(
    'values = ["none", "fixed_base", "moving_base"]', 'values = ["fixed_base"]')


def _kp():
    path = runner.fmu_files(["leg_controller"])["leg_controller"]
    return float(next(v for v in description(path).modelVariables if v.name == "kp").start)


# what is changed, (text, its replacement), the first thing outside its tolerance
PLANTED = {
    "gain +1 %": ('fmu = "leg_controller"\n',
                  lambda: f'fmu = "leg_controller"\nparameters = {{ kp = {_kp() * 1.01!r} }}\n', "plant.pose"),
    "lever arm +2 %": ('lever_arm = "25 m"', 'lever_arm = "25.5 m"', "leg error rms"),
    "payload mass +1 %": ('fidelity = "full",', 'fidelity = "full", payload_mass_error = "21.297 kg",', "plant.pose"),
    "master": ('master = "jacobi"', 'master = "gauss-seidel"', "plant.pose"),
    "extrapolation": ('extrapolation = "linear"', 'extrapolation = "none"', "plant.pose"),
    "integrator": ('integrator = "rk4"', 'integrator = "euler"', "plant.pose"),
    "fidelity": ('fidelity = "full"', 'fidelity = "massless_legs"', "plant.pose"),
}


@pytest.fixture(scope="module")
def held(tmp_path_factory):
    """(the scene's file, its baseline folder), the baseline made once."""
    folder = tmp_path_factory.mktemp("held")
    path = folder / "slew.toml"
    path.write_text(SCENE)
    made = regress.regress([path], folder / "baseline", update=True, ci=True)
    assert made.exit_code == 0, made.summary()
    return path, folder / "baseline"


def _changed(tmp_path, old, new):
    """The scene with ``old`` replaced by ``new``, under the baseline's file name."""
    assert old in SCENE
    path = tmp_path / "slew.toml"
    path.write_text(SCENE.replace(old, new() if callable(new) else new, 1))
    return path


@pytest.mark.parametrize("what", PLANTED)
def test_a_planted_change_is_caught_and_the_first_finding_named(held, tmp_path, what):
    old, new, first = PLANTED[what]
    outcome = regress.regress([_changed(tmp_path, old, new)], held[1], ci=True)
    assert outcome.exit_code == 1, outcome.summary()
    scene, run, finding = outcome.findings()[0]
    assert (scene, run) == ("telescope_slew", "fixed_base")
    assert finding.name.startswith(first), finding.text
    assert math.isfinite(finding.first) and 0 < finding.first < 8.0
    assert outcome.scenes[0].notes, "what changed since the baseline is said"


def test_a_metric_change_is_told_in_the_domain_terms(held, tmp_path):
    old, new, _ = PLANTED["lever arm +2 %"]
    outcome = regress.regress([_changed(tmp_path, old, new)], held[1], ci=True)
    stored = json.loads((held[1] / "slew" / "baseline.json").read_text())["runs"]["fixed_base"]
    finding = next(f for _, _, f in outcome.findings() if f.name == "pose error peak")
    change = 100 * (finding.new - finding.old) / finding.old
    assert finding.old == stored["metrics"]["pose error"]["peak"]
    assert finding.text.startswith(f"pose error peak {change:+.3g} % ({finding.old:.6g} -> {finding.new:.6g} µm; ")
    assert 2.0 < change < 2.5          # the lever arm's 2 %, about proportionally in the tracking error
    assert "first outside its tube at t = 5.01 s" in finding.text   # the slew starts at 5 s
    assert "base.lever_arm 25.0 -> 25.5" in outcome.scenes[0].notes


def test_the_same_baseline_passes_with_two_jobs_under_fmi3_and_pythonfmu(held):
    """No false failure: the sweep's run on a worker process, the FMI 3.0 FMUs (the kit
    claims the same numbers bit for bit: docs/fmi3.md) and the pythonfmu FMUs (the same
    numbers, scenarios/files/telescope_slew.toml says)."""
    path, baseline = held
    for settings in ({}, {"jobs": 2}, {"fmi_version": 3}, {"implementation": "python"}):
        outcome = regress.regress([path], baseline, ci=True, **settings)
        assert outcome.exit_code == 0, (settings, outcome.summary())
        assert outcome.scenes[0].runs[0].compared > 40


def _metrics(text, tmp_path, name):
    path = tmp_path / f"{name}.toml"
    path.write_text(text)
    scenario, paths, descriptions, values = runner.prepare(path, True)
    return runner.run_prepared(scenario, paths, descriptions, values, None, False)[0].metrics


def test_tolerances_are_twice_the_step_halved_change_or_the_floors(held, tmp_path):
    """With Euler the integrator's own error is above the floors: the tolerance is twice
    the change of the file run with its max_step written as half; with RK4 at 1 ms that
    change (~1e-10 µm) is under them: the floors stand."""
    euler = SCENE.replace('integrator = "rk4"', 'integrator = "euler"')
    (tmp_path / "euler.toml").write_text(euler)
    regress.regress([tmp_path / "euler.toml"], tmp_path / "b", update=True, ci=True)
    tolerances = json.loads((tmp_path / "b" / "euler" / "baseline.json").read_text())["runs"]["fixed_base"]
    coarse = _metrics(euler, tmp_path, "coarse")
    fine = _metrics(euler.replace('max_step = "1 ms"', 'max_step = "0.5 ms"'), tmp_path, "fine")
    for metric, key in (("pose error", "peak"), ("pose error", "rms"), ("leg error", "peak"), ("leg force", "rms")):
        change = abs(coarse[metric][key] - fine[metric][key])
        assert change > regress.RELATIVE * abs(coarse[metric][key])                  # above the floor
        assert tolerances["tolerances"]["metrics"][metric][key] == pytest.approx(2 * change, rel=1e-9)
    assert tolerances["tolerances"]["metrics"]["pose error"]["peak"] == pytest.approx(0.807, abs=0.001)   # µm
    stored = json.loads((held[1] / "slew" / "baseline.json").read_text())
    run = stored["runs"]["fixed_base"]
    peak = run["metrics"]["pose error"]["peak"]
    assert run["tolerances"]["metrics"]["pose error"]["peak"] == pytest.approx(2 * regress.RELATIVE * peak)
    assert run["tolerances"]["metrics"]["pointing"]["peak"] == 2 * regress.FLOOR     # 0.47 arcsec: the floor
    legs = [run["tolerances"]["signals"][f"plant.leg_length[{k}]"] for k in range(1, 7)]
    assert len(set(legs)) == 1 and legs[0] == pytest.approx(2 * regress.SIGNAL_RELATIVE * 3.1221, rel=1e-3)
    assert run["tolerances"]["signals"]["plant.pose[4]"] == pytest.approx(2 * regress.SI_FLOOR)   # rad: the floor
    prov = stored["provenance"]
    assert prov["master"] == {"master": "jacobi", "extrapolation": "linear", "step": 0.001, "start_time": 0.0,
                              "stop_time": 8.0, "record_interval": 0.01, "ci": True}
    assert set(prov["fmus"]) == {"base", "plant", "controller"} and len(prov["fmus"]["plant"]["checksum"]) == 64
    assert prov["parameters"]["base"]["lever_arm"] == 25.0
    size = sum(p.stat().st_size for p in (held[1] / "slew").iterdir())
    assert size < 250_000     # small enough to commit


def test_floors_stand_above_a_one_ulp_change():
    """What RELATIVE and SIGNAL_RELATIVE are sized from: the lever arm moved by one ulp
    moves the metrics by less than a hundredth of their floor."""
    scenario, paths, descriptions, values = runner.prepare(runner.resolve("telescope_slew"), True)
    runs = runner.run_prepared(scenario, paths, descriptions, values, None, False)
    moved = {inst: dict(v) for inst, v in values.items()}
    moved["base"]["lever_arm"] = np.nextafter(values["base"]["lever_arm"], 100.0)
    nudged = runner.run_prepared(scenario, paths, descriptions, moved, None, False)
    for run, other in zip(runs, nudged):
        for metric, numbers in run.metrics.items():
            for key, value in numbers.items():
                if key != "unit":
                    change = abs(other.metrics[metric][key] - value)
                    assert change < max(regress.RELATIVE * abs(value), regress.FLOOR) / 100, (metric, key)
        variables = regress.read_variables(scenario)
        base, new = regress.signals_of(run, variables), regress.signals_of(other, variables)
        floors = regress.signal_tolerances(base, {}, regress.SIGNAL_RELATIVE, regress.SI_FLOOR)   # 2 x the floor
        for name, (_, v, _) in base.items():
            assert np.max(np.abs(new[name][1] - v)) < floors[name] / 2 / 100, name


def test_update_over_a_baseline_says_what_changed_then_replaces_it(held, tmp_path):
    baseline = tmp_path / "baseline"
    (baseline / "slew").mkdir(parents=True)
    for file in (held[1] / "slew").iterdir():
        (baseline / "slew" / file.name).write_bytes(file.read_bytes())
    old, new, _ = PLANTED["lever arm +2 %"]
    path = _changed(tmp_path, old, new)
    updated = regress.regress([path], baseline, update=True, ci=True)
    assert updated.exit_code == 0
    changed = updated.scenes[0].updated[0].findings
    assert changed[0].name == "leg error rms" and "+2.17 %" in changed[0].text
    assert "outside the old tolerances" in updated.summary() and "base.lever_arm 25.0 -> 25.5" in updated.summary()
    assert regress.regress([path], baseline, ci=True).exit_code == 0     # replaced: the new run is the baseline


def test_a_tolerance_override_with_units_replaces_one_and_is_stored(held, tmp_path):
    old, new, _ = PLANTED["lever arm +2 %"]
    path = _changed(tmp_path, old, new)
    strict = {f.name for _, _, f in regress.regress([path], held[1], ci=True).findings()}
    wide = regress.regress([path], held[1], ci=True, overrides={"leg error rms": "0.5 mm"})   # 500 µm
    assert {f.name for _, _, f in wide.findings()} == strict - {"leg error rms"}
    stored_in = tmp_path / "stored"
    regress.regress([held[0]], stored_in, update=True, ci=True, overrides={"pose error peak": "0.5 mm"})
    run = json.loads((stored_in / "slew" / "baseline.json").read_text())["runs"]["fixed_base"]
    assert run["tolerances"]["metrics"]["pose error"]["peak"] == pytest.approx(500.0)    # µm
    before = {f.name: f.read_bytes() for f in (stored_in / "slew").iterdir()}
    refused = regress.regress([held[0]], stored_in, update=True, ci=True, overrides={"pose eror peak": "1 um"})
    assert refused.exit_code == 2 and {f.name: f.read_bytes() for f in (stored_in / "slew").iterdir()} == before
    assert sorted(p.name for p in stored_in.iterdir()) == ["slew"]      # nothing half-written beside it
    for override, said in (({"pose eror peak": "1 um"}, "tolerance 'pose eror peak': no metric number"),
                           ({"pose error peak": "1 kN"}, "expected a quantity in µm")):
        refused = regress.regress([held[0]], held[1], ci=True, overrides=override)
        assert said in refused.scenes[0].error and refused.exit_code == 2


def test_the_tube_is_the_funnel_of_its_definition():
    """Each baseline point widened by the time tolerance (the largest and smallest value
    within it) and the value tolerance, against the definition by brute force."""
    rng = np.random.default_rng(7)
    t = np.cumsum(rng.uniform(0.5, 1.5, 200))
    y = np.sin(t / 5) + 0.1 * rng.standard_normal(200)
    low, high = regress.tube(t, y, 0.05, 2.0)
    for i in range(len(t)):
        near = y[np.abs(t - t[i]) <= 2.0]
        assert (low[i], high[i]) == (near.min() - 0.05, near.max() + 0.05)
    assert np.array_equal(regress.tube(t, y, 0.05)[1], y + 0.05)     # no time tolerance: a band
    new = y.copy()
    new[50] = high[50] + 0.3
    beyond = regress.outside(t, low, high, t, new)
    assert np.flatnonzero(beyond).tolist() == [50] and beyond[50] == pytest.approx(0.3)
    assert np.isinf(regress.outside(t, low, high, t[:100], y[:100])[100:]).all()   # ended early: outside


def test_a_metric_quantity_is_read_in_its_unit():
    assert units.in_unit("0.5 mm", "µm") == pytest.approx(500.0)
    assert units.in_unit("1 arcsec", "µrad") == pytest.approx(4.84813681109536)
    assert units.in_unit("2", "kN") == 2.0
    with pytest.raises(units.UnitError, match="another dimension 'N'; expected a quantity in µm"):
        units.in_unit("1 N", "µm")


def test_exit_codes_junit_and_report(held, tmp_path):
    path, baseline = held
    old, new, _ = PLANTED["lever arm +2 %"]
    changed = _changed(tmp_path, old, new)
    command = [sys.executable, "-m", "movingbase", "regress", "--ci", "--quiet", "--baseline", str(baseline)]
    assert subprocess.run(command + [str(path)], capture_output=True).returncode == 0
    done = subprocess.run(command + [str(changed), "--junit", str(tmp_path / "j.xml"), "--report",
                                     str(tmp_path / "rep")], capture_output=True, text=True)
    assert done.returncode == 1, done.stderr
    assert "fixed_base: leg error rms +2.17 %" in done.stdout
    suite = ElementTree.parse(tmp_path / "j.xml").getroot().find("testsuite")
    assert (suite.get("tests"), suite.get("failures"), suite.get("errors")) == ("1", "1", "0")
    assert suite.find("testcase/failure").get("message").startswith("leg error rms +2.17 %")
    report = (tmp_path / "rep" / "regress.md").read_text()
    charts = [line[line.index("(") + 1:-1] for line in report.splitlines() if line.startswith("![")]
    assert len(charts) == CHARTS_PER_RUN and all((tmp_path / "rep" / c).stat().st_size > 10_000 for c in charts)
    missing = subprocess.run(command + [str(changed), "--baseline", str(tmp_path / "none")], capture_output=True,
                             text=True)
    assert missing.returncode == 2 and "no baseline for slew" in missing.stdout
    assert subprocess.run(command + ["no_such_scene"], capture_output=True).returncode == 2


def test_junit_and_report_of_a_scene_that_could_not_run(tmp_path):
    outcome = regress.Regression([regress.SceneOutcome("x", "x.toml", error="no baseline for x")], "b")
    root = ElementTree.parse(write_junit(outcome, tmp_path / "j.xml")).getroot()
    assert root.find("testsuite").get("errors") == "1" and root.find("testsuite/testcase/error") is not None
    assert "| x | | could not run | no baseline for x |" in write_report(outcome, tmp_path).read_text()
    assert outcome.exit_code == 2


def test_a_baseline_of_the_other_length_is_refused(held):
    outcome = regress.regress([held[0]], held[1], ci=False)
    assert outcome.exit_code == 2 and "holds the [ci] runs; run with --ci" in outcome.scenes[0].error



@pytest.mark.slow
def test_an_fmu_rebuilt_fresh_passes_and_one_rebuilt_from_changed_c_is_caught(held, tmp_path, monkeypatch):
    """The controller's native FMU rebuilt from a copy of its C: as it is, the baseline
    holds (a fresh build is no change); with the PID's integral step in controller/c/pid.c
    halved (the supplier's next FMU), the scene is caught."""
    from fmu_src import native_build
    from fmu_src.python_build import ensure_built
    python_fmu = ensure_built(["leg_controller_fmu"])["leg_controller_fmu"]
    kernels, paths = native_build.KERNELS, runner.fmu_paths
    old = "double candidate = integral[i] + dt * error[i];"

    def rebuilt(folder, change):
        copy = tmp_path / folder / "controller_c"
        copy.mkdir(parents=True)
        for source in kernels[1].iterdir():
            if source.is_file():
                copy.joinpath(source.name).write_bytes(source.read_bytes())
        assert old in (copy / "pid.c").read_text()
        (copy / "pid.c").write_text((copy / "pid.c").read_text().replace(old, change))
        with monkeypatch.context() as building:    # the copy for this build only: build/ is never made from it
            building.setattr(native_build, "KERNELS", (kernels[0], copy))
            fmu = native_build.build_native(python_fmu, tmp_path / folder / "fmu")
        monkeypatch.setattr(runner, "fmu_paths", lambda scenario: {**paths(scenario), "controller": fmu})
        return regress.regress([held[0]], held[1], ci=True)

    fresh = rebuilt("fresh", old)
    assert fresh.exit_code == 0, fresh.summary()
    changed = rebuilt("changed", "double candidate = integral[i] + 0.5 * dt * error[i];")
    assert changed.exit_code == 1, changed.summary()
    first = changed.findings()[0][2]
    assert first.name.startswith("plant.pose") and 0 < first.first < 8.0, first.text
    assert any(note.startswith("FMU controller (leg_controller): rebuilt from other sources")
               for note in changed.scenes[0].notes), changed.scenes[0].notes


def test_bad_arguments_are_refused_before_anything_runs(tmp_path):
    with pytest.raises(regress.BaselineError, match="x: more than one scenario file of that name"):
        regress.regress([tmp_path / "a" / "x.toml", tmp_path / "b" / "x.toml"], tmp_path)
    with pytest.raises(regress.BaselineError, match="write 'NAME = QUANTITY'"):
        regress.parse_override("pose error peak 1 um")
    assert regress.parse_override(" pose error peak = 0.5 µm ") == ("pose error peak", "0.5 µm")
    done = subprocess.run([sys.executable, "-m", "movingbase", "regress", "telescope_slew", "--baseline",
                           str(tmp_path), "--time-tolerance", "5 kg"], capture_output=True, text=True)
    assert done.returncode == 2 and "regress error: '5 kg' is in kg; expected a quantity in s" in done.stderr


def test_the_baseline_holds_on_the_vector_units_of_a_smaller_processor(held):
    """Another x86-64 machine, as far as one machine can play it: numpy's AVX-512 loops
    and glibc's FMA and AVX2 function variants switched off for the comparing process
    (NPY_DISABLE_CPU_FEATURES, GLIBC_TUNABLES), against the baseline made with them."""
    from numpy._core._multiarray_umath import __cpu_features__
    off = [f for f in ("AVX512_SPR", "AVX512_ICL", "X86_V4") if __cpu_features__.get(f)]
    if not off:
        pytest.skip("this processor has no AVX-512 for numpy to leave aside")
    env = {**os.environ, "NPY_DISABLE_CPU_FEATURES": " ".join(off),
           "GLIBC_TUNABLES": "glibc.cpu.hwcaps=-AVX512F,-AVX2,-FMA,-AVX512F_Usable,-AVX2_Usable,-FMA_Usable"}
    done = subprocess.run([sys.executable, "-m", "movingbase", "regress", str(held[0]), "--baseline", str(held[1]),
                           "--ci", "--quiet"], capture_output=True, text=True, env=env)
    assert done.returncode == 0, done.stdout + done.stderr
    assert "telescope_slew: pass (1 run" in done.stdout


def test_the_signals_named_are_those_stored(held, tmp_path):
    made = regress.regress([held[0]], tmp_path, update=True, ci=True, signals=["plant.pose"])
    assert made.exit_code == 0, made.summary()
    run = json.loads((tmp_path / "slew" / "baseline.json").read_text())["runs"]["fixed_base"]
    assert run["signals"] == [f"plant.pose[{k}]" for k in range(1, 7)]
    assert regress.regress([held[0]], tmp_path, ci=True).exit_code == 0
    old, new, _ = PLANTED["master"]
    assert regress.regress([_changed(tmp_path, old, new)], tmp_path, ci=True).findings()[0][2].name.startswith(
        "plant.pose")
    unrecorded = regress.regress([held[0]], tmp_path / "b", update=True, ci=True, signals=["plant.leg_rate"])
    assert unrecorded.exit_code == 2 and "signal 'plant.leg_rate' is not recorded; recorded: " in \
        unrecorded.scenes[0].error
    with pytest.raises(regress.BaselineError, match="signals are chosen when a baseline is stored"):
        regress.regress([held[0]], tmp_path, ci=True, signals=["plant.pose"])
