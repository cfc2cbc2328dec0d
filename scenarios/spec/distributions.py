"""Uncertain inputs as files write them: a deviation from the nominal value, its distribution
and its scale in the input's unit, as a drawing writes a tolerance (+-0.1 mm):

    "plant.payload_mass" = { distribution = "normal", sd = "5 kg" }
    leg_offset = { distribution = "uniform", half_width = "0.1 mm" }

``uniform``: the deviation is uniform in +-half_width; ``normal``: zero-mean with standard
deviation sd. A sample maps points u of the unit interval through the inverse distribution
function (``ppf``), so Monte Carlo draws, Sobol (Saltelli) designs and a re-run of one sample
from its seed all take the same path. Used by geometric tolerance budgets and by campaign
samples alike, so both files read the same."""
from dataclasses import dataclass

import numpy as np
from scipy.special import ndtri

from scenarios.spec.text import ScenarioError
from scenarios.spec.units import UnitError, to_si

SCALES = {"uniform": "half_width", "normal": "sd"}   # kind -> the key of its scale


@dataclass(frozen=True)
class Distribution:
    """A zero-mean deviation: ``kind`` (a key of SCALES) and ``scale`` (SI, > 0 or 0 for none)."""

    kind: str
    scale: float

    def ppf(self, u):
        """Deviations at the points ``u`` in (0, 1) (any shape)."""
        u = np.asarray(u, dtype=float)
        if self.kind == "uniform":
            return self.scale * (2.0 * u - 1.0)
        return self.scale * ndtri(u)

    @property
    def std(self):
        """The standard deviation [SI]."""
        return self.scale / np.sqrt(3.0) if self.kind == "uniform" else self.scale

    def salib(self):
        """(dist, bounds) of this input in a SALib problem: 'unif' [-h, h] or 'norm' [0, sd]."""
        return ("unif", [-self.scale, self.scale]) if self.kind == "uniform" else ("norm", [0.0, self.scale])


def parse(source, key, value, dimension=None, error=ScenarioError):
    """The Distribution a file's table ``value`` at ``key`` gives (``source`` and ``key`` name it
    in the ``error`` raised); ``dimension``: the unit its scale must be in (an SI unit, or the
    variable's own)."""
    if not isinstance(value, dict):
        raise error(source, key, f"expected a table like {{ distribution = \"uniform\", half_width = "
                            f"\"0.1 mm\" }}, got {value!r}")
    kind = value.get("distribution")
    if kind not in SCALES:
        raise error(source, key, f"distribution {kind!r} is not one of {', '.join(SCALES)}")
    scale_key = SCALES[kind]
    unknown = sorted(set(value) - {"distribution", scale_key})
    if unknown or scale_key not in value:
        need = f"a {kind} distribution takes exactly '{scale_key}'"
        raise error(source, key, need + (f"; unknown key(s): {', '.join(unknown)}" if unknown else ""))
    try:
        scale = to_si(value[scale_key], dimension)
    except UnitError as e:
        raise error(source, f"{key}.{scale_key}", str(e)) from None
    if scale < 0:
        raise error(source, f"{key}.{scale_key}", f"must be >= 0, got {value[scale_key]!r}")
    return Distribution(kind, scale)
