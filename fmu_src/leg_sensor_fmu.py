"""FMU: the hexapod's leg encoders (true leg lengths in, measured lengths and estimated
rates out), inserted between the plant and the controller in a realistic loop.

The sensor model is plant/c/sensors.h (one C kernel for this FMU and the native one):
white noise, quantisation to the encoder resolution, the rate from a filtered backward
difference of the measured lengths, and delay_steps samples of computation delay. A
sample is taken at each doStep(t, h) from the input at t and read out at t + h: under a
Jacobi master the sensor adds one communication step of latency (a sampled encoder
read at the controller's next tick); under Gauss-Seidel (plant, sensor, controller) none.
Everything 0 gives the exact length and its backward-difference rate. The defaults are
off, not an encoder's values: the realistic scenario sets them, with their sources.
The noise generator's state (8 bytes) is saved with the FMU state, so a replay from a
saved state repeats the same noise.

A scale error (scale_error, per leg; 0: none) is a calibration error of the incremental
encoder homed at the home length: the sensed length is l + e (l - l_home), e times the
true travel from home added, before noise and quantisation.
"""
import numpy as np

from fmu_src.slave import INPUT, OUTPUT, PARAMETER, GuardedSlave
from plant._kernel import ffi, lib
from plant.hexapod.model import StewartParams

SEED_RANGE = (0, 2 ** 31 - 1)
HOME_LENGTHS = StewartParams.paper().home_lengths


class LegSensor(GuardedSlave):
    description = "Hexapod leg encoders: noise, quantisation, filtered-difference rate, sample delay"

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.settings = self.parameters((
            ("resolution", "m", 0.0, "encoder resolution (quantisation step); 0: no rounding", (0.0, 1e-2)),
            ("noise", "m", 0.0, "white measurement noise, RMS per sample; 0: none", (0.0, 1e-2)),
            ("rate_cutoff", "1/s", 0.0, "cutoff of the first-order low-pass on the backward-difference rate "
             "[Hz]; 0: the plain backward difference", (0.0, 1e5)),
        ))
        self.integer("delay_steps", "samples of computation delay on top of the communication step", 0,
                     (0, lib.MB_SENSOR_MAX_DELAY))
        self.integer("seed", "seed of the noise generator (same seed: same noise)", 1, SEED_RANGE)
        self.scale_error = self.vector("scale_error", 6, PARAMETER, "encoder scale error of the leg: it reads "
                                       "(1 + scale_error) times the true travel from the home length (assumed: "
                                       "incremental encoder homed there); 0: none", "1", np.zeros(6),
                                       valid=(-0.01, 0.01))
        self.true_length = self.vector("leg_length", 6, INPUT, "true leg length", "m", start=HOME_LENGTHS)
        self.measured = self.vector("measured_length", 6, OUTPUT, "measured leg length", "m", start=HOME_LENGTHS)
        self.rate = self.vector("estimated_rate", 6, OUTPUT, "leg rate estimated from the measured lengths",
                                "m/s")
        self.state = ffi.new("mb_sensor *")
        self.sensed = HOME_LENGTHS.copy()     # the true length as the encoder's scale sees it
        self._pointers = [ffi.from_buffer("double[]", a) for a in (self.sensed, self.measured, self.rate)]

    def _sense(self):
        """l + e (l - l_home): with e = 0 exactly l (native: the same two roundings)."""
        self.sensed[:] = self.true_length + self.scale_error * (self.true_length - HOME_LENGTHS)

    def initialize(self):
        s = self.settings
        self._sense()
        lib.mb_sensor_start(self.state, self.seed, 6, s["resolution"], s["noise"], *self._pointers)

    def step(self, t, h):
        s = self.settings
        self._sense()
        lib.mb_sensor_sample(self.state, 6, s["resolution"], s["noise"], s["rate_cutoff"], self.delay_steps, h,
                             *self._pointers)

    def extra_state(self):
        return bytes(ffi.buffer(self.state))

    def set_extra_state(self, extra):
        ffi.buffer(self.state)[:] = extra
