"""FMU: wind on the subreflector, a disturbance wrench on the hexapod's platform.

The along-wind gust u(t) of a Kaimal or Davenport spectrum and the quasi-steady drag
0.5 rho Cd A (U + u_A)^2 along the wind (u_A the gust averaged over the drag area, through
the aerodynamic admittance of a plate), with the moment of a centre of pressure off the
platform's origin, as the platform_wrench the hexapod plant takes (in {B}, turned from
{W} with the base pose input). The model is the C kernel's (plant/c/wind.h says its
equations and simplifications); u(t) is a fixed function of time drawn from the seed at
initialisation, stepped by turning phasors (mb_wind_sample_stepped, within ~1e-12 of the
direct sum; the phasors are the FMU's state), so the same seed gives the same run byte for
byte, and the native twin (fmu_src/native/wind_fmu.c) calls the same kernel.

Values (assumed, labelled in each description): the subreflector of a 65 m antenna
~6.5 m across (a tenth of the primary, as on comparable Cassegrain antennas; Tianma's
own figure not found in public sources) -> drag area pi 6.5^2 / 4 = 33.2 m2; Cd 1.2,
a flat disc's (a concave subreflector face-on lies near it); the subreflector 60 m above
ground (the antenna is 70 m high); turbulence intensity 0.15 (open country at that
height); the centre of pressure 1 m from the platform's origin along z.

The anemometer (output anemometer_speed, what a wind feedforward reads; Tianma carries one on
its subreflector, ICCT 2017): assumed on the subreflector's rim, 3.25 m across the wind from
the centre, a cup anemometer of ~2.5 m distance constant (0.25 s at 10 m/s; IEC 61400-12-1
class cups have 1.5-5 m), Davenport's C = 8 (7-10 across the wind; Simiu and Scanlan).
"""
import numpy as np

from fmu_src.operating_point import BASE_POSE
from fmu_src.slave import INPUT, OUTPUT, POSE_UNITS, GuardedSlave
from plant._kernel import ffi, lib
from plant.errors import InvalidInputError

SPECTRA = ("kaimal", "davenport")
SETTINGS = ("mean_speed", "turbulence_intensity", "length_scale", "height", "air_density", "drag_coefficient",
            "drag_area", "moment_arm", "direction", "anemometer_distance", "anemometer_upstream",
            "anemometer_time_constant", "coherence_decay")
SUBREFLECTOR_DIAMETER = 6.5   # m (assumed)
DEFAULTS = {"mean_speed": 10.0, "turbulence_intensity": 0.15, "length_scale": 0.0, "height": 60.0,
            "air_density": 1.225, "drag_coefficient": 1.2, "drag_area": np.pi * SUBREFLECTOR_DIAMETER ** 2 / 4,
            "moment_arm": 1.0, "direction": 0.0, "anemometer_distance": SUBREFLECTOR_DIAMETER / 2,
            "anemometer_upstream": 0.0, "anemometer_time_constant": 0.25, "coherence_decay": 8.0}


def gust_model(settings, spectrum=0, seed=0):
    """The kernel's seeded gust (an ``mb_wind *``) for the settings (SETTINGS names, SI)."""
    params = ffi.new("mb_wind_params *")
    for name in SETTINGS:
        setattr(params, name, float(settings[name]))
    params.spectrum = int(spectrum)
    model = ffi.new("mb_wind *")
    status = lib.mb_wind_init(model, params, int(seed))
    if status:
        raise ValueError(ffi.string(lib.mb_wind_status_text(status)).decode())
    return model


def gusts(model, times, area=False):
    """u (m/s) at the given times; ``area``: the area-averaged gust u_A the drag sees."""
    times = np.ascontiguousarray(times, dtype=float)
    out = np.empty_like(times)
    f = lib.mb_wind_area_gusts if area else lib.mb_wind_gusts
    f(model, times.size, ffi.from_buffer("double[]", times), ffi.from_buffer("double[]", out))
    return out


def anemometer_speeds(model, times):
    """The anemometer's reading U + u_a (m/s) at the given times."""
    times = np.ascontiguousarray(times, dtype=float)
    out = np.empty_like(times)
    lib.mb_wind_anemometer(model, times.size, ffi.from_buffer("double[]", times), ffi.from_buffer("double[]", out))
    return out


class Wind(GuardedSlave):
    description = "Wind on the subreflector: Kaimal/Davenport gust, quasi-steady drag -> platform wrench in {B}"

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        d = DEFAULTS
        self.settings = self.parameters((
            ("mean_speed", "m/s", d["mean_speed"], "mean wind speed U at the subreflector (10-minute mean; 0 = calm)",
             (0.0, 60.0)),
            ("turbulence_intensity", "1", d["turbulence_intensity"],
             "sigma_u / U of the along-wind gust (assumed 0.15: open country at 60 m)", (0.0, 1.0)),
            ("length_scale", "m", d["length_scale"], "integral length scale L of the spectrum; 0 = the spectrum's "
             "standard scale (Kaimal: 8.1 * 0.7 * min(height, 60 m), IEC 61400-1; Davenport: 1200 m)", (0.0, 1e5)),
            ("height", "m", d["height"], "height of the subreflector above ground (assumed 60 m; the antenna is 70 m "
             "high)", (1e-3, 1e3)),
            ("air_density", "kg/m3", d["air_density"], "air density (ISA sea level; the site is near sea level)",
             (0.0, 2.0)),
            ("drag_coefficient", "1", d["drag_coefficient"], "drag coefficient Cd (assumed 1.2, a flat disc)",
             (0.0, 5.0)),
            ("drag_area", "m2", d["drag_area"], "drag area A (assumed: a 6.5 m subreflector, pi 6.5^2 / 4)",
             (0.0, 1e3)),
            ("moment_arm", "m", d["moment_arm"], "centre of pressure along {B}'s z from {P}'s origin (assumed 1 m)",
             (-50.0, 50.0)),
            ("direction", "rad", d["direction"], "astronomical azimuth the wind comes from (north through east)",
             (-2 * np.pi, 2 * np.pi)),
            ("anemometer_distance", "m", d["anemometer_distance"], "anemometer's distance across the wind from the "
             "subreflector's centre (assumed 3.25 m: on the rim of the 6.5 m disc)", (0.0, 1e3)),
            ("anemometer_upstream", "m", d["anemometer_upstream"], "anemometer's distance up the wind from the "
             "centre, e.g. on a mast (assumed 0; it leads the gust by upstream / U, Taylor's frozen turbulence)",
             (-1e3, 1e3)),
            ("anemometer_time_constant", "s", d["anemometer_time_constant"], "anemometer's first-order lag (assumed "
             "0.25 s: a cup anemometer of 2.5 m distance constant at 10 m/s; a sonic one ~0)", (0.0, 100.0)),
            ("coherence_decay", "1", d["coherence_decay"], "Davenport's decay C of the gust's root-coherence "
             "exp(-C f d / U) between anemometer and disc (assumed 8: 7-10 across the wind, Simiu and Scanlan)",
             (0.0, 100.0)),
        ))
        self.enumeration("spectrum", "gust spectrum", SPECTRA, 0)
        self.integer("seed", "seed of the gust's random phases and frequencies", 0, (0, 2 ** 31 - 1))
        self.base_pose = self.vector("base_pose", 6, INPUT, [f"base, in {{W}}, {n}" for n in
                                                           ("x", "y", "z", "roll", "pitch", "yaw")], POSE_UNITS,
                                     start=BASE_POSE)   # the operating point
        self.out = np.zeros(9)   # wrench (6), gust, anemometer speed, drag speed
        self.vector("platform_wrench", 6, OUTPUT,
                    [f"wind {n} on the platform at {{P}}'s origin, in {{B}}" for n in
                     ("force x", "force y", "force z", "moment x", "moment y", "moment z")],
                    ("N", "N", "N", "N.m", "N.m", "N.m"), values=self.out[:6])
        self.real("gust", OUTPUT, "along-wind gust u at a point (the wind speed is U + u; the drag sees it averaged "
                  "over the drag area)", "m/s",
                  getter=lambda: self.out.item(6))
        self.real("anemometer_speed", OUTPUT, "along-wind speed U + u_a the anemometer reads: its gust partly "
                  "coherent with the disc's, through its lag", "m/s", getter=lambda: self.out.item(7))
        self.real("drag_speed", OUTPUT, "U + u_A, the speed whose drag the platform takes (the gust averaged over the "
                  "drag area): what no instrument reads, a feedforward's upper bound", "m/s",
                  getter=lambda: self.out.item(8))

    def initialize(self):
        self.model = gust_model(self.settings, self.spectrum, self.seed)
        self.phasors = ffi.new("mb_wind_phasors *")
        lib.mb_wind_phasors_reset(self.phasors)
        self._pose = ffi.from_buffer("double[]", self.base_pose)
        self._wrench = ffi.from_buffer("double[]", self.out)
        self._speeds = ffi.from_buffer("double[]", self.out[6:])   # gust, anemometer speed, drag speed
        self._publish(0.0, 0.0)

    def step(self, t, h):
        self._publish(t + h, h)

    def _publish(self, t, h):
        if lib.mb_wind_sample_stepped(self.model, self.phasors, t, h, self._pose, self._wrench, self._speeds):
            raise InvalidInputError("base pose input contains NaN or inf")

    def extra_state(self):
        return bytes(ffi.buffer(self.phasors))

    def set_extra_state(self, extra):
        ffi.buffer(self.phasors)[:] = extra
