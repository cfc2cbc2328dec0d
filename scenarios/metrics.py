"""Metrics computed while a run streams: running RMS and peak, plus a decimated time
series for the charts (at most MAX_POINTS points, so memory stays flat on long runs).

Kinds (scenario key ``kind``):
* ``leg_tracking``: measured leg lengths against the legs of the reference pose
  (inverse kinematics of the hexapod), in µm.
* ``pose_tracking``: platform pose against the reference pose: position error norm [µm]
  and rotation error angle [µrad].
* ``tracking``: any measured vector against a reference vector of the same size [µm].
* ``peak``: largest |value| of a variable [kN].
* ``base_effect``: along the reference motion and the base motion, the peak leg-force
  change the base motion causes, split into gravity turning with the base and the
  transport/centripetal/Coriolis terms (inverse dynamics at three fidelities) [kN].
"""
import math

import numpy as np

from plant.rotations import rpy_matrix
from plant.stewart import StateInverseDynamics, StewartParams, inverse_kinematics

MAX_POINTS = 4000


class _Metric:
    scale, unit = 1.0, ""
    start = 0.0      # updates before this time are ignored (settling)

    def __init__(self, name):
        self.name = name
        self.count = 0
        self.sum_sq = 0.0
        self.peak = 0.0
        self.t, self.values = [], []
        self.stride, self._countdown = 1, 1

    def _accumulate(self, t, error):
        """error: per-point magnitude(s) (any shape); RMS over all, peak of |error|;
        the series keeps the point's RMS every stride-th call."""
        error = np.asarray(error, dtype=float).ravel()
        square = float(error @ error)
        self.count += error.size
        self.sum_sq += square
        self.peak = max(self.peak, float(error.max()), -float(error.min()))
        self._countdown -= 1
        if self._countdown > 0:
            return
        self._countdown = self.stride
        self.t.append(t)
        self.values.append(math.sqrt(square / error.size))
        if len(self.t) >= MAX_POINTS:   # thin to half and keep half as often from now on
            self.t, self.values = self.t[::2], self.values[::2]
            self.stride *= 2

    def result(self):
        """RMS and peak in the metric's unit; NaN if nothing was counted (a run that
        failed before the metric's ``from``), never a reassuring 0."""
        if not self.count:
            return {"rms": math.nan, "peak": math.nan, "unit": self.unit}
        rms = math.sqrt(self.sum_sq / self.count)
        return {"rms": rms * self.scale, "peak": self.peak * self.scale, "unit": self.unit}

    def series(self):
        return np.array(self.t), np.array(self.values) * self.scale


class LegTracking(_Metric):
    scale, unit = 1e6, "µm"

    def __init__(self, name, measured, reference_pose, params=None):
        super().__init__(name)
        self.params = params or StewartParams.paper()
        self.needs = [measured, reference_pose]
        self.measured, self.reference = measured, reference_pose

    def update(self, t, values):
        self._accumulate(t, values[self.measured] - inverse_kinematics(self.params, values[self.reference]))


class PoseTracking(_Metric):
    scale, unit = 1e6, "µm / µrad"

    def __init__(self, name, measured, reference):
        super().__init__(name)
        self.needs = [measured, reference]
        self.measured, self.reference = measured, reference
        self.rotation = _Metric(name + " rotation")

    def update(self, t, values):
        pose, ref = values[self.measured], values[self.reference]
        offset = pose[:3] - ref[:3]
        self._accumulate(t, math.sqrt(offset @ offset))
        ref_R, pose_R = rpy_matrix(np.stack([ref[3:], pose[3:]]))
        r = ref_R.T @ pose_R
        axis = math.hypot(r[2, 1] - r[1, 2], r[0, 2] - r[2, 0], r[1, 0] - r[0, 1])
        # atan2 keeps full precision for small angles, where arccos of the trace does not
        self.rotation._accumulate(t, math.atan2(axis, r[0, 0] + r[1, 1] + r[2, 2] - 1.0))

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

    def update(self, t, values):
        self._accumulate(t, values[self.measured] - values[self.reference])


class Peak(_Metric):
    scale, unit = 1e-3, "kN"

    def __init__(self, name, variable):
        super().__init__(name)
        self.needs = [variable]
        self.variable = variable

    def update(self, t, values):
        self._accumulate(t, values[self.variable])


class BaseEffect(_Metric):
    """Peak |F_full - F_no_base| (total), |F_gravity - F_no_base| (gravity turning) and
    |F_full - F_gravity| (transport, centripetal, Coriolis) along the reference motion."""

    scale, unit = 1e-3, "kN"

    def __init__(self, name, base, reference, params=None):
        super().__init__(name)
        params = params or StewartParams.paper()
        self.models = {f: StateInverseDynamics(params, f) for f in ("full", "base_gravity", "no_base")}
        self.base = [f"{base}.base_pose", f"{base}.base_rate", f"{base}.base_acc"]
        self.ref = [f"{reference}.reference_pose", f"{reference}.reference_rate", f"{reference}.reference_acc"]
        self.needs = self.base + self.ref
        self.gravity_peak = 0.0
        self.transport_peak = 0.0

    def update(self, t, values):
        motion = [values[r] for r in self.ref + self.base]
        full, gravity, none = (self.models[f](*motion)[0].copy() for f in ("full", "base_gravity", "no_base"))
        self._accumulate(t, full - none)
        self.gravity_peak = max(self.gravity_peak, float(np.abs(gravity - none).max()))
        self.transport_peak = max(self.transport_peak, float(np.abs(full - gravity).max()))

    def result(self):
        out = super().result()
        counted = 1.0 if self.count else math.nan
        out.update(gravity_peak=self.gravity_peak * self.scale * counted,
                   transport_peak=self.transport_peak * self.scale * counted)
        return out


KINDS = {"leg_tracking": LegTracking, "pose_tracking": PoseTracking, "tracking": Tracking,
         "peak": Peak, "base_effect": BaseEffect}


def make(metric):
    """A fresh metric object from a scenario's Metric spec."""
    made = KINDS[metric.kind](metric.name, **metric.args)
    made.start = metric.start
    return made
