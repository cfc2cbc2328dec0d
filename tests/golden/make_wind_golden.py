"""tests/golden/wind_kernel.npz: the Wind kernel's gust, area gust and wrench as they were
before the anemometer (run once with the tree before it, from its root:
``python tests/golden/make_wind_golden.py tests/golden/wind_kernel.npz``); the anemometer's
draws come after these, so tests/plant/test_anemometer.py finds them unchanged bit for bit."""
import sys

import numpy as np

from fmu_src.wind_fmu import DEFAULTS, gust_model, gusts
from plant._kernel import ffi, lib

times = np.linspace(0.0, 60.0, 401)
pose = np.array([0.1, -0.2, 25.0, 0.01, 0.52, 0.3])
out = {"times": times, "base_pose": pose}
for spectrum in (0, 1):
    for seed in (0, 7):
        m = gust_model(DEFAULTS, spectrum, seed)
        key = f"s{spectrum}_seed{seed}"
        out[key + "_gust"] = gusts(m, times)
        out[key + "_area"] = gusts(m, times, area=True)
        w, g = np.empty((times.size, 6)), np.empty(1)
        for i, t in enumerate(times):
            lib.mb_wind_wrench(m, t, ffi.from_buffer("double[]", pose), ffi.from_buffer("double[]", w[i]),
                               ffi.from_buffer("double[]", g))
        out[key + "_wrench"] = w
np.savez_compressed(sys.argv[1], **out)
