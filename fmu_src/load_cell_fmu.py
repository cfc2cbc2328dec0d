"""FMU: the legs' load cells (the actuator's force in, the measured force out), for the leg
controller's disturbance observer (controller/observer.py).

What it measures: wire the plant's ``leg_force_actual`` to ``leg_force``: the force the
actuator delivers to the leg after its 50 Hz lag, its limit and the screw's friction
(plant/c/hexapod.c). A cell between the leg and its platform joint would also see the
reflected mass's inertia force, m_r times the leg's acceleration; the kit models it at the
nut, before that term, and the observer's mass (``observer_mass`` of the controller)
carries the reflected mass instead. A motor-current measure would read the force before
the friction, with the current loop's noise: the same FMU with other parameters and the
friction then counted in the disturbance.

The sensor model is plant/c/sensors.h (mb_load_cell, one C kernel for this FMU and the
native one): a first-order low-pass at ``bandwidth``, white noise, quantisation to
``resolution`` and ``delay_steps`` samples of delay; a sample taken at doStep(t, h) from
the input at t is read out at t + h, as the LegSensor's. Everything 0 gives the exact force
one communication step late. The defaults are off; the scenes set values, ASSUMED: a
25 kN strain-gauge cell with 0.02 % of range (5 N) RMS noise, 1 N steps, 500 Hz.
The noise generator's state is saved with the FMU state.
"""

from fmu_src.operating_point import STATIC_LEG_FORCES
from fmu_src.slave import INPUT, OUTPUT, GuardedSlave
from plant._kernel import ffi, lib

SEED_RANGE = (0, 2 ** 31 - 1)


class LoadCell(GuardedSlave):
    description = "Hexapod leg load cells: first-order bandwidth, noise, quantisation, sample delay"

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.settings = self.parameters((
            ("resolution", "N", 0.0, "converter step (quantisation) of the measured force; 0: no rounding",
             (0.0, 1e4)),
            ("noise", "N", 0.0, "white measurement noise, RMS per sample; 0: none", (0.0, 1e4)),
            ("bandwidth", "1/s", 0.0, "cutoff of the cell's and amplifier's first-order low-pass [Hz]; "
             "0: none", (0.0, 1e5)),
        ))
        self.integer("delay_steps", "samples of conversion delay on top of the communication step", 0,
                     (0, lib.MB_SENSOR_MAX_DELAY))
        self.integer("seed", "seed of the noise generator (same seed: same noise)", 1, SEED_RANGE)
        self.true_force = self.vector("leg_force", 6, INPUT, "true actuator force on the leg, + extends", "N",
                                      start=STATIC_LEG_FORCES)
        self.measured = self.vector("measured_force", 6, OUTPUT, "measured leg force, + extends", "N",
                                    start=STATIC_LEG_FORCES)
        self.state = ffi.new("mb_load_cell *")
        self._pointers = [ffi.from_buffer("double[]", a) for a in (self.true_force, self.measured)]

    def initialize(self):
        s = self.settings
        lib.mb_load_cell_start(self.state, self.seed, 6, s["resolution"], s["noise"], *self._pointers)

    def step(self, t, h):
        s = self.settings
        lib.mb_load_cell_sample(self.state, 6, s["resolution"], s["noise"], s["bandwidth"], self.delay_steps, h,
                                *self._pointers)

    def extra_state(self):
        return bytes(ffi.buffer(self.state))

    def set_extra_state(self, extra):
        ffi.buffer(self.state)[:] = extra
