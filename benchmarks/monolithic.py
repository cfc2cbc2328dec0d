"""The monolithic C loop (benchmarks/monolithic.c) next to the co-simulation it mirrors.

``Pair(scenario, paths, values)`` starts the scenario's native FMUs as the master does
(scenarios/cosim/master.py start), reads from the initialised instances every number the loop
needs (parameters, start values, the kernel constants of fmu_src/native_build.py), and
then runs either side: ``cosim(steps)`` through the master's C stepping loop (the leg
lengths after every step), ``monolithic(steps)`` through the C loop. Scenarios of a
telescope, a HexapodPlant and a LegController wired as paper_manoeuvre, Jacobi master.
"""
import ctypes
import os
import pathlib
import subprocess
import tempfile

import numpy as np

ROOT = pathlib.Path(__file__).resolve().parents[1]
from controller.feedforward import FEEDFORWARD_MODES, model_fidelity
from fmu_src.native_build import CFLAGS
from fmu_src.telescope_fmu import BLOCK, PROFILES
from plant.hexapod.model import FIDELITIES, HOME_POSE, S_BAND_POSE, SINGULAR_RATIO, StewartParams, fidelity_mode
from plant.integrators import INTEGRATORS
from plant.telescope.model import TelescopeParams
from scenarios.cosim import master

_LIB = None
ROLES = {"telescope": "base", "hexapod_plant": "plant", "leg_controller": "controller"}


def library():
    """monolithic.c and the kernels it calls, compiled once per process with the native
    FMUs' flags (-ffp-contract=off: their roundings), its symbol left visible."""
    global _LIB
    if _LIB is None:
        folders = [ROOT / "plant" / "c", ROOT / "controller" / "c"]
        sources = [ROOT / "benchmarks" / "monolithic.c"] + [c for f in folders for c in sorted(f.glob("*.c"))]
        target = pathlib.Path(tempfile.mkdtemp()) / "libmonolithic.so"
        cmd = [os.environ.get("CC", "cc"), *(f for f in CFLAGS if not f.startswith("-fvisibility")),
               *(f"-I{f}" for f in folders),
               *map(str, sources), "-o", str(target), "-lm"]
        run = subprocess.run(cmd, capture_output=True, text=True)
        if run.returncode:
            raise RuntimeError(f"compiling the monolithic loop failed:\n{' '.join(cmd)}\n{run.stderr}")
        lib = ctypes.CDLL(str(target))
        dp, ip = ctypes.POINTER(ctypes.c_double), ctypes.POINTER(ctypes.c_int)
        lib.mb_monolithic.argtypes = [dp, dp, ip, dp, ip, dp, ip, ctypes.c_double, ctypes.c_double, ctypes.c_long,
                                      ctypes.c_int, dp]
        lib.mb_monolithic.restype = ctypes.c_long
        _LIB = lib
    return _LIB


def _doubles(parts):
    """One contiguous double array of the parts (numbers and arrays) one after the other."""
    return np.concatenate([np.asarray(part, dtype=float).ravel() for part in parts])


def _ints(values):
    return np.ascontiguousarray(np.asarray(values, dtype=np.intc))


def _ptr(array, kind):
    return array.ctypes.data_as(ctypes.POINTER(kind))


class Pair:
    """A scenario's co-simulation (native FMUs) and its monolithic loop, set up alike."""

    def __init__(self, scenario, paths, values):
        roles = {ROLES[f]: inst for inst, f in scenario.fmus.items()}
        if sorted(roles) != ["base", "controller", "plant"] or scenario.master != "jacobi":
            raise ValueError(f"the monolithic loop mirrors a Jacobi telescope + hexapod_plant + leg_controller "
                             f"scenario, not {scenario.name}")
        self.scenario, self.instances = scenario, {}
        self._lib = library()   # compiled before anything is timed
        try:
            self.exchange, _ = master.start(scenario, paths, values, self.instances)
            self.loop = master.Loop(self.exchange, self.instances, list(scenario.fmus), False,
                                    scenario.extrapolation, scenario.start_time, scenario.step)
            port, where = self.exchange.read_ports[roles["plant"]]
            self._lengths = where.start + np.array([port.names.index(f"leg_length[{i}]") for i in range(1, 7)])
            self.exchange.read()
            self.exchange.y_prev[:] = self.exchange.y
            self._args = self._arguments(*(self.instances[roles[r]] for r in ("base", "plant", "controller")))
        except BaseException:
            self.close()
            raise

    @staticmethod
    def _reals(inst, *names):
        return [inst.get_real(n) for name in names
                for n in ([f"{name}[{i}]" for i in range(1, 7)] if f"{name}[1]" in inst.variables else [name])]

    @staticmethod
    def _integer(inst, name):
        return inst.call("getInteger", [inst.vr(name)])[0]

    def _arguments(self, base, plant, ctrl):
        p = StewartParams.paper()
        hexapod = _doubles([p.base_joints, p.platform_joints, p.kernel_data])
        self._singular = SINGULAR_RATIO * p.home_det
        stroke = plant.get_real("stroke")
        plant_mode = fidelity_mode(FIDELITIES[self._integer(plant, "fidelity")])
        if INTEGRATORS[self._integer(plant, "integrator")] not in ("rk4", "euler"):
            raise ValueError("the native plant (and this loop) has rk4 and euler only")
        plant_data = _doubles([*self._reals(plant, "actuator_bandwidth", "reflected_mass", "coulomb_friction",
                                            "viscous_friction", "friction_velocity", "actuator_force_limit"),
                               p.home_lengths - stroke, p.home_lengths + stroke, plant.get_real("max_step"),
                               *self._reals(plant, "leg_force", "platform_wrench", "pose")])
        plant_modes = _ints([INTEGRATORS[self._integer(plant, "integrator")] == "rk4",
                             int(plant_mode[0]) if self._integer(plant, "moving_base") else 0,
                             bool(plant_mode[1])])
        gains = _doubles(self._reals(ctrl, "kp", "ki", "kd", "force_limit", "integral"))
        mode = FEEDFORWARD_MODES[self._integer(ctrl, "feedforward")]
        ctrl_mode = fidelity_mode(model_fidelity(mode))
        ctrl_modes = _ints([int(ctrl_mode[0]), bool(ctrl_mode[1]), mode != "none"])
        if base.get_real("servo_bandwidth") > 0:
            raise ValueError("the monolithic loop has the telescope without its axis servo")
        t = TelescopeParams.tianma()
        tel = _doubles([*self._reals(base, "latitude", "longitude", "lever_arm", "az_rate_max", "az_acc_max",
                                     "el_rate_max", "el_acc_max"), t.b_y, t.c_y, t.b_z, t.c_z, t.home,
                        *self._reals(base, "start_azimuth", "start_elevation", "target_azimuth",
                                     "target_elevation", "right_ascension", "declination", "utc_start",
                                     "paper_duration", "start_delay"), HOME_POSE, S_BAND_POSE])
        first = base.vr("base_pose[1]")
        rows = [base.vr(f"{v}[1]") - first for v in ("base_pose", "base_rate", "base_acc", "reference_pose",
                                                     "reference_rate", "reference_acc")]
        kind = {"slew": 0, "sidereal": 1, "paper": 2}[PROFILES[self._integer(base, "profile")]]
        tel_modes = _ints([kind, BLOCK, *rows])
        return [hexapod, plant_data, plant_modes, gains, ctrl_modes, tel, tel_modes]

    def monolithic(self, steps, lengths=True):
        """(steps completed, leg lengths (steps + 1, 6) after initialization and every
        step, or None): the C loop from the initial state."""
        hexapod, plant_data, plant_modes, gains, ctrl_modes, tel, tel_modes = self._args
        out = np.full((steps + 1, 6), np.nan) if lengths else None
        done = self._lib.mb_monolithic(
            _ptr(hexapod, ctypes.c_double), _ptr(plant_data, ctypes.c_double), _ptr(plant_modes, ctypes.c_int),
            _ptr(gains, ctypes.c_double), _ptr(ctrl_modes, ctypes.c_int), _ptr(tel, ctypes.c_double),
            _ptr(tel_modes, ctypes.c_int), self._singular, self.scenario.step, steps,
            int(self.scenario.extrapolation == "linear"),
            _ptr(out, ctypes.c_double) if lengths else None)
        return done, out

    def cosim(self, steps, lengths=True):
        """(steps completed, leg lengths as ``monolithic``): the master's C stepping loop
        over the native FMUs, one macro step per call when the lengths are kept, else all
        steps in one call. Runs once per Pair (the FMUs are not reset)."""
        if not lengths:
            return self.loop.steps(0, steps), None
        out = np.full((steps + 1, 6), np.nan)
        out[0] = self.exchange.y[self._lengths]
        for k in range(steps):
            if self.loop.steps(k, 1) != 1:
                return k, out
            out[k + 1] = self.exchange.y[self._lengths]
        return steps, out

    def close(self):
        for instance in self.instances.values():
            instance.terminate()
