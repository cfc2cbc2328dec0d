/* The monolithic loop of a telescope + HexapodPlant + LegController co-simulation: the
   kernels the native FMUs run (plant/c telescope and hexapod, controller/c pid), stepped
   in one C loop with no FMI in between. It makes the calls and floating-point operations
   of the Jacobi master (scenarios/cosim/c/cosim.c, linear extrapolation optional) and of the
   three model files (fmu_src/native/telescope_fmu.c, hexapod_plant_fmu.c, leg_controller_fmu.c)
   in their order, so its leg lengths equal the co-simulation's bit for bit
   (tests/scenarios/cosim/test_monolithic.py): what is left between the two is the cost of FMI itself
   (benchmarks/bench_native.py prints the ratio). Error messages and the controller's
   saturation warning are left out; the checks that stop a run are kept. */
#include <math.h>
#include <string.h>

#include "hexapod.h"
#include "pid.h"
#include "telescope.h"

/* Exchange vector y: the connected outputs, as the master keeps them. */
enum { Y_BASE = 0, Y_REF = 18, Y_LENGTH = 36, Y_RATE = 42, Y_FORCE = 48, NY = 54 };

static int finite_all(const double *x, int n)
{
    for (int k = 0; k < n; k++)
        if (!isfinite(x[k])) return 0;
    return 1;
}

/* u, or its linear extrapolation u + (u - u_prev) / 2 (cosim.c write_inputs). */
static void feed(double *to, const double *y, const double *y_prev, int from, int n, int extrapolate)
{
    for (int j = 0; j < n; j++) {
        double u = y[from + j];
        if (extrapolate) u = u + 0.5 * (u - y_prev[from + j]);
        to[j] = u;
    }
}

/* The telescope's 60-double row at t after a step of h, time formed as telescope_fmu.c
   publish does; its six output vectors copied into y. */
static int telescope(const mb_tel_params *p, const mb_tel_profile *prof, const int *rows, int block,
                     double *block_t, double *block_h, double t, double h, double *y)
{
    double index = -1.0, row[60];
    int first_bad = -1;
    if (*block_h == h && h > 0) index = nearbyint((t - *block_t) / *block_h);
    if (!(index >= 0 && index < block && fabs(*block_t + index * h - t) <= 1e-9 * (fabs(t) > 1.0 ? fabs(t) : 1.0))) {
        *block_t = t;
        *block_h = h;
        index = 0.0;
    }
    double time = *block_t + h * index;
    if (mb_tel_fmu_rows_full(p, prof, 1, &time, row, &first_bad)) return 1;
    for (int v = 0; v < 6; v++) memcpy(y + Y_BASE + 6 * v, row + rows[v], 6 * sizeof(double));
    return 0;
}

/* hexapod_plant_fmu.c advance: x over [t0, t0 + h]; leg lengths and rates into y. */
static int plant(const double *hex, const double *act, const double *bounds, double max_step, int rk4,
                 int base_mode, int legs, double singular, double *x, const double *inputs, double t0, double h,
                 double *y)
{
    double n = ceil(h / max_step - 1e-9), outputs[24], det = 0.0;
    int substeps = n > 1 ? (int)n : 1;
    int status = mb_hexapod_advance_actuated(rk4, substeps, hex, hex + 18, hex + 36, act, x, inputs, t0, h,
                                             base_mode, legs, bounds, outputs, &det);
    if (status != MB_HEXAPOD_OK || !(det >= singular)) return 1;
    memcpy(y + Y_LENGTH, outputs, 12 * sizeof(double));
    return 0;
}

/* leg_controller_fmu.c update: the feedforward, and the PID with its integral on a step. */
static int controller(const double *hex, const double *gains, int base_mode, int legs, int feedforward,
                      double singular, const double *in, int stepping, double h, double *integral, double *y)
{
    double ff[6], ref_lengths[6], ref_rates[6];
    if (!finite_all(in, 48)) return 1;
    double det = mb_hexapod_inverse_dynamics(hex, hex + 18, hex + 36, in, in + 6, in + 12, in + 30, in + 36, in + 42,
                                             base_mode, legs, ff, ref_lengths, ref_rates);
    if (fabs(det) < singular) return 1;
    if (!feedforward) memset(ff, 0, sizeof ff);
    if (!stepping) {
        memcpy(y + Y_FORCE, ff, sizeof ff);
        return 0;
    }
    double error[6], error_rate[6], new_integral[6];
    for (int k = 0; k < 6; k++) {
        error[k] = ref_lengths[k] - in[18 + k];
        error_rate[k] = ref_rates[k] - in[24 + k];
    }
    mb_pid_update(gains[0], gains[1], gains[2], gains[3], 6, integral, error, error_rate, ff, h, y + Y_FORCE,
                  new_integral);
    memcpy(integral, new_integral, sizeof new_integral);
    return 0;
}

/* Initialise as scenarios/cosim/master.py start does (telescope, plant, controller), then run
   `steps` macro steps of h from t = 0. Returns the macro steps completed (steps, or the
   one a check stopped at; -1 when initialization failed).
   hex (50)        base_joints (18), platform_joints (18), kernel data (MB_HEXAPOD_NDATA)
   plant (37)      actuator (MB_ACTUATOR_NDATA), bounds (12), max_step, the leg_force and
                   platform_wrench start values (6 + 6), initial_pose (6)
   plant_modes (3) rk4, base_mode, legs
   gains (10)      kp, ki, kd, force_limit, integral start (6)
   ctrl_modes (3)  base_mode, legs, feedforward on
   tel (38)        mb_tel_params in field order (17), mb_tel_profile's doubles in field order (21)
   tel_modes (8)   profile kind, BLOCK, then where base_pose, base_rate, base_acc,
                   reference_pose, reference_rate, reference_acc start in the 60-double row
   singular        SINGULAR_RATIO * HOME_DET [m^3]
   lengths         (steps + 1, 6) leg lengths after initialization and every step, or NULL */
long mb_monolithic(const double *hex, const double *plant_data, const int *plant_modes, const double *gains,
                   const int *ctrl_modes, const double *tel, const int *tel_modes, double singular, double h,
                   long steps, int extrapolate, double *lengths)
{
    mb_tel_params p;
    mb_tel_profile prof;
    memcpy(&p.latitude, tel, 11 * sizeof(double));
    memcpy(p.home, tel + 11, 6 * sizeof(double));
    prof.kind = tel_modes[0];
    memcpy(&prof.start_az, tel + 17, 9 * sizeof(double));
    memcpy(prof.ref_start, tel + 26, 6 * sizeof(double));
    memcpy(prof.ref_stop, tel + 32, 6 * sizeof(double));
    if (mb_tel_check_params(&p)) return -1;

    const double *act = plant_data, *bounds = plant_data + 6, max_step = plant_data[18];
    double x[18] = {0}, integral[6], y[NY], y_prev[NY], plant_in[30], ctrl_in[48];
    double block_t = INFINITY, block_h = 0.0;
    const int rk4 = plant_modes[0], p_base = plant_modes[1], p_legs = plant_modes[2];
    const int c_base = ctrl_modes[0], c_legs = ctrl_modes[1], ff_on = ctrl_modes[2];
    memcpy(integral, gains + 4, sizeof integral);

    if (telescope(&p, &prof, tel_modes + 2, tel_modes[1], &block_t, &block_h, 0.0, 0.0, y)) return -1;
    memcpy(x, plant_data + 31, 6 * sizeof(double));
    memcpy(plant_in, plant_data + 19, 6 * sizeof(double));           /* leg_force: its start value */
    memcpy(plant_in + 6, y + Y_BASE, 18 * sizeof(double));
    memcpy(plant_in + 24, plant_data + 25, 6 * sizeof(double));      /* platform_wrench */
    if (act[MB_ACT_BANDWIDTH] > 0)
        for (int leg = 0; leg < 6; leg++) {
            double f = plant_in[leg], limit = act[MB_ACT_FORCE_LIMIT];
            x[12 + leg] = limit > 0 ? (f > limit ? limit : (f < -limit ? -limit : f)) : f;
        }
    if (plant(hex, act, bounds, max_step, rk4, p_base, p_legs, singular, x, plant_in, 0.0, 0.0, y)) return -1;
    memcpy(ctrl_in, y + Y_REF, 18 * sizeof(double));
    memcpy(ctrl_in + 18, y + Y_LENGTH, 12 * sizeof(double));
    memcpy(ctrl_in + 30, y + Y_BASE, 18 * sizeof(double));
    if (controller(hex, gains, c_base, c_legs, ff_on, singular, ctrl_in, 0, 0.0, integral, y)) return -1;
    if (lengths) memcpy(lengths, y + Y_LENGTH, 6 * sizeof(double));
    memcpy(y_prev, y, sizeof y);

    for (long k = 0; k < steps; k++) {
        double t = (double)k * h;
        int ex = extrapolate && k;
        feed(plant_in, y, y_prev, Y_FORCE, 6, ex);
        feed(plant_in + 6, y, y_prev, Y_BASE, 18, ex);
        feed(ctrl_in, y, y_prev, Y_REF, 18, ex);
        feed(ctrl_in + 18, y, y_prev, Y_LENGTH, 12, ex);
        feed(ctrl_in + 30, y, y_prev, Y_BASE, 18, ex);
        memcpy(y_prev, y, sizeof y);
        if (telescope(&p, &prof, tel_modes + 2, tel_modes[1], &block_t, &block_h, t + h, h, y)
            || plant(hex, act, bounds, max_step, rk4, p_base, p_legs, singular, x, plant_in, t, h, y)
            || controller(hex, gains, c_base, c_legs, ff_on, singular, ctrl_in, 1, h, integral, y))
            return k;
        if (lengths) memcpy(lengths + 6 * (k + 1), y + Y_LENGTH, 6 * sizeof(double));
    }
    return steps;
}
