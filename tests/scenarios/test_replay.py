"""The telescope's replay profile in the loop: a log sampled at 20 Hz from the kit's own
analytic profiles, replayed by the pythonfmu Telescope, against the run of the profile
itself (the truth), the native FMI 2.0 and 3.0 Telescopes against the pythonfmu one, and
the refusals a scenario or an FMU gets."""
import ctypes
import io
import zipfile
from datetime import datetime, timezone

import numpy as np
import pytest

import movingbase
from fmu_src import catalogue, native_build, replay_table
from plant.errors import InvalidInputError
from plant.telescope import model as tm
from plant.telescope import replay
from scenarios import spec, ssp
from scenarios.cosim.fmi import FmuError
from scenarios.runs import single
from tests.fmu_helpers import open_fmu, opened
from tests.scenario_helpers import SLEW, edited
from tests.ssp_helpers import RECORD, START_DELAY, columns, configure, run_columns

P = tm.TelescopeParams.tianma()
DEG = np.pi / 180
UTC = 1.7e9     # the FMU's default utc_start
BASE = '[fmus.base]\nfmu = "telescope"\nparameters = { profile = "slew", start_azimuth = "0 deg", ' \
       'start_elevation = "30 deg", target_azimuth = "20 deg", target_elevation = "45 deg", lever_arm = "25 m", ' \
       'start_delay = "5 s" }'
ONE_RUN = ('[sweep]\nparameter = "controller.feedforward"\nvalues = ["none", "fixed_base", "moving_base"]',
           '[sweep]\nparameter = "controller.feedforward"\nvalues = ["moving_base"]')
REPLAY = '[fmus.base]\nfmu = "telescope"\nimplementation = "python"\nparameters = { profile = "replay", ' \
         'replay_table = "log.csv", lever_arm = "25 m" }'


def write_log(path, t, axes):
    np.savetxt(path, np.column_stack([t, np.degrees(axes.azimuth), np.degrees(axes.E)]), delimiter=",",
               header="time [s],azimuth [deg],elevation [deg]", comments="", fmt="%.17g")


def runs(tmp_path, truth_base):
    """(truth, replay) results of the slew scene's CI version (8 s) with the base as given
    and replaying tmp_path/log.csv."""
    truth = tmp_path / "truth.toml"
    truth.write_text(edited(SLEW, ONE_RUN, (BASE, truth_base)))
    replay = tmp_path / "replay.toml"
    replay.write_text(edited(SLEW, ONE_RUN, (BASE, REPLAY)))
    return [movingbase.run(f, ci=True, progress=False)[0] for f in (truth, replay)]


def test_replayed_slew_gives_the_slews_loads(tmp_path):
    """The slew's log replayed: the axes within the docs' smoothing bound (two corners of
    one pulse, J = 0.25 deg/s^2, h = 0.25 s: 0.322 J h^2, 0.427 J h); the legs' forces and
    the base's effect on them within 0.1 % (they follow the base's acceleration averaged
    over the run). The tracking error is not among them: the analytic slew's corners have
    infinite jerk, which kicks the hexapod and sets its peak error; the replay's
    acceleration is continuous (a 20 Hz log cannot carry a sharper corner), so its error
    is smaller, by the size of that kick (measured ~50x here)."""
    t = np.arange(0.0, 70.0, 0.05)
    write_log(tmp_path / "log.csv", t, tm.slew(P, (0.0, 30 * DEG), (20 * DEG, 45 * DEG), t - 5.0))
    truth, replay = runs(tmp_path, BASE)
    assert truth.ok and replay.ok
    J, H = 0.25 * DEG, 0.25
    for name, bound in (("base.axis[1]", 0.322 * J * H ** 2), ("base.axis[2]", 0.322 * J * H ** 2),
                        ("base.axis_rate[1]", 0.427 * J * H), ("base.axis_rate[2]", 0.427 * J * H)):
        error = np.abs(replay[name] - truth[name]).max()
        assert 0.3 * bound < error <= bound, (name, error / bound)
    m, n = truth.metrics, replay.metrics
    for metric, field in (("leg force", "rms"), ("leg force", "peak"), ("base effect", "rms")):
        assert n[metric][field] == pytest.approx(m[metric][field], rel=1e-3), (metric, field)
    assert n["pose error"]["peak"] < 0.1 * m["pose error"]["peak"]


def test_replayed_sidereal_track_is_the_sidereal_profile(tmp_path):
    """A smooth motion is replayed to h^4 |x''''| (below 1e-9 rad): every metric of the
    loop agrees with the sidereal profile's run (a source at dec 50 deg) to what that leaves."""
    ra, dec = 1.0, 50 * DEG
    t = np.arange(0.0, 20.0, 0.05)
    axes = tm.sidereal_track(P, ra, dec, datetime.fromtimestamp(UTC, tz=timezone.utc), t)
    write_log(tmp_path / "log.csv", t, axes)
    sidereal = BASE.replace('profile = "slew", start_azimuth = "0 deg", start_elevation = "30 deg", target_azimuth = '
                            '"20 deg", target_elevation = "45 deg", lever_arm = "25 m", start_delay = "5 s"',
                            f'profile = "sidereal", right_ascension = {ra}, declination = {dec}, lever_arm = "25 m"')
    truth, replay = runs(tmp_path, sidereal)
    assert truth.ok and replay.ok
    assert np.abs(replay["base.axis[2]"] - truth["base.axis[2]"])[1:-1].max() < 1e-9
    m, n = truth.metrics, replay.metrics
    # the forces follow the base's acceleration: to 1e-9 (measured 5e-12); the pose error of
    # a track is nm (the spline's natural end conditions at t = 0 leave 0.4 nm of it)
    for field in ("rms", "peak"):
        assert n["leg force"][field] == pytest.approx(m["leg force"][field], rel=1e-9)
        assert abs(n["pose error"][field] - m["pose error"][field]) < 1e-9
        assert abs(n["pointing"][field] - m["pointing"][field]) < 1e-11
    assert m["pose error"]["peak"] < 2e-8


def test_a_bad_log_is_refused_before_the_run(tmp_path):
    t = np.arange(0.0, 20.0, 0.05)
    axes = tm.slew(P, (0.0, 30 * DEG), (20 * DEG, 45 * DEG), t - 5.0)
    write_log(tmp_path / "log.csv", np.r_[t[:100], t[100:] + 2.0], axes)
    scene = tmp_path / "replay.toml"
    scene.write_text(edited(SLEW, ONE_RUN, (BASE, REPLAY)))
    with pytest.raises(spec.ScenarioError, match=r"replay\.toml: fmus\.base\.parameters: profile 'replay' with "
                                                 r"replay_table = 'log.csv'.*rows 100-101: a gap of 2\.05 s"):
        movingbase.run(scene, ci=True, progress=False)


@pytest.mark.parametrize("implementation", ["python", "native"])
def test_ssp_export_carries_the_table(fmus, native_fmus, tmp_path, implementation):
    """The exported SSP holds the prepared table inside the telescope's FMU (the parameter
    reads "resource:log.mbreplay"), so fmpy's SSP master replays it with the original file
    gone, with the pythonfmu or the native Telescope, and its run equals ours (as
    tests/scenarios/test_ssp.py compares the analytic slew)."""
    script = catalogue.BY_KEY["telescope"].script
    scenario, paths, descriptions, params = configure(
        {**fmus, script: (fmus if implementation == "python" else native_fmus)[script]})
    t = np.arange(0.0, 5.0, 0.05)
    log = tmp_path / "log.csv"
    write_log(log, t, tm.slew(P, (0.0, 30 * DEG), (20 * DEG, 45 * DEG), t - START_DELAY))
    params["base"].update(profile=tm.PROFILE_KINDS.index("replay"), replay_table=str(log), start_delay=0.0)
    ours = run_columns(single.run(scenario, paths, params, tmp_path, "ours"))   # the master prepares the log
    path = ssp.export_ssp(scenario, paths, params, tmp_path / "replay.ssp")
    log.unlink()
    with zipfile.ZipFile(path) as z:
        ssd = z.read("SystemStructure.ssd").decode()
        with zipfile.ZipFile(io.BytesIO(z.read("resources/base_Telescope.fmu"))) as fmu:
            assert "resources/log.mbreplay" in fmu.namelist()
    assert 'value="resource:log.mbreplay"' in ssd
    theirs = ssp.simulate_exported(path, scenario, initial_exchange=True)
    for name in columns(scenario, descriptions, RECORD):
        np.testing.assert_allclose(theirs[name], ours[name][1:], rtol=1e-9, atol=1e-12, err_msg=name)
    assert np.ptp(ours["base.base_pose[2]"]) > 1e-4      # the replayed slew moves the base


def test_native_scene_replays_as_the_pythonfmu_one(tmp_path):
    """The same replay scene with the native Telescope (the kit prepares the log for it) and
    the pythonfmu one: the base's motion and a leg's force equal bit for bit (one C spline, the same
    coefficients, the same communication points)."""
    t = np.arange(0.0, 20.0, 0.05)
    write_log(tmp_path / "log.csv", t, tm.slew(P, (0.0, 30 * DEG), (20 * DEG, 45 * DEG), t - 5.0))
    results = []
    for label, base in (("python", REPLAY), ("native", REPLAY.replace('implementation = "python"', 'implementation = '
                                                                       '"native"'))):
        scene = tmp_path / f"{label}.toml"
        scene.write_text(edited(SLEW, ONE_RUN, (BASE, base)))
        results.append(movingbase.run(scene, ci=True, progress=False)[0])
    python, native = results
    assert python.ok and native.ok
    for name in ("base.base_acc[1]", "base.base_acc[2]", "base.axis[1]", "base.axis_rate[2]",
                 "controller.leg_force[1]"):
        np.testing.assert_array_equal(native[name], python[name], err_msg=name)
    assert np.ptp(native["base.axis[1]"]) > 0.01   # rad: the replayed slew moved it (1 deg in the CI run's 3 s)


SHORT = np.arange(0.0, 6.0, 0.05)


@pytest.fixture(scope="module")
def table(tmp_path_factory):
    """(log, its prepared table) of a short slew."""
    folder = tmp_path_factory.mktemp("replay")
    write_log(folder / "log.csv", SHORT, tm.slew(P, (0.0, 30 * DEG), (20 * DEG, 45 * DEG), SHORT - 1.0))
    return folder / "log.csv", replay_table.write(folder / "log.csv", folder / "log.mbreplay", P)


def _run(path, table, names, steps=400, h=0.01):
    """The named outputs over ``steps`` steps of ``h`` with profile replay of ``table``."""
    from scenarios.cosim.fmi import Instance
    inst = Instance(path, "a")
    inst.initialize(0.0, {"profile": tm.PROFILE_KINDS.index("replay"), "replay_table": str(table)})
    rows = []
    for k in range(steps):
        inst.do_step(k * h, h)
        rows.append([inst.get_real(n) for n in names])
    inst.terminate()
    return np.array(rows)


@pytest.fixture(scope="module")
def fmi3(native_fmus, tmp_path_factory):
    """The native FMI 3.0 Telescope."""
    return native_build.build_native3(native_fmus[catalogue.BY_KEY["telescope"].script], tmp_path_factory.mktemp("n3"))


def test_native_fmi2_and_fmi3_replay_as_the_pythonfmu_fmu_bit_for_bit(fmus, native_fmus, fmi3, table):
    """The pythonfmu Telescope on the log (smoothed by scipy in the FMU), and on the
    prepared table; the native FMI 2.0 and FMI 3.0 ones on the prepared table: the same
    numbers bit for bit, and the motion is the slew's (axis within the docs' smoothing
    bound 0.322 J h^2 of the analytic slew)."""
    script = catalogue.BY_KEY["telescope"].script
    log, prepared = table
    names = ["axis[1]", "axis[2]", "axis_rate[1]", "axis_acc[2]", "base_acc[4]", "reference_pose[3]"]
    python = _run(fmus[script], log, names)
    for path, source in ((fmus[script], prepared), (native_fmus[script], prepared), (fmi3, prepared)):
        np.testing.assert_array_equal(_run(path, source, names), python, err_msg=str(path))
    times = 0.01 * np.arange(1, 401)
    truth = tm.slew(P, (0.0, 30 * DEG), (20 * DEG, 45 * DEG), times - 1.0)
    error = np.abs(python[:, 0] - truth.azimuth).max()
    assert 1e-6 < error <= 0.322 * 0.25 * DEG * 0.25 ** 2


def _damaged(path, what):
    """A copy of the prepared table at ``path`` with one defect."""
    data = bytearray(path.read_bytes())
    n = replay.PREPARED_HEADER.itemsize
    knots = np.frombuffer(bytes(data[n:n + 8 * 4]), dtype="<f8").copy()
    if what == "truncated":
        return bytes(data[:-8])
    if what == "magic":
        return b"XBREPLAY" + bytes(data[8:])
    if what == "nan":
        knots[2] = np.nan
    elif what == "decreasing":
        knots[2] = knots[0]
    data[n:n + 32] = knots.tobytes()
    return bytes(data)


@pytest.mark.parametrize("what, message", [
    ("truncated", r"version 1 \(read: 1\), 120 knots \(2\.\.\d*\) in 8592 bytes \(8600 expected\): truncated"),
    ("magic", "not a prepared replay table"),
    ("nan", r"knot 2 \(0-based\) is not finite or does not follow"),
    ("decreasing", r"knot 2 \(0-based\) is not finite or does not follow"),
    ("missing", "cannot be opened"),
    ("empty", "replay_table is empty"),
    ("smoothing", "was smoothed over 0.25 s, replay_smoothing is 0.5 s"),
])
def test_native_telescope_refuses_a_bad_table_with_a_line(native_fmus, table, tmp_path, what, message):
    """Each defect of a prepared table: exitInitializationMode answers Error with a log line
    naming it (no crash); the Python reader says the same of the same bytes."""
    import re
    path = tmp_path / "bad.mbreplay"
    if what not in ("missing", "empty", "smoothing"):
        path.write_bytes(_damaged(table[1], what))
        with pytest.raises(InvalidInputError, match=message):
            replay.read_prepared(path)
    values = {"profile": tm.PROFILE_KINDS.index("replay"),
              "replay_table": "" if what == "empty" else str(table[1] if what == "smoothing" else path)}
    if what == "smoothing":
        values["replay_smoothing"] = 0.5
    inst, status = opened(native_fmus[catalogue.BY_KEY["telescope"].script], **values)
    assert status == 3   # fmi2Error
    assert re.search(message, "\n".join(inst.log)), inst.log


def test_native_telescope_refuses_a_null_string(native_fmus):
    """fmi2SetString with a NULL value: fmi2Error and a line; the String keeps its value."""
    from scenarios.cosim.fmi import Instance
    from tests.fmu_helpers import OPENED
    inst = Instance(native_fmus[catalogue.BY_KEY["telescope"].script], "a")
    OPENED.append(inst)
    inst.call("setupExperiment", startTime=0.0)
    inst.call("enterInitializationMode")
    inst.set("replay_table", "kept.mbreplay")
    vr = (ctypes.c_uint * 1)(inst.vr("replay_table"))
    assert inst.raw("fmi2SetString")(inst.fmu.component, vr, 1, (ctypes.c_char_p * 1)(None)) == 3   # fmi2Error
    assert "fmi2SetString: the value of replay_table is NULL" in "\n".join(inst.log)
    value = (ctypes.c_char_p * 1)()
    assert inst.raw("fmi2GetString")(inst.fmu.component, vr, 1, value) == 0
    assert value[0] == b"kept.mbreplay"


def test_native_fmi3_telescope_refuses_a_missing_table_with_a_line(fmi3, tmp_path):
    """The FMI 3.0 build: fmi3ExitInitializationMode answers fmi3Error with the same line."""
    with pytest.raises(FmuError, match=r"failed in exitInitializationMode(.|\n)*replay table '.*none\.mbreplay' "
                                       r"cannot be opened"):
        open_fmu(fmi3, profile=tm.PROFILE_KINDS.index("replay"), replay_table=str(tmp_path / "none.mbreplay"))
