/* Model-side checks the native controllers share (leg_controller_fmu.c, slider_controller_fmu.c),
   declared in model.h: the models' own rules, not an FMI layer's. */
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
