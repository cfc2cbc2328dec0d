/* SliderController, native: the variables of fmu_src/slider_controller_fmu.py over the 3T
   kernel's reference and feedforward (plant/c/mechanism3t.h, mb_m3t_reference_forces) and
   the PID of controller/c/pid.h, with the Python FMU's checks and messages. */
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "SliderController_vars.h"
#include "m3t_status.h"
#include "pid.h"

/* Reference, feedforward and forces at t; the integral advances only on a real step. */
static int update(mb_instance *inst, double *r, int *i, double t, int stepping, double h)
{
    char buf[32];
    double ref[3], ref_rate[3], ref_acc[3], ff[3];
    int mode = i[VR_mode];
    int status = mb_m3t_reference_forces(PACKED, t, &r[VR_initial_position], r[VR_amplitude], r[VR_omega], mode, ref,
                                         ref_rate, ref_acc, ff);
    if (!i[VR_feedforward]) {
        memset(ff, 0, sizeof ff);
    } else if (status) {
        m3t_fail(inst, status, mode);
        return 1;
    }
    double limit = r[VR_force_limit], *forces = &r[VR_slider_force];
    if (!stepping) {
        for (int k = 0; k < 3; k++) forces[k] = ff[k] < -limit ? -limit : (ff[k] > limit ? limit : ff[k]);
    } else {
        const double *measured = &r[VR_slider_position];   /* slider_position (3), slider_rate (3) */
        for (int k = 0; k < 6; k++) {
            if (!isfinite(measured[k])) {
                mb_error(inst, "InvalidInputError", "measured slider position/rate input contains NaN or inf: "
                         "[[%g %g %g] [%g %g %g]]", measured[0], measured[1], measured[2], measured[3], measured[4],
                         measured[5]);
                return 1;
            }
        }
        if (!(isfinite(h) && h > 0)) {
            mb_error(inst, "ValueError", "time step must be finite and > 0, got %s", mb_repr(h, buf));
            return 1;
        }
        double error[3], error_rate[3], new_integral[3], *integral = &r[VR_integral];
        for (int k = 0; k < 3; k++) {
            error[k] = ref[k] - measured[k];
            error_rate[k] = ref_rate[k] - measured[3 + k];
        }
        mb_pid_update(r[VR_kp], r[VR_ki], r[VR_kd], limit, 3, integral, error, error_rate, ff, h, forces,
                      new_integral);
        memcpy(integral, new_integral, sizeof new_integral);
    }
    memcpy(&r[VR_reference_position], ref, sizeof ref);
    memcpy(&r[VR_reference_rate], ref_rate, sizeof ref_rate);
    memcpy(&r[VR_feedforward_force], ff, sizeof ff);
    return 0;
}

static const char *const SLIDERS[3] = {"x_A2", "y_A1", "y_A3"};

typedef struct {
    int saturated;
} Model;

static int init(mb_instance *inst, double *r, int *i, void *model, double start_time)
{
    ((Model *)model)->saturated = 0;
    if (i[VR_feedforward] != 0 && i[VR_feedforward] != 1) {
        mb_error(inst, "InvalidInputError", "feedforward must be 0 (off) or 1 (on), got %d", i[VR_feedforward]);
        return 1;
    }
    if (mb_check_pid_gains(inst, r[VR_kp], r[VR_ki], r[VR_kd], r[VR_force_limit]))
        return 1;
    memset(&r[VR_integral], 0, 3 * sizeof(double));
    return update(inst, r, i, start_time, 0, 0.0);
}

/* A step, then the Python FMU's saturation warning, once per episode as the leg controller says it. */
static int step(mb_instance *inst, double *r, int *i, void *model, double t, double h)
{
    Model *m = model;
    if (update(inst, r, i, t, 1, h)) return 1;
    const double *forces = &r[VR_slider_force], limit = r[VR_force_limit];
    char sliders[32] = "";
    size_t used = 0;
    int saturated = 0;
    for (int k = 0; k < 3; k++) {
        if (fabs(forces[k]) >= limit) {
            used += (size_t)snprintf(sliders + used, sizeof sliders - used, "%s%s", saturated ? ", " : "", SLIDERS[k]);
            saturated = 1;
        }
    }
    if (saturated && !m->saturated)
        mb_warning(inst, "slider forces saturated at +-%g N at t=%.6g s (sliders %s)", limit, t + h, sliders);
    m->saturated = saturated;
    return 0;
}

/* the integral is an output; the model keeps whether the forces were saturated (one warning per episode) */
const mb_model_info MB_MODEL = {MB_IDENTIFIER, MB_GUID, MB_NVARS, MB_VARS, sizeof(Model), 0, init, step};
