"""The operating point every FMU's inputs start at, so that a host's first step is valid
with no initial exchange and a plain ``fmpy.simulate_fmu`` of any FMU runs a sensible
second: the telescope at rest at Telescope's default start pointing (azimuth 0,
elevation 30 deg), the hexapod platform at home on that base, held still by the static
leg forces; the 3T mechanism at its paper configuration, held by its static slider forces.
The numbers come from the plant models (inverse dynamics at zero rate and acceleration),
not from a table.
"""
import numpy as np

from plant.hexapod.model import HOME_POSE, StewartParams, inverse_dynamics
from plant.mechanism3t import kernel as mechanism3t_kernel
from plant.mechanism3t.model import MM, PAPER_REFERENCE_RHO_MM, Mechanism3TParams
from plant.telescope import model as telescope

START_AZ_EL = (0.0, float(np.radians(30.0)))   # Telescope's default slew start (rad)


def _telescope_at_rest():
    """Telescope's outputs (its 60, in its order) at t = 0 with its default parameters."""
    profile = telescope.motion_profile("slew", START_AZ_EL, START_AZ_EL)
    return telescope.fmu_outputs(telescope.TelescopeParams.tianma(), profile, [0.0])[0]


_ROW = _telescope_at_rest()
BASE_POSE = _ROW[0:6]          # {B} in {W}; its rate and acceleration are 0 at rest
AXIS = _ROW[36:38]             # astronomical azimuth, elevation
# leg forces holding the platform still at home on the tilted base (full model, + extends)
STATIC_LEG_FORCES = inverse_dynamics(StewartParams.paper(), HOME_POSE, np.zeros(6), np.zeros(6), BASE_POSE,
                                     np.zeros(6), np.zeros(6))
SLIDER_POSITION = np.array(PAPER_REFERENCE_RHO_MM) * MM
# slider forces holding the 3T mechanism still there (assembly mode +1, the paper's)
STATIC_SLIDER_FORCES = mechanism3t_kernel.slider_forces(Mechanism3TParams.paper(), SLIDER_POSITION, np.zeros(3),
                                                        np.zeros(3))
