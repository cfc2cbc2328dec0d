"""Each scenario metric against data with a known answer: analytic RMS and peak, leg
lengths from an independent geometry (tests/plant/newton_euler.py tables, scipy rotations),
and the base effect against the Newton-Euler reference dynamics."""
import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from plant.errors import InvalidInputError
from plant.hexapod.model import StateInverseDynamics, StewartParams, inverse_kinematics
from plant.rotations import rpy_matrix
from plant.telescope import optics
from scenarios import spec
from scenarios.runs import metrics
from tests.plant import newton_euler as ne

HOME = np.array([0.0, 0.0, -2.6815, 0.0, 0.0, 0.0])
PAPER = StewartParams.paper()
TIANMA = optics.Cassegrain.tianma()


def rpy(R):
    """[roll, pitch, yaw] of R = Rz(yaw) Ry(pitch) Rx(roll) (scipy, intrinsic ZYX)."""
    return Rotation.from_matrix(R).as_euler("ZYX")[::-1]


def leg_lengths(pose):
    """|p + R a_i - B_i| from the spec's joint tables, independent of plant.hexapod.model."""
    table = ne.Table()
    R = Rotation.from_euler("ZYX", pose[5:2:-1]).as_matrix()
    return np.linalg.norm(pose[:3] + table.platform_joints @ R.T - table.base_joints, axis=1)


def test_tracking_rms_and_peak_of_a_constant_error():
    metric = metrics.Tracking("e", "p.x", "r.x")
    for k in range(7):
        reference = np.array([0.1 * k, -2.0])
        metric.update(k * 1e-3, {"p.x": reference + [3e-6, -4e-6], "r.x": reference})
    result = metric.result()
    assert result["rms"] == pytest.approx(math.sqrt((9 + 16) / 2), rel=1e-9)     # µm, over both elements
    assert result["peak"] == pytest.approx(4.0, rel=1e-9) and result["unit"] == "µm"


def test_tracking_rms_of_a_sine_is_its_amplitude_over_root_two():
    metric = metrics.Tracking("e", "p.x", "r.x")
    amplitude, n = 7e-6, 400                                # 400 samples over exactly 5 periods
    for k in range(n):
        error = amplitude * math.sin(2 * math.pi * 5 * k / n)
        metric.update(k, {"p.x": np.array([1.0 + error]), "r.x": np.array([1.0])})
    assert metric.result()["rms"] == pytest.approx(7 / math.sqrt(2), rel=1e-6)
    assert metric.result()["peak"] == pytest.approx(7.0, rel=1e-6)   # k = 20 hits the crest
    t, values = metric.series()
    assert len(t) == n and values[20] == pytest.approx(7.0, rel=1e-6)


def test_peak_is_the_largest_magnitude_in_kilonewton():
    metric = metrics.Peak("force", "c.f")
    for forces in ([1500.0, -300.0], [-2500.0, 10.0], [2000.0, 0.0]):
        metric.update(0.0, {"c.f": np.array(forces)})
    squares = [1500 ** 2, 300 ** 2, 2500 ** 2, 10 ** 2, 2000 ** 2, 0]
    assert metric.result()["peak"] == pytest.approx(2.5, rel=1e-12)
    assert metric.result()["rms"] == pytest.approx(math.sqrt(sum(squares) / 6) / 1e3, rel=1e-12)


def test_nothing_counted_is_not_a_number_never_zero():
    for metric in (metrics.Peak("f", "c.f"), metrics.PoseTracking("p", "a.p", "b.p")):
        assert all(math.isnan(v) for k, v in metric.result().items() if k != "unit")


def test_leg_tracking_against_independent_leg_lengths():
    reference = HOME + [0.012, -0.007, 0.02, math.radians(0.8), math.radians(-0.5), math.radians(1.2)]
    offsets = np.array([1.0, 2.0, 3.0, -1.0, -2.0, -3.0]) * 1e-6
    metric = metrics.LegTracking("legs", "p.l", "r.pose")
    metric.update(0.0, {"p.l": leg_lengths(reference) + offsets, "r.pose": reference})
    assert metric.result()["rms"] == pytest.approx(math.sqrt(28 / 6), abs=1e-6)   # µm
    assert metric.result()["peak"] == pytest.approx(3.0, abs=1e-6)


def test_pose_tracking_position_norm_and_rotation_angle():
    """A (3, 4, 0) mm offset and a 2 mrad turn about the platform's own x axis, built by
    scipy from a tilted reference: 5000 µm and 2000 µrad."""
    reference = HOME + [0.0, 0.0, 0.0, 0.01, -0.02, 0.03]
    R = Rotation.from_euler("ZYX", reference[5:2:-1]).as_matrix() @ Rotation.from_rotvec([2e-3, 0, 0]).as_matrix()
    pose = np.r_[reference[:3] + [3e-3, 4e-3, 0.0], rpy(R)]
    metric = metrics.PoseTracking("pose", "p.pose", "r.pose")
    metric.update(0.0, {"p.pose": pose, "r.pose": reference})
    result = metric.result()
    assert result["rms"] == pytest.approx(5000.0, rel=1e-9) and result["peak"] == pytest.approx(5000.0, rel=1e-9)
    assert result["rotation_rms"] == pytest.approx(2000.0, rel=1e-6)


MOTION = [   # (base pose, base rate, base acc): tilted, turning, accelerating
    ([0.0, 0.0, 0.0, math.radians(30.0), 0.0, math.radians(20.0)], [0.0, 0.0, 0.0, 0.2, 0.0, 0.15],
     [0.0, 0.0, 0.0, -0.1, 0.0, 0.05]),
    ([0.5, -1.0, 2.0, math.radians(60.0), 0.0, math.radians(-40.0)], [0.1, 0.0, -0.2, -0.05, 0.0, 0.3],
     [0.0, 0.3, 0.0, 0.2, 0.0, -0.1]),
]


def test_base_effect_against_newton_euler():
    """Total: full model minus no base at all; gravity: the base at rest in its pose
    minus no base; transport: the rest. Each peak over the samples and legs, kN."""
    metric = metrics.make(spec.Metric("base", "base_effect", {"base": "b", "reference": "r"}))
    pose, rate, acc = HOME + [0.01, 0.0, 0.02, 0.0, 0.01, 0.0], np.array([0.0, 0.02, 0, 0.1, 0, 0]), np.zeros(6)
    total, gravity, transport = [], [], []
    for base_pose, base_rate, base_acc in MOTION:
        values = {"b.base_pose": np.array(base_pose), "b.base_rate": np.array(base_rate),
                  "b.base_acc": np.array(base_acc), "r.reference_pose": pose, "r.reference_rate": rate,
                  "r.reference_acc": acc}
        metric.update(0.0, values)
        full = ne.inverse_dynamics(pose, rate, acc, base_pose, base_rate, base_acc)
        at_rest = ne.inverse_dynamics(pose, rate, acc, base_pose, np.zeros(6), np.zeros(6))
        none = ne.inverse_dynamics(pose, rate, acc)
        total.append(np.abs(full - none).max())
        gravity.append(np.abs(at_rest - none).max())
        transport.append(np.abs(full - at_rest).max())
    result = metric.result()
    scale = np.abs(ne.inverse_dynamics(pose, rate, acc)).max() * 1e-8 / 1e3   # Kane vs Newton-Euler agreement
    assert result["peak"] == pytest.approx(max(total) / 1e3, abs=scale)
    assert result["gravity_peak"] == pytest.approx(max(gravity) / 1e3, abs=scale)
    assert result["transport_peak"] == pytest.approx(max(transport) / 1e3, abs=scale)
    assert min(max(gravity), max(transport)) > 100.0   # N: both terms present in these samples


def test_base_effect_of_a_base_at_rest_upright_is_zero():
    metric = metrics.make(spec.Metric("base", "base_effect", {"base": "b", "reference": "r"}))
    zero = np.zeros(6)
    metric.update(0.0, {"b.base_pose": zero, "b.base_rate": zero, "b.base_acc": zero,
                        "r.reference_pose": HOME, "r.reference_rate": zero, "r.reference_acc": zero})
    assert max(abs(v) for k, v in metric.result().items() if k != "unit") < 1e-9


# ------------------------------------------------------------- block against per row
def _per_row_errors(kind, values):
    """One row's errors by the single-state calls, as each row was evaluated on arrival."""
    if kind == "tracking":
        return values["p.x"] - values["r.x"]
    if kind == "peak":
        return values["c.f"]
    if kind == "leg_tracking":
        return values["p.l"] - inverse_kinematics(PAPER, values["r.pose"])
    if kind == "pose_tracking":
        pose, ref = values["p.pose"], values["r.pose"]
        offset = pose[:3] - ref[:3]
        ref_R, pose_R = rpy_matrix(np.stack([ref[3:], pose[3:]]))
        r = ref_R.T @ pose_R
        axis = math.hypot(r[2, 1] - r[1, 2], r[0, 2] - r[2, 0], r[1, 0] - r[0, 1])
        return [math.sqrt(offset @ offset)], [math.atan2(axis, r[0, 0] + r[1, 1] + r[2, 2] - 1.0)]
    if kind == "pointing":
        motion = optics.subreflector_motion(values["p.pose"], values["r.pose"])
        beam = optics.pointing(motion[0], TIANMA)[0]
        return [math.hypot(*beam)], optics.path_error(motion[0], TIANMA)
    motion = [values[f"r.reference_{k}"] for k in ("pose", "rate", "acc")] + \
             [values[f"b.base_{k}"] for k in ("pose", "rate", "acc")]
    full, gravity, none = (StateInverseDynamics(PAPER, f)(*motion)[0][0].copy()
                           for f in ("full", "base_gravity", "no_base"))
    return full - none, np.abs(gravity - none).max(), np.abs(full - gravity).max()


class _RowByRow:
    """Sum of squares, peak and the stride-decimated series, one row at a time."""

    def __init__(self):
        self.count, self.sum_sq, self.peak, self.t, self.values, self.stride, self.countdown = 0, 0.0, 0.0, [], [], 1, 1

    def add(self, t, error):
        error = np.asarray(error, dtype=float)
        square = float(error @ error)
        self.count += error.size
        self.sum_sq += square
        self.peak = max(self.peak, float(error.max()), -float(error.min()))
        self.countdown -= 1
        if self.countdown == 0:
            self.countdown = self.stride
            self.t.append(t)
            self.values.append(math.sqrt(square / error.size))
            if len(self.t) >= metrics.MAX_POINTS:
                self.t, self.values, self.stride = self.t[::2], self.values[::2], 2 * self.stride

    def check(self, metric):
        t, values = metric.series()   # flushes the block
        assert (metric.count, metric.sum_sq, metric.peak) == (self.count, self.sum_sq, self.peak)
        assert t.tolist() == self.t and values.tolist() == (np.array(self.values) * metric.scale).tolist()


ROWS = {  # kind: scenario args, {variable: (centre, random spread)}
    "tracking": ({"measured": "p.x", "reference": "r.x"}, {"p.x": (0.0, 1e-5), "r.x": (0.0, 1e-5)}),
    "peak": ({"variable": "c.f"}, {"c.f": (0.0, 3e3)}),
    "leg_tracking": ({"measured": "p.l", "reference_pose": "r.pose"},
                     {"p.l": (inverse_kinematics(PAPER, HOME), 1e-4),
                      "r.pose": (HOME, 0.02)}),
    "pose_tracking": ({"measured": "p.pose", "reference": "r.pose"},
                      {"p.pose": (HOME, 0.02), "r.pose": (HOME, 0.02)}),
    "pointing": ({"measured": "p.pose", "reference": "r.pose"},
                 {"p.pose": (HOME, 0.02), "r.pose": (HOME, 0.02)}),
    "base_effect": ({"base": "b", "reference": "r"},
                    {"b.base_pose": (0.0, 0.5), "b.base_rate": (0.0, 0.2), "b.base_acc": (0.0, 0.2),
                     "r.reference_pose": (HOME, 0.02), "r.reference_rate": (0.0, 0.05), "r.reference_acc": (0.0, 0.1)}),
}


@pytest.mark.parametrize("kind", ROWS)
def test_block_evaluation_equals_row_by_row_evaluation(kind, monkeypatch):
    """Random rows over 2.5 blocks, the series thinned several times (MAX_POINTS 40), a
    series() read inside the second block (a partial flush) and the rows handed over in
    one buffer the caller overwrites (as the Recorder does): every sum, peak and series
    point equals the single-row calls' bit for bit."""
    monkeypatch.setattr(metrics, "MAX_POINTS", 40)
    args, spread = ROWS[kind]
    metric = metrics.make(spec.Metric("m", kind, args))
    two = kind in ("pose_tracking", "pointing")    # a second part: rotation, path-length error
    rows = [_RowByRow() for _ in range(2 if two else 1)]
    peaks = [0.0, 0.0]
    rng = np.random.default_rng(9)
    buffer = {name: np.empty(6 if kind != "tracking" else 2) for name in spread}
    n = int(2.5 * metrics.BLOCK) + 3
    for k in range(n):
        t = k * 1e-2
        for name, (centre, scale) in spread.items():
            buffer[name][:] = centre + scale * rng.standard_normal(buffer[name].size)
        metric.update(t, buffer)
        errors = _per_row_errors(kind, buffer)
        if kind == "base_effect":
            errors, *more = errors
            peaks = [max(p, float(m)) for p, m in zip(peaks, more)]
        for row, error in zip(rows, errors if two else [errors]):
            row.add(t, error)
        if k == metrics.BLOCK + metrics.BLOCK // 3:
            rows[0].check(metric)
    assert rows[0].stride >= 8   # thinned three times, across blocks
    rows[0].check(metric)
    if kind == "pose_tracking":
        rows[1].check(metric.rotation)
    if kind == "pointing":
        rows[1].check(metric.path)
    if kind == "base_effect":
        result = metric.result()
        assert [result["gravity_peak"], result["transport_peak"]] == [p * 1e-3 for p in peaks]


def test_a_bad_row_in_a_block_raises_with_the_rows_before_it_counted():
    metric = metrics.LegTracking("legs", "p.l", "r.pose")
    with pytest.raises(InvalidInputError, match="pose contains NaN"):
        for k in range(20):
            pose = HOME + [0.0, 0.0, 0.0, 0.0, 0.0, math.nan if k == 10 else 0.0]
            metric.update(k * 1e-2, {"p.l": np.full(6, 2.9), "r.pose": pose})
        metric.result()
    assert metric.count == 10 * 6


# ------------------------------------------------------------ rows that cannot carry a metric
def _sampled_sine(rows_per_period, periods=10, amplitude=5e-6):
    metric = metrics.Tracking("e", "p.x", "r.x")
    n = rows_per_period * periods
    for k in range(n):
        error = amplitude * abs(math.sin(math.pi * k / rows_per_period + 0.3))
        metric.update(k, {"p.x": np.array([error]), "r.x": np.array([0.0])})
    return metric


def test_a_metric_its_rows_resolve_is_not_undersampled():
    assert _sampled_sine(40).undersampled() is None
    assert metrics.Tracking("e", "p.x", "r.x").undersampled() is None     # nothing counted: NaN says it


def test_a_metric_from_too_few_or_aliased_rows_is_undersampled():
    few = metrics.Tracking("e", "p.x", "r.x")
    for k in range(3):
        few.update(k, {"p.x": np.array([1e-6]), "r.x": np.array([0.0])})
    assert few.undersampled() == "is counted from 3 recorded rows (at least 10 carry one)"
    # |sin| sampled twice a half period: every other row is the crest or the trough
    aliased = _sampled_sine(2)
    assert "its RMS over every other row is" in aliased.undersampled()
    # below 1 nm an error is numerical noise: no check
    assert _sampled_sine(2, amplitude=1e-12).undersampled() is None


@pytest.fixture(scope="module")
def slews():
    """telescope_slew [ci] recorded every step (the truth: the metrics over every step) and
    at coarser intervals, up to the stop time (one row counted)."""
    import warnings

    import movingbase
    runs = {}
    for interval in (0.001, 0.01, 0.05, 0.1, 8.0):
        scenario = movingbase.load_scenario("telescope_slew", ci=True)
        scenario.record_interval = interval
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            runs[interval] = movingbase.run(scenario, progress=False)
    return runs


def test_a_record_interval_too_coarse_for_a_metric_is_flagged_never_missed(slews):
    """Every run whose RMS is more than 10 % off the every-step RMS is flagged undersampled
    (no miss); the shipped interval (10 ms, 0.2 % off) is not."""
    truth = slews[0.001]
    assert truth.ok and slews[0.01].ok
    flagged = 0
    for interval, result in slews.items():
        for run in result:
            for name in ("leg error", "pose error"):
                true, got = truth[run.label].metrics[name]["rms"], run.metrics[name]["rms"]
                kinds = [f.kind for f in run.flags]
                if abs(got - true) > 0.10 * true:
                    assert "undersampled" in kinds, (interval, run.label, name, got, true)
                    flagged += 1
    assert flagged >= 7     # moving_base at 50 ms and 100 ms, every run at 8 s (1 row)
    coarse = slews[8.0]["none"].flags
    assert coarse[0].message.startswith("metric 'leg error' is counted from 1 recorded row")
    assert "record.interval 8000 ms is too coarse" in coarse[0].message


# ------------------------------------------------------------- pointing (the telescope's units)
def test_pointing_of_known_offsets_in_arcsec_microns_and_ruze_percent():
    """Half the rows 0.1 mm lateral, half 0.2 mm axial: the pointing RMS is the lateral
    row's angle over sqrt(2), its peak that angle; the path-length RMS mixes both rows'
    errors; the loss at each band is 1 - exp(-(4 pi (path RMS / 2) / lambda)^2), by hand."""
    metric = metrics.make(spec.Metric("pointing", "pointing", {"measured": "p.pose", "reference": "r.pose"}))
    lateral, axial = np.array([1e-4, 0, 0, 0, 0, 0]), np.array([0, 0, 2e-4, 0, 0, 0])
    for k in range(40):
        reference = HOME + [0.0, 0.01 * k, 0.0, 0.0, 0.0, 0.2]     # the reference moves; its error does not
        metric.update(k * 1e-2, {"p.pose": reference + (lateral if k % 2 else axial), "r.pose": reference})
    result = metric.result()
    geometry = TIANMA
    angle = 6.146864 * 0.1 * optics.ARCSEC          # the ray trace's 6.1469 arcsec per mm (test_telescope_optics)
    assert result["peak"] == pytest.approx(angle / optics.ARCSEC, rel=1e-6)
    assert result["rms"] == pytest.approx(angle / optics.ARCSEC / math.sqrt(2), rel=1e-6)
    paths = optics.path_error(np.array([[1e-4, 0, 0, 0, 0], [0, 0, 2e-4, 0, 0]]), geometry)
    assert result["path_rms"] == pytest.approx(1e6 * math.sqrt(np.mean(paths**2)), rel=1e-12)
    assert result["path_peak"] == pytest.approx(1e6 * paths.max(), rel=1e-12)
    for band, ghz in (("Ku", 15), ("K", 22), ("Ka", 31), ("Q", 43)):
        wavelength = 299_792_458.0 / (ghz * 1e9)
        by_hand = 100 * (1 - math.exp(-(4 * math.pi * result["path_rms"] * 1e-6 / 2 / wavelength) ** 2))
        assert result[f"efficiency_loss_{ghz}GHz"] == pytest.approx(by_hand, rel=1e-12)
    assert result["unit"] == "arcsec, µm, %"
    assert [metrics.key_unit(result, k) for k in ("rms", "path_peak", "efficiency_loss_43GHz")] == ["arcsec", "µm", "%"]
    assert result["efficiency_loss_43GHz"] > result["efficiency_loss_22GHz"] > 0


def test_pointing_of_a_run_that_counted_nothing_is_nan():
    result = metrics.make(spec.Metric("p", "pointing", {"measured": "p.pose", "reference": "r.pose"})).result()
    assert all(math.isnan(v) for k, v in result.items() if k != "unit")


def test_pointing_on_a_shipped_scene_equals_its_records():
    """paper_manoeuvre [ci], its moving-base run, with the reference pose recorded too: the
    metric equals plant/telescope/optics.py applied to the recorded rows from the metric's
    'from' on (the rows the metric was fed), and its arcsec are the pose error's lateral
    and tilt parts in the telescope's units."""
    import dataclasses

    import movingbase
    scenario = movingbase.load_scenario("paper_manoeuvre", ci=True)
    scenario = dataclasses.replace(scenario, record=scenario.record + ["base.reference_pose"],
                                   sweep=(scenario.sweep[0], ["moving_base"]))
    run = movingbase.run(scenario, progress=False)["moving_base"]
    metric = next(m for m in scenario.metrics if m.kind == "pointing")
    counted = run.time >= metric.start
    pose = np.column_stack([run[f"plant.pose[{i}]"] for i in range(1, 7)])[counted]
    reference = np.column_stack([run[f"base.reference_pose[{i}]"] for i in range(1, 7)])[counted]
    motion = optics.subreflector_motion(pose, reference)
    geometry = TIANMA
    angle = np.hypot(*optics.pointing(motion, geometry).T) / optics.ARCSEC
    path = optics.path_error(motion, geometry) * 1e6
    got = run.metrics["pointing"]
    assert got["rms"] == pytest.approx(math.sqrt(np.mean(angle**2)), rel=1e-9)
    assert got["peak"] == pytest.approx(angle.max(), rel=1e-12)
    assert got["path_rms"] == pytest.approx(math.sqrt(np.mean(path**2)), rel=1e-9)
    assert 0 < got["efficiency_loss_22GHz"] < got["efficiency_loss_43GHz"]
