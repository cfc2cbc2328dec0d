#ifndef MB_M3T_STATUS_H
#define MB_M3T_STATUS_H
/* The error the Python 3T FMUs report for a kernel status (plant.mechanism3t.kernel.
   raise_status): exception class and message, for mb_error. */
#include "mechanism3t.h"
#include "model.h"

static void m3t_fail(mb_instance *inst, int status, int mode)
{
    const char *sign = mode > 0 ? "+" : "-";
    switch (status) {
    case MB_M3T_BAD_RHO: mb_error(inst, "InvalidInputError", "rho contains NaN or inf"); break;
    case MB_M3T_BAD_RHO_DOT: mb_error(inst, "InvalidInputError", "rho_dot contains NaN or inf"); break;
    case MB_M3T_BAD_FORCE: mb_error(inst, "InvalidInputError", "slider forces contains NaN or inf"); break;
    case MB_M3T_BAD_RHO_DDOT: mb_error(inst, "InvalidInputError", "rho_ddot contains NaN or inf"); break;
    case MB_M3T_BAD_MODE:
        mb_error(inst, "InvalidInputError", "mode must be +1 or -1 (sign before the eq. 11 square root), got %d", mode);
        break;
    case MB_M3T_SING_SIN:
        mb_error(inst, "SingularConfigurationError", "output singularity (paper 3.3, f33 = 0): sin theta = 0, "
                 "D3C3 perpendicular to B3C3");
        break;
    case MB_M3T_SING_W:
        mb_error(inst, "SingularConfigurationError", "output singularity (paper 3.3, f33 = 0): "
                 "x - e + a + l4 cos theta = 0, E3 and C3 share x");
        break;
    case MB_M3T_SING_LIMB1:
        mb_error(inst, "SingularConfigurationError", "limb I fully stretched or folded (|BD| = l2 +- l3)");
        break;
    case MB_M3T_SING_LIMB2:
        mb_error(inst, "SingularConfigurationError", "limb II fully stretched or folded (|BD| = l2 +- l3)");
        break;
    case MB_M3T_SING_MASS:
        mb_error(inst, "SingularConfigurationError", "mass matrix singular: no slider accelerations solve "
                 "M rho_ddot = F - bias");
        break;
    case MB_M3T_UNREACH_D3E3:
        mb_error(inst, "UnreachableError", "eq. 10-11: l6^2 - (y_A1 + d - y_A3)^2 < 0 (D3E3 too short for the y offset)");
        break;
    case MB_M3T_UNREACH_ARCCOS:
        mb_error(inst, "UnreachableError", "eq. 11: arccos argument (N3 %s sqrt(l6^2 - N4^2))/l4 outside [-1, 1]", sign);
        break;
    case MB_M3T_UNREACH_LIMB1:
        mb_error(inst, "UnreachableError", "limb I cannot close: eq. 8 square root negative "
                 "(|B1D1| outside [|l2 - l3|, l2 + l3])");
        break;
    case MB_M3T_UNREACH_LIMB2:
        mb_error(inst, "UnreachableError", "limb II cannot close: eq. 8 square root negative "
                 "(|B2D2| outside [|l2 - l3|, l2 + l3])");
        break;
    default: mb_error(inst, "PlantError", "3T kernel status %d", status);
    }
}

#endif
