"""The telescope's replay profile in the loop: a log sampled at 20 Hz from the kit's own
analytic profiles, replayed by the pythonfmu Telescope, against the run of the profile
itself (the truth), and the refusals a scenario gets before its run."""
import io
import zipfile
from datetime import datetime, timezone

import numpy as np
import pytest

import movingbase
from fmu_src import catalogue
from plant.telescope import model as tm
from scenarios import spec, ssp
from scenarios.cosim.fmi import FmuError
from scenarios.runs import single
from tests.fmu_helpers import free_all, open_fmu
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
    native = REPLAY.replace('implementation = "python"\n', "").replace('replay_table = "log.csv", ', "")
    scene.write_text(edited(SLEW, ONE_RUN, (BASE, native)))
    with pytest.raises(spec.ScenarioError, match="set implementation = \"python\""):
        movingbase.run(scene, ci=True, progress=False)


def test_ssp_export_carries_the_table(fmus, tmp_path):
    """The exported SSP holds the table inside the telescope's FMU (the parameter reads
    "resource:log.csv"), so fmpy's SSP master replays it with the original file gone, and
    its run equals ours (as tests/scenarios/test_ssp.py compares the analytic slew)."""
    scenario, paths, descriptions, params = configure(fmus)
    t = np.arange(0.0, 5.0, 0.05)
    log = tmp_path / "log.csv"
    write_log(log, t, tm.slew(P, (0.0, 30 * DEG), (20 * DEG, 45 * DEG), t - START_DELAY))
    params["base"].update(profile=tm.PROFILE_KINDS.index("replay"), replay_table=str(log), start_delay=0.0)
    ours = run_columns(single.run(scenario, paths, params, tmp_path, "ours"))
    path = ssp.export_ssp(scenario, paths, params, tmp_path / "replay.ssp")
    log.unlink()
    with zipfile.ZipFile(path) as z:
        ssd = z.read("SystemStructure.ssd").decode()
        with zipfile.ZipFile(io.BytesIO(z.read("resources/base_Telescope.fmu"))) as fmu:
            assert "resources/log.csv" in fmu.namelist()
    assert 'value="resource:log.csv"' in ssd
    theirs = ssp.simulate_exported(path, scenario, initial_exchange=True)
    for name in columns(scenario, descriptions, RECORD):
        np.testing.assert_allclose(theirs[name], ours[name][1:], rtol=1e-9, atol=1e-12, err_msg=name)
    assert np.ptp(ours["base.base_pose[2]"]) > 1e-4      # the replayed slew moves the base


def test_the_native_telescope_refuses_replay_saying_why(native_fmus):
    """The native FMUs have no String variable for the table: profile replay fails at
    initialization with a line saying what to use instead (not a crash, not a silent slew)."""
    with pytest.raises(FmuError, match="failed in exitInitializationMode") as error:
        open_fmu(native_fmus[catalogue.BY_KEY["telescope"].script], profile=tm.PROFILE_KINDS.index("replay"))
    assert "profile replay reads its table (replay_table, a String) in Python: use the pythonfmu Telescope" \
        in str(error.value)
    free_all()
