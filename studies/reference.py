"""Reference solutions of the hexapod scenes, outside FMI, and the co-simulation error
measured against them.

What the reference is
---------------------
The three FMUs of a scene (telescope base motion, hexapod plant, leg controller) taken
as ONE continuous-time model and integrated by scipy's Radau IIA (implicit, order 5) at
rtol 1e-10 with per-state absolute tolerances (pose 1e-12, twist 1e-11, integral 1e-15),
in segments split where the scene's profiles switch (quintic start and end, the corners
of a trapezoidal slew), so that no step straddles a jump in the base or reference
acceleration.

State z = [pose (6), twist (6), PID integral (6)]:

* plant: the same compiled right-hand side as the plant FMU (StewartParams.kernel.rhs, the
  scene's fidelity and moving_base setting), but with the base motion evaluated exactly
  at t instead of held and Taylor-extrapolated from the start of a communication step;
* base and reference motion: exactly what the telescope FMU evaluates (plant.telescope.model
  profiles, base_motion, reference_pose, or the paper's quintics), at t;
* controller: the continuous-time limit of controller.pid and the controller FMU, with
  no sample-and-hold and no delay:
      e = l_ref(t) - l(x),  de = l_ref'(t) - l'(x),  dI/dt = e (0 while winding up),
      F = clip(ff(t) + kp e + ki I + kd de, +-force_limit),
  ff, l_ref and l_ref' from controller.feedforward.feedforward_and_legs with the
  scene's feedforward mode and the same (reference and base) inputs the FMU is fed.
  Conditional-integration anti-windup is kept in its continuous form (dI/dt = 0 while
  |F| is beyond the limit and e pushes it further); whether the limit was ever reached
  is reported (``Reference.saturated``).

So the co-simulation error against this reference holds everything the communication
step costs: the controller's zero-order hold and its one-step delay (Jacobi), the
plant's held leg forces and extrapolated base motion, the master's ordering and
extrapolation, and the plant integrator's own error, plus, for a reduced-fidelity
plant, the model error (the reference keeps the scene's own fidelity, "full" in every
shipped scene).

Initial state: as in the co-simulation, the platform at the reference pose at the
start time, at rest relative to the base, the integral zero.

Error measures (``errors``), over the co-simulation's recorded times in a window:
platform position error |p - p_ref| [µm], rotation error (angle of R_ref^T R) [µrad],
leg-force error F - F_ref [N] over all legs; each as RMS and max. The force the
co-simulation records at t_k is the one the plant holds over [t_k, t_k+1]; it is
compared with the continuous controller's force at t_k.
"""
from dataclasses import dataclass, field, replace

import numpy as np
from scipy.integrate import solve_ivp

from controller.feedforward import FEEDFORWARD_MODES, feedforward_and_legs
from plant.hexapod import kernel as kane
from plant.hexapod.model import FIDELITIES, HOME_POSE, S_BAND_POSE, StewartParams, fidelity_mode
from plant.rotations import rpy_matrix
from plant.telescope import model as telescope
from plant.trajectory import quintic
from scenarios.spec import Link

PROFILES = ("slew", "sidereal", "paper")          # the telescope FMU's enumeration
SIGNALS = ("base_pose", "base_rate", "base_acc", "reference_pose", "reference_rate", "reference_acc")
RTOL = 1e-10
ATOL = np.r_[np.full(6, 1e-12), np.full(6, 1e-11), np.full(6, 1e-15)]


def _defaults(description):
    """{name: start value} of an FMU's parameters from its model description (a String
    parameter, such as the Telescope's replay_table, as its text)."""
    out = {}
    for v in description.modelVariables:
        if v.causality == "parameter" and v.start is not None:
            out[v.name] = (int(v.start) if v.type in ("Integer", "Enumeration") else
                           v.start if v.type == "String" else float(v.start))
    return out


class BaseMotion:
    """The telescope FMU's outputs as functions of time, computed the way it computes
    them (fmu_src.telescope_fmu.Telescope._evaluate)."""

    def __init__(self, settings):
        from datetime import datetime, timezone
        s = self.settings = dict(settings)
        self.kind = PROFILES[int(s["profile"])]
        self.params = replace(telescope.TelescopeParams.tianma(), lever_arm=s["lever_arm"],
                              latitude=s["latitude"], longitude=s["longitude"],
                              az_rate_max=s["az_rate_max"], az_acc_max=s["az_acc_max"],
                              el_rate_max=s["el_rate_max"], el_acc_max=s["el_acc_max"])
        if self.kind == "slew":
            start = (s["start_azimuth"], s["start_elevation"])
            target = (s["target_azimuth"], s["target_elevation"])
            self.profile_at = lambda t: telescope.slew(self.params, start, target, t)
        elif self.kind == "sidereal":
            utc = datetime.fromtimestamp(s["utc_start"], tz=timezone.utc)
            self.profile_at = lambda t: telescope.sidereal_track(self.params, s["right_ascension"],
                                                                 s["declination"], utc, t)
        else:
            self.profile_at = lambda t: telescope.paper_manoeuvre(t, s["paper_duration"])

    def __call__(self, times):
        """{signal: (n, 6)} at the times (1-D, increasing)."""
        times = np.atleast_1d(np.asarray(times, dtype=float)) - self.settings["start_delay"]
        axes = self.profile_at(times)
        base = telescope.base_motion(self.params, axes)
        if self.kind == "paper":
            ref = quintic(HOME_POSE, S_BAND_POSE, self.settings["paper_duration"], times)
        else:
            ref = telescope.reference_pose(self.params, axes)
        return dict(zip(SIGNALS, (*base, *ref)))

    def breakpoints(self):
        """Times where a base or reference acceleration jumps or its derivative does."""
        s, delay = self.settings, self.settings["start_delay"]
        if self.kind == "paper":
            return [delay, delay + s["paper_duration"]]
        if self.kind == "slew":
            points = [delay]
            for d, rate, acc in ((s["target_azimuth"] - s["start_azimuth"], s["az_rate_max"], s["az_acc_max"]),
                                 (s["target_elevation"] - s["start_elevation"], s["el_rate_max"], s["el_acc_max"])):
                D = abs(d)
                if D == 0:
                    continue
                t_acc = min(rate / acc, np.sqrt(D / acc))
                duration = D / (acc * t_acc) + t_acc
                points += [delay + t_acc, delay + duration - t_acc, delay + duration]
            return sorted(points)
        return []


@dataclass
class Scene:
    """What the reference needs of a scenario: time window, base motion, plant and
    controller settings, and which base signals the controller is fed."""

    name: str
    start_time: float
    stop_time: float
    motion: BaseMotion
    moving_base: bool
    fidelity: str
    feedforward: str
    gains: dict
    controller_constants: dict = field(default_factory=dict)   # unconnected inputs -> value

    @classmethod
    def from_prepared(cls, scenario, descriptions, values):
        """From scenarios.runs.runner.prepare's (scenario, _, descriptions, values)."""
        kinds = {inst: fmu for inst, fmu in scenario.fmus.items()}
        inst = {kind: name for name, kind in kinds.items()}
        base, plant, ctrl = inst["telescope"], inst["hexapod_plant"], inst["leg_controller"]

        def settings(name):
            out = _defaults(descriptions[name])
            out.update({k: v for k, v in values.get(name, {}).items() if not isinstance(v, Link)})
            return out

        b, p, c = settings(base), settings(plant), settings(ctrl)
        fed = {t.split(".", 1)[1]: s for s, ts in scenario.connections for t in ts if t.startswith(ctrl + ".")}
        constants = {}
        for name in SIGNALS:
            source = fed.get(name)
            if source is None:
                constants[name] = np.array([c.get(f"{name}[{i}]", 0.0) for i in range(1, 7)])
            elif source != f"{base}.{name}":
                raise ValueError(f"{ctrl}.{name} is fed by {source}; the reference expects {base}.{name}")
        for name in ("base_pose", "base_rate", "base_acc"):
            if scenario.connections and p["moving_base"] and not any(
                    s == f"{base}.{name}" and f"{plant}.{name}" in ts for s, ts in scenario.connections):
                raise ValueError(f"{plant}.{name} is not fed by {base}.{name}")
        gains = {k: c[k] for k in ("kp", "ki", "kd", "force_limit")}
        return cls(scenario.name, scenario.start_time, scenario.stop_time, BaseMotion(b), bool(p["moving_base"]),
                   FIDELITIES[int(p["fidelity"])], FEEDFORWARD_MODES[int(c["feedforward"])], gains, constants)


class ClosedLoop:
    """Right-hand side of the coupled continuous-time model, z = [pose, twist, integral]."""

    def __init__(self, scene):
        self.scene = scene
        self.plant = StewartParams.paper()
        self.params = StewartParams.paper()
        base_mode, self.legs = fidelity_mode(scene.fidelity)
        self.base_mode = base_mode if scene.moving_base else kane.BASE_NONE
        g = scene.gains
        self.kp, self.ki, self.kd, self.limit = g["kp"], g["ki"], g["kd"], g["force_limit"]
        self._kernel = self.plant.kernel
        self._legs = np.empty((3, 6))
        self.forces = np.zeros((1, 6))
        self.base0 = np.zeros((3, 6))
        self.calls = 0
        self._cache = {}

    def inputs(self, t):
        """What depends on t alone, cached (Radau evaluates each stage time many times):
        (plant's base signals, feedforward, reference leg lengths, reference leg rates)."""
        hit = self._cache.get(t)
        if hit is not None:
            return hit
        sig = {k: v[0] for k, v in self.scene.motion(np.array([t])).items()}
        c = dict(sig)
        c.update(self.scene.controller_constants)
        ff, l_ref, ld_ref = feedforward_and_legs(self.params, self.scene.feedforward, c["reference_pose"],
                                                 c["reference_rate"], c["reference_acc"], c["base_pose"],
                                                 c["base_rate"], c["base_acc"])
        if len(self._cache) > 256:
            self._cache.clear()
        self._cache[t] = hit = (sig, ff, l_ref, ld_ref)
        return hit

    def _plant(self, t, x, forces, sig):
        self.base0[0], self.base0[1], self.base0[2] = sig["base_pose"], sig["base_rate"], sig["base_acc"]
        dx = np.empty(12)
        self._kernel.rhs(x, forces, self.base0, t, t, self.base_mode, self.legs, dx)
        self._kernel.leg_kinematics(x, self._legs)
        return dx, self._legs[0].copy(), self._legs[1].copy()

    def control(self, t, z):
        """(leg forces, dI/dt, pose-twist state, base signals, unclamped |F| max) at z, t."""
        sig, ff, l_ref, ld_ref = self.inputs(t)
        x, integral = np.ascontiguousarray(z[:12]), z[12:]
        self.forces[0] = 0.0
        _, length, ldot = self._plant(t, x, self.forces, sig)
        e, de = l_ref - length, ld_ref - ldot
        unclamped = ff + self.kp * e + self.kd * de + self.ki * integral
        winding = (np.abs(unclamped) > self.limit) & (e * unclamped > 0)
        force = np.clip(unclamped, -self.limit, self.limit)
        return force, np.where(winding, 0.0, e), x, sig, np.abs(unclamped).max()

    def __call__(self, t, z):
        self.calls += 1
        force, dI, x, sig, _ = self.control(t, z)
        self.forces[0] = force
        dx, _, _ = self._plant(t, x, self.forces, sig)
        return np.r_[dx, dI]

    def initial_state(self):
        pose = self.inputs(self.scene.start_time)[0]["reference_pose"]
        return np.r_[pose, np.zeros(12)]


@dataclass
class Reference:
    """A dense reference solution: pose and leg forces at any time in the scene."""

    scene: Scene
    segments: list            # [(t0, t1, OdeSolution)]
    rtol: float
    rhs_calls: int
    wall_time: float
    peak_force: float = 0.0   # largest |unclamped PID + feedforward force| on a 1 ms grid [N]

    @property
    def saturated(self):
        """Did the controller's force limit act anywhere (on the 1 ms grid)?"""
        return self.peak_force > self.scene.gains["force_limit"]

    def state(self, times):
        times = np.atleast_1d(times)
        out = np.empty((times.size, 18))
        ends = np.array([s[1] for s in self.segments])
        which = np.minimum(np.searchsorted(ends, times, side="left"), len(self.segments) - 1)
        for k, (_, _, sol) in enumerate(self.segments):
            mask = which == k
            if mask.any():
                out[mask] = sol(times[mask]).T
        return out

    def evaluate(self, times, peak=False):
        """(pose (n, 6), leg forces (n, 6)) at the times [, largest unclamped |force|]."""
        times = np.atleast_1d(np.asarray(times, dtype=float))
        z = self.state(times)
        loop = ClosedLoop(self.scene)
        out = [loop.control(t, zi) for t, zi in zip(times, z)]
        forces = np.array([o[0] for o in out])
        if peak:
            return z[:, :6], forces, max(o[4] for o in out)
        return z[:, :6], forces


def solve(scene, rtol=RTOL, atol_scale=1.0, method="Radau"):
    """Integrate the coupled model over the scene (segments between the profiles'
    breakpoints); returns a Reference."""
    import time
    loop = ClosedLoop(scene)
    cuts = [t for t in scene.motion.breakpoints() if scene.start_time < t < scene.stop_time]
    edges = [scene.start_time, *cuts, scene.stop_time]
    z = loop.initial_state()
    segments = []
    start = time.perf_counter()
    for t0, t1 in zip(edges[:-1], edges[1:]):
        sol = solve_ivp(loop, (t0, t1), z, method=method, rtol=rtol, atol=ATOL * atol_scale,
                        dense_output=True)
        if not sol.success:
            raise RuntimeError(f"reference of {scene.name} failed on [{t0}, {t1}]: {sol.message}")
        segments.append((t0, t1, sol.sol))
        z = sol.y[:, -1]
    wall = time.perf_counter() - start
    ref = Reference(scene, segments, rtol, loop.calls, wall)
    grid = np.linspace(scene.start_time, scene.stop_time, int(round((scene.stop_time - scene.start_time) / 1e-3)) + 1)
    ref.peak_force = float(ref.evaluate(grid, peak=True)[2])
    return ref


# ------------------------------------------------------------------------ error measures
def rotation_angle(pose, ref):
    """Angle [rad] of R(ref)^T R(pose), row by row (atan2 of the skew and symmetric
    parts: accurate down to 1e-16 rad, where arccos of the trace stops at ~1e-8)."""
    relative = np.swapaxes(rpy_matrix(ref[:, 3:]), -1, -2) @ rpy_matrix(pose[:, 3:])
    skew = relative - np.swapaxes(relative, -1, -2)
    sin = 0.5 * np.sqrt(skew[:, 2, 1] ** 2 + skew[:, 0, 2] ** 2 + skew[:, 1, 0] ** 2)
    cos = 0.5 * (np.trace(relative, axis1=-2, axis2=-1) - 1)
    return np.arctan2(sin, cos)


def errors(times, pose, forces, ref_pose, ref_forces):
    """Error measures of a trajectory against the reference at the same times:
    position [µm], rotation [µrad], leg force [N]; RMS and max each."""
    position = np.linalg.norm(pose[:, :3] - ref_pose[:, :3], axis=1) * 1e6
    rotation = rotation_angle(pose, ref_pose) * 1e6
    force = np.abs(forces - ref_forces)
    rms = lambda a: float(np.sqrt(np.mean(np.square(a))))
    return {"pose_rms_um": rms(position), "pose_max_um": float(position.max()),
            "rot_rms_urad": rms(rotation), "rot_max_urad": float(rotation.max()),
            "force_rms_N": rms(force), "force_max_N": float(force.max())}


def compare(reference, times, pose, forces, window=None):
    """errors() of a co-simulated trajectory (pose, forces at ``times``) against the
    reference, over ``window`` = (t_from, t_to) (default: the whole scene)."""
    times = np.asarray(times)
    lo, hi = window or (reference.scene.start_time, reference.scene.stop_time)
    keep = (times >= lo - 1e-12) & (times <= hi + 1e-12)
    ref_pose, ref_forces = reference.evaluate(times[keep])
    return errors(times[keep], pose[keep], forces[keep], ref_pose, ref_forces)


def difference(a, b, times):
    """errors() of reference a against reference b at the times (convergence checks)."""
    pa, fa = a.evaluate(times)
    pb, fb = b.evaluate(times)
    return errors(times, pa, fa, pb, fb)
