/* LegController, native: the variables of fmu_src/leg_controller_fmu.py over the
   single-state inverse dynamics of the hexapod kernel (plant/c/hexapod.h) and the PID of
   controller/c/pid.h, with the checks, messages and saturation warning of the Python FMU.
   The eight inputs (reference pose/rate/acc, leg length/rate, base pose/rate/acc) are
   consecutive value references: one NaN/inf check, rows read in place. The disturbance
   observer (observer_bandwidth > 0) is controller/c/observer.h, as in the Python FMU. */
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "LegController_vars.h"
#include "hexapod.h"
#include "observer.h"
#include "pid.h"
#include "wind.h"

typedef struct {
    int base_mode, legs, feedforward_on, saturated;
    double wind_filtered;   /* the wind speed filter's state */
    double observer_mass[36];   /* the observer's leg-space mass matrix (mb_observer_mass) */
    mb_observer_gains gains;    /* the observer's constants for its bandwidth and step (made when they change) */
} Model;

static const char *const INPUT_NAMES[8] = {"reference_pose", "reference_rate", "reference_acc", "leg_length",
                                           "leg_rate", "base_pose", "base_rate", "base_acc"};

/* Wind feedforward (mb_wind_feedforward): the legs' hold of the measured speed's drag, added to ff. */
static int wind_forces(mb_instance *inst, const double *r, Model *m, const double *ref, const double *base,
                       double h, double *ff)
{
    double speed = r[VR_wind_speed], wrench[6], forces[6];
    if (!isfinite(speed)) {
        mb_error(inst, "InvalidInputError", "wind_speed input contains NaN or inf");
        return 1;
    }
    if (r[VR_wind_cutoff] > 0.0)
        speed = m->wind_filtered = mb_wind_speed_filter(m->wind_filtered, speed, r[VR_wind_cutoff], h);
    mb_wind_feedforward(BASE_JOINTS, PLATFORM_JOINTS, KERNEL_DATA, ref, base, r[VR_wind_drag], r[VR_wind_moment_arm],
                        r[VR_wind_direction], speed, r[VR_wind_feedforward], wrench, forces);
    for (int k = 0; k < 6; k++) ff[k] += forces[k];
    return 0;
}

/* The disturbance observer: command = ff - its estimate; advances its state. error is
   reference - measured length, the observer takes measured - reference. */
static int observe(mb_instance *inst, double *r, Model *m, const double *ff, const double *error, double h,
                   double *command)
{
    static const char *const name[1] = {"leg_force_measured"};
    const double *measured = &r[VR_leg_force_measured];
    double gap[6], off[6], state[4 * 6];
    char bad[40];
    if (mb_nonfinite_rows(1, 6, measured, name, bad, sizeof bad)) {
        mb_error(inst, "InvalidInputError", "%s input contains NaN or inf", bad);
        return 1;
    }
    for (int k = 0; k < 6; k++) {
        gap[k] = ff[k] - measured[k];
        off[k] = -error[k];
    }
    memcpy(state, &r[VR_observer_state], sizeof state);
    if (m->gains.bandwidth != r[VR_observer_bandwidth] || m->gains.h != h)
        mb_observer_make_gains(6, r[VR_observer_bandwidth], m->observer_mass, h, &m->gains);
    mb_observer_step(6, &m->gains, state, gap, off, &r[VR_disturbance_estimate], &r[VR_observer_state]);
    for (int k = 0; k < 6; k++) command[k] -= r[VR_disturbance_estimate + k];
    return 0;
}

/* The operating point (start_force not all 0; the Python FMU's _start_holding): start_force
   commanded, its part beyond the feedforward held by the observer's estimate or the integral. */
static int start_holding(mb_instance *inst, double *r, const double *ff)
{
    const double *start = &r[VR_start_force], limit = r[VR_force_limit];
    double hold[6], largest = 0.0;
    int any = 0;
    for (int k = 0; k < 6; k++) {
        any |= start[k] != 0.0;
        hold[k] = start[k] - ff[k];
        largest = fabs(hold[k]) > largest ? fabs(hold[k]) : largest;
    }
    if (!any) return 0;
    for (int k = 0; k < 6; k++) {
        if (r[VR_observer_bandwidth] > 0.0 && r[VR_observer_on_time] <= 0.0) {
            r[VR_disturbance_estimate + k] = r[VR_observer_state + MB_OBSERVER_STATES * k] = -hold[k];
            r[VR_integral + k] = 0.0;
        } else if (r[VR_ki] > 0.0) {
            r[VR_integral + k] = hold[k] / r[VR_ki];
        } else {
            mb_error(inst, "InvalidInputError", "start_force needs an integral gain ki > 0 (or the observer) to "
                     "hold %.6g N beyond the feedforward; ki is 0", largest);
            return 1;
        }
        r[VR_leg_force + k] = start[k] < -limit ? -limit : (start[k] > limit ? limit : start[k]);
    }
    return 0;
}

/* Forces from the inputs now (a step from t); the integral advances only on a real step (h > 0 given);
   the observer acts from observer_on_time on. */
static int update(mb_instance *inst, double *r, Model *m, int stepping, double t, double h)
{
    const double *in = &r[VR_reference_pose];
    char bad[160];
    if (mb_nonfinite_rows(8, 6, in, INPUT_NAMES, bad, sizeof bad)) {
        mb_error(inst, "InvalidInputError", "%s input contains NaN or inf", bad);
        return 1;
    }
    const double *ref = in, *ref_rate = in + 6, *ref_acc = in + 12, *lengths = in + 18, *rates = in + 24;
    const double *base = in + 30;
    double ff[6], ref_lengths[6], ref_rates[6];
    double det = mb_hexapod_inverse_dynamics(BASE_JOINTS, PLATFORM_JOINTS, KERNEL_DATA, ref, ref_rate, ref_acc,
                                             base, base + 6, base + 12, m->base_mode, m->legs, ff, ref_lengths,
                                             ref_rates);
    if (fabs(det) < SINGULAR_RATIO * HOME_DET) {
        mb_error(inst, "SingularConfigurationError", "singular configuration: |det J| is %.2e of its home value (< %s)",
                 fabs(det) / HOME_DET, SINGULAR_RATIO_TEXT);
        return 1;
    }
    if (!m->feedforward_on) memset(ff, 0, sizeof ff);
    if (r[VR_wind_feedforward] != 0.0 && wind_forces(inst, r, m, ref, base, stepping ? h : -1.0, ff)) return 1;
    double *forces = &r[VR_leg_force], *integral = &r[VR_integral];
    if (!stepping) {
        double off[6];
        for (int k = 0; k < 6; k++) off[k] = lengths[k] - ref_lengths[k];
        memcpy(forces, ff, sizeof ff);
        mb_observer_start(6, off, &r[VR_observer_state]);
        if (start_holding(inst, r, ff)) return 1;
    } else {
        double error[6], error_rate[6], new_integral[6];
        for (int k = 0; k < 6; k++) {
            error[k] = ref_lengths[k] - lengths[k];
            error_rate[k] = ref_rates[k] - rates[k];
        }
        double command[6];
        memcpy(command, ff, sizeof ff);
        if (r[VR_observer_bandwidth] > 0.0 && t >= r[VR_observer_on_time]) {
            if (observe(inst, r, m, ff, error, h, command)) return 1;
        } else if (r[VR_observer_bandwidth] > 0.0) {   /* not on yet: at rest, its length history current */
            double off[6];
            for (int k = 0; k < 6; k++) off[k] = -error[k];
            mb_observer_start(6, off, &r[VR_observer_state]);
        }
        mb_pid_update(r[VR_kp], r[VR_ki], r[VR_kd], r[VR_force_limit], 6, integral, error, error_rate, command, h,
                      forces, new_integral);
        memcpy(integral, new_integral, sizeof new_integral);
    }
    memcpy(&r[VR_feedforward_force], ff, sizeof ff);
    return 0;
}

static int init(mb_instance *inst, double *r, int *i, void *model, double start_time)
{
    (void)start_time;
    Model *m = model;
    int mode = i[VR_feedforward];
    if (mode < 0 || mode >= N_FEEDFORWARD_NAMES) {
        mb_error(inst, "IndexError", "feedforward %d is not one of 0..%d", mode, N_FEEDFORWARD_NAMES - 1);
        return 1;
    }
    if (mb_check_pid_gains(inst, r[VR_kp], r[VR_ki], r[VR_kd], r[VR_force_limit]))
        return 1;
    int observer_model = i[VR_observer_model];
    if (observer_model < 0 || observer_model >= N_OBSERVER_MODEL_NAMES) {
        mb_error(inst, "IndexError", "observer_model %d is not one of 0..%d", observer_model, N_OBSERVER_MODEL_NAMES - 1);
        return 1;
    }
    mb_observer_mass(6, observer_model, r[VR_observer_mass], LEG_MASS_HOME, m->observer_mass);
    m->gains.bandwidth = m->gains.h = NAN;   /* made at the first step, for the mass made here */
    int fidelity = FEEDFORWARD_FIDELITY[mode];
    m->base_mode = FIDELITY_BASE_MODE[fidelity];
    m->legs = FIDELITY_LEGS[fidelity];
    m->feedforward_on = mode != FEEDFORWARD_NONE;
    m->saturated = 0;
    return update(inst, r, m, 0, 0.0, 0.0);
}

static int step(mb_instance *inst, double *r, int *i, void *model, double t, double h)
{
    (void)i;
    Model *m = model;
    if (update(inst, r, m, 1, t, h)) return 1;
    const double *forces = &r[VR_leg_force], limit = r[VR_force_limit];
    char legs[32] = "";
    size_t used = 0;
    int saturated = 0;
    for (int k = 0; k < 6; k++) {
        if (fabs(forces[k]) >= limit) {
            used += (size_t)snprintf(legs + used, sizeof legs - used, "%s%d", saturated ? ", " : "", k + 1);
            saturated = 1;
        }
    }
    if (saturated && !m->saturated)   /* say so once per episode: an unstable loop saturates quietly */
        mb_warning(inst, "leg forces saturated at +-%g N at t=%.6g s (legs %s)", limit, t + h, legs);
    m->saturated = saturated;
    return 0;
}

const mb_model_info MB_MODEL = {MB_IDENTIFIER, MB_GUID, MB_NVARS, MB_VARS, sizeof(Model), 0, init, step};
