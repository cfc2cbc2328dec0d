"""Metrics computed while a run streams: running RMS and peak, plus a decimated time
series for the charts (at most MAX_POINTS points, so memory stays flat on long runs).
A metric copies the rows it is fed into a block of BLOCK rows and evaluates a full block
(and what is left at result()/series()) with batched plant calls: the paper manoeuvre's
four metrics took 60-130 µs per recorded row evaluated one row at a time, 10-20 µs in
blocks. The sums, the peak and the series still run row by row in time order, so the
numbers equal one-row-at-a-time evaluation.

Kinds (scenario key ``kind``):
* ``leg_tracking``: measured leg lengths [m] against the legs of the reference pose
  (inverse kinematics of the hexapod), in µm.
* ``pose_tracking``: platform pose against the reference pose: position error norm [µm]
  and rotation error angle [µrad].
* ``tracking``: any measured vector of lengths [m] against a reference vector of the same
  size [µm].
* ``peak``: largest |value| of a force variable [N], in kN.
* ``base_effect``: along the reference motion and the base motion, the peak leg-force
  change the base motion causes, split into gravity turning with the base and the
  transport/centripetal/Coriolis terms (inverse dynamics at three fidelities) [kN].
* ``pointing``: what the platform pose's error against the reference pose costs the
  telescope (plant/telescope/optics.py, Tianma's Cassegrain): the beam's pointing error
  [arcsec], the path-length error over the aperture once piston and tilt are removed
  [µm] and the aperture efficiency it loses by Ruze's law at 15, 22, 31 and 43 GHz (at
  the run's RMS path-length error, the mean loss to first order) [%].
"""
import math

import numpy as np

from plant.errors import PlantError
from plant.hexapod.model import StewartParams, inverse_dynamics, inverse_kinematics
from plant.rotations import rpy_matrix
from plant.telescope import optics
from scenarios.cosim.records import Block

MAX_POINTS = 4000
BLOCK = 256   # rows buffered per metric, then evaluated at once by the batched plant calls


def _squares(errors):
    """Each row's sum of squares, by the same dot product a single row's ``e @ e`` runs."""
    return (errors[:, None, :] @ errors[:, :, None])[:, 0, 0]


def _largest(rows):
    """Largest of the rows' maxima; a row holding NaN is skipped, as max() over one row's
    NaN maximum skipped it (NaN when every row holds one, which max() then skips)."""
    return float(np.fmax.reduce(rows.max(axis=1)))


FLOOR = 1e-3      # in a metric's unit (1 nm, 1 N): below it an error is numerical noise
MIN_ROWS = 10     # a metric counted from fewer recorded rows is no measure of a run
SAMPLED = 0.10    # ... nor one whose RMS over every other counted row differs from its RMS by more:
                  # the error changes faster than the rows are recorded (their interval aliases it)


class _Metric:
    """Running RMS, peak and decimated series of per-row errors. A subclass buffers the
    rows its ``needs`` name (``feed``: the recorder's blocks; ``update``: one row) and
    turns a block of them into errors at once (``_evaluate``); the sums then run row by
    row in time order, as one row at a time did."""

    scale, unit = 1.0, ""
    start = 0.0      # updates before this time are ignored (settling)
    needs = ()

    def __init__(self, name):
        self.name = name
        self.count = 0
        self.sum_sq = 0.0
        self.peak = 0.0
        self.t, self.values = [], []
        self.stride, self._countdown = 1, 1
        self._block = None
        self.rows, self.even_sq, self.even_count = 0, 0.0, 0   # the sampling check (undersampled)

    def feed(self, t, columns):
        """Rows at times t (n,): ``columns`` holds each need's values (n, its size),
        copied into the block (the caller may overwrite its arrays afterwards); each
        full block is evaluated."""
        if self._block is None:
            ends = np.cumsum([0] + [np.shape(c)[1] for c in columns]).tolist()
            self._where = [slice(a, b) for a, b in zip(ends, ends[1:])]
            self._cuts = ends[1:-1]
            self._block = Block(BLOCK, ends[-1])
        self._block.add(t, list(zip(columns, self._where)), self._flush)

    def update(self, t, values):
        """One row given by name, {need: its values} (a caller without the recorder's
        blocks): a block of one row."""
        self.feed(np.array([t]), [np.reshape(values[name], (1, -1)) for name in self.needs])

    def _flush(self):
        """Evaluate the buffered rows. If the batched call refuses the block (a singular
        pose, NaN), the rows go one at a time: those before the bad one are counted and
        its error is raised, as when each row was evaluated on arrival."""
        if self._block is None or not self._block.filled:
            return
        times, rows = self._block.take()
        try:
            self._evaluate(times, np.split(rows, self._cuts, axis=1))
        except PlantError:
            for k in range(len(times)):
                self._evaluate(times[k:k + 1], np.split(rows[k:k + 1], self._cuts, axis=1))
            raise

    def _accumulate(self, t, errors):
        """t (n,) and errors (n, m): one row's m magnitudes per time, in time order; RMS
        over all, peak of |error|; the series keeps a row's RMS every stride-th row."""
        squares = _squares(errors)
        size = errors.shape[1]
        self.count += size * len(t)
        even = (self.rows + np.arange(len(t))) % 2 == 0
        self.rows += len(t)
        self.even_sq += float(squares[even].sum())
        self.even_count += size * int(even.sum())
        self.sum_sq = float(np.add.accumulate(np.r_[self.sum_sq, squares])[-1])   # added in time order
        self.peak = max(self.peak, _largest(errors), _largest(-errors))
        times, rms = t.tolist(), np.sqrt(squares / size).tolist()
        i = self._countdown - 1   # the next row the series keeps
        while i < len(times):     # up to the next thinning at a time
            stop = min(len(times), i + (MAX_POINTS - len(self.t)) * self.stride)
            self.t += times[i:stop:self.stride]
            self.values += rms[i:stop:self.stride]
            i += len(range(i, stop, self.stride)) * self.stride
            if len(self.t) >= MAX_POINTS:   # thin to half and keep half as often from now on
                self.t, self.values = self.t[::2], self.values[::2]
                self.stride *= 2
        self._countdown = i - len(times) + 1

    def result(self):
        """RMS and peak in the metric's unit; NaN if nothing was counted (a run that
        failed before the metric's ``from``), never a reassuring 0."""
        self._flush()
        if not self.count:
            return {"rms": math.nan, "peak": math.nan, "unit": self.unit}
        rms = math.sqrt(self.sum_sq / self.count)
        return {"rms": rms * self.scale, "peak": self.peak * self.scale, "unit": self.unit}

    def series(self):
        self._flush()
        return np.array(self.t), np.array(self.values) * self.scale

    def undersampled(self):
        """Why the recorded rows cannot carry this metric (None if they can, or if nothing
        was counted: its NaN says so): fewer than MIN_ROWS rows, or an RMS over every other
        row that differs from the RMS over all by more than SAMPLED. Below 1 nm (or 1 N)
        the check is not made: numerical noise has no sampling to get right."""
        self._flush()
        if not self.rows:
            return None
        if self.rows < MIN_ROWS:
            return f"is counted from {self.rows} recorded row{'s' * (self.rows != 1)} (at least {MIN_ROWS} carry one)"
        full = math.sqrt(self.sum_sq / self.count)
        half = math.sqrt(self.even_sq / self.even_count)
        if full * self.scale < FLOOR or abs(half - full) <= SAMPLED * full:
            return None
        return (f"changes faster than its rows are recorded: its RMS over every other row is "
                f"{abs(half - full) / full:.0%} off its RMS over all (more than {SAMPLED:.0%})")


class LegTracking(_Metric):
    scale, unit = 1e6, "µm"

    def __init__(self, name, measured, reference_pose, params=None):
        super().__init__(name)
        self.params = params or StewartParams.paper()
        self.needs = [measured, reference_pose]
        self.measured, self.reference = measured, reference_pose

    def _evaluate(self, t, columns):
        measured, reference = columns
        self._accumulate(t, measured - inverse_kinematics(self.params, reference))


class _Part(_Metric):
    """A second quantity of a metric (a pose's rotation angle, a path-length error), fed by
    it: reading it flushes its owner's block."""

    def __init__(self, name, owner):
        super().__init__(name)
        self.owner = owner

    def _flush(self):
        self.owner._flush()


def key_unit(values, key):
    """The unit of one number of a metric's result ({"rms": ..., "unit": "µm, µrad"}): a
    pose metric's rotation_* keys are in its second unit, a pointing metric's path_* keys
    in its second and efficiency_loss_* keys in its third."""
    units = values.get("unit", "").split(", ")
    second = ("rotation", "path")
    if len(units) > 2 and key.startswith("efficiency_loss"):
        return units[2]
    return units[1] if len(units) > 1 and key.startswith(second) else units[0]


class PoseTracking(_Metric):
    scale, unit = 1e6, "µm / µrad"

    def __init__(self, name, measured, reference):
        super().__init__(name)
        self.needs = [measured, reference]
        self.measured, self.reference = measured, reference
        self.rotation = _Part(name + " rotation", self)

    def _evaluate(self, t, columns):
        pose, ref = columns
        offset = pose[:, :3] - ref[:, :3]
        distance = np.sqrt(_squares(offset))
        r = np.swapaxes(rpy_matrix(ref[:, 3:]), 1, 2) @ rpy_matrix(pose[:, 3:])
        # atan2 keeps full precision for small angles, where arccos of the trace does not
        angle = [math.atan2(math.hypot(a, b, c), trace - 1.0) for a, b, c, trace in zip(
            (r[:, 2, 1] - r[:, 1, 2]).tolist(), (r[:, 0, 2] - r[:, 2, 0]).tolist(),
            (r[:, 1, 0] - r[:, 0, 1]).tolist(), (r[:, 0, 0] + r[:, 1, 1] + r[:, 2, 2]).tolist())]
        self._accumulate(t, distance[:, None])
        self.rotation._accumulate(t, np.array(angle)[:, None])

    def result(self):
        position, rotation = super().result(), self.rotation.result()
        return {"rms": position["rms"], "peak": position["peak"], "rotation_rms": rotation["rms"] * 1e6,
                "rotation_peak": rotation["peak"] * 1e6, "unit": "µm, µrad"}


class Tracking(_Metric):
    scale, unit = 1e6, "µm"

    def __init__(self, name, measured, reference):
        super().__init__(name)
        self.needs = [measured, reference]
        self.measured, self.reference = measured, reference

    def _evaluate(self, t, columns):
        measured, reference = columns
        self._accumulate(t, measured - reference)


class Peak(_Metric):
    scale, unit = 1e-3, "kN"

    def __init__(self, name, variable):
        super().__init__(name)
        self.needs = [variable]
        self.variable = variable

    def _evaluate(self, t, columns):
        self._accumulate(t, columns[0])


class BaseEffect(_Metric):
    """Peak |F_full - F_no_base| (total), |F_gravity - F_no_base| (gravity turning) and
    |F_full - F_gravity| (transport, centripetal, Coriolis) along the reference motion."""

    scale, unit = 1e-3, "kN"

    def __init__(self, name, base, reference, params=None):
        super().__init__(name)
        self.params = params or StewartParams.paper()
        self.base = [f"{base}.base_pose", f"{base}.base_rate", f"{base}.base_acc"]
        self.ref = [f"{reference}.reference_pose", f"{reference}.reference_rate", f"{reference}.reference_acc"]
        self.needs = self.base + self.ref
        self.gravity_peak = 0.0
        self.transport_peak = 0.0

    def _evaluate(self, t, columns):
        motion = columns[3:] + columns[:3]   # reference pose, rate, acc, then the base's
        full, gravity, none = (inverse_dynamics(self.params, *motion, fidelity=f)
                               for f in ("full", "base_gravity", "no_base"))
        self._accumulate(t, full - none)
        self.gravity_peak = max(self.gravity_peak, _largest(np.abs(gravity - none)))
        self.transport_peak = max(self.transport_peak, _largest(np.abs(full - gravity)))

    def result(self):
        out = super().result()
        counted = 1.0 if self.count else math.nan
        out.update(gravity_peak=self.gravity_peak * self.scale * counted,
                   transport_peak=self.transport_peak * self.scale * counted)
        return out


LOSS_BANDS = ("Ku", "K", "Ka", "Q")   # optics.BANDS whose efficiency loss a pointing metric gives


def loss_key(band):
    """'efficiency_loss_22GHz': the result key of the loss at an optics.BANDS band."""
    return f"efficiency_loss_{optics.BANDS[band] / 1e9:g}GHz"


class Pointing(_Metric):
    """The pose error in the telescope's units: the beam's pointing error (its angle,
    arcsec), and a part for the path-length error (µm) whose RMS gives the efficiency
    loss at LOSS_BANDS."""

    scale, unit = 1.0 / optics.ARCSEC, "arcsec"

    def __init__(self, name, measured, reference, geometry=None):
        super().__init__(name)
        self.geometry = geometry or optics.Cassegrain.tianma()
        self.needs = [measured, reference]
        self.measured, self.reference = measured, reference
        self.path = _Part(name + " path", self)
        self.path.scale = 1e6

    def _evaluate(self, t, columns):
        motion = optics.subreflector_motion(*columns)
        beam = optics.pointing(motion, self.geometry)
        self._accumulate(t, np.hypot(beam[:, 0], beam[:, 1])[:, None])
        self.path._accumulate(t, optics.path_error(motion, self.geometry)[:, None])

    def result(self):
        angle, path = super().result(), self.path.result()
        losses = {loss_key(band): 100.0 * float(optics.efficiency_loss(path["rms"] * 1e-6, optics.BANDS[band]))
                  if math.isfinite(path["rms"]) else math.nan for band in LOSS_BANDS}
        return {"rms": angle["rms"], "peak": angle["peak"], "path_rms": path["rms"], "path_peak": path["peak"],
                **losses, "unit": "arcsec, µm, %"}


KINDS = {"leg_tracking": LegTracking, "pose_tracking": PoseTracking, "tracking": Tracking,
         "peak": Peak, "base_effect": BaseEffect, "pointing": Pointing}


def make(metric):
    """A fresh metric object from a scenario's Metric spec."""
    made = KINDS[metric.kind](metric.name, **metric.args)
    made.start = metric.start
    return made
