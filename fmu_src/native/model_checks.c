/* Model-side checks the native model files share, declared in model.h: the models' own
   rules, not an FMI layer's. The controllers' gains (leg_controller_fmu.c,
   slider_controller_fmu.c) and the plants' integrator (hexapod_plant_fmu.c,
   mechanism3t_plant_fmu.c). */
#include <math.h>

#include "model.h"

int mb_check_pid_gains(mb_instance *inst, double kp, double ki, double kd, double force_limit)
{
    static const char *const names[3] = {"kp", "ki", "kd"};
    const double gains[3] = {kp, ki, kd};
    char buf[32];
    for (int k = 0; k < 3; k++) {
        if (!(isfinite(gains[k]) && gains[k] >= 0)) {
            mb_error(inst, "ValueError", "gain %s must be finite and >= 0, got %s", names[k], mb_repr(gains[k], buf));
            return 1;
        }
    }
    if (!(isfinite(force_limit) && force_limit > 0)) {
        mb_error(inst, "ValueError", "force_limit must be finite and > 0, got %s", mb_repr(force_limit, buf));
        return 1;
    }
    return 0;
}

int mb_check_integrator(mb_instance *inst, const char *model, int integrator, int n_integrators, int radau,
                        double max_step)
{
    char buf[32];
    if (integrator < 0 || integrator >= n_integrators) {
        mb_error(inst, "InvalidInputError", "integrator index %d is not one of 0..%d (rk4, euler, radau)", integrator,
                 n_integrators - 1);
        return 1;
    }
    if (integrator == radau) {
        mb_error(inst, "InvalidInputError", "integrator radau needs the python implementation (scipy's Radau); "
                 "the native %s has rk4 and euler", model);
        return 1;
    }
    if (!(max_step > 0)) {
        mb_error(inst, "InvalidInputError", "max_step must be positive, got %s", mb_repr(max_step, buf));
        return 1;
    }
    return 0;
}
