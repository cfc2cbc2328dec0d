/* Mechanism3TPlant, native: the variables of fmu_src/mechanism3t_plant_fmu.py over the 3T
   kernel (plant/c/mechanism3t.h, mb_m3t_plant_step), with the Python FMU's checks and
   messages. The state (slider_position, slider_rate) is the output variables themselves
   (consecutive value references), advanced in place; the layer restores it if a step
   fails. Radau needs scipy: the native plant refuses it at initialization. */
#include <math.h>
#include <string.h>

#include "Mechanism3TPlant_vars.h"
#include "m3t_status.h"

typedef struct {
    int rk4, mode;
    double max_step;
} Model;

static int init(mb_instance *inst, double *r, int *i, void *model, double start_time)
{
    (void)start_time;
    Model *m = model;
    int integrator = i[VR_integrator];
    m->max_step = r[VR_max_step];
    if (mb_check_integrator(inst, "Mechanism3TPlant", integrator, N_INTEGRATOR_NAMES, INTEGRATOR_RADAU, m->max_step))
        return 1;
    m->rk4 = integrator == INTEGRATOR_RK4;
    m->mode = i[VR_mode];
    if (m->mode != 1 && m->mode != -1) {
        m3t_fail(inst, MB_M3T_BAD_MODE, m->mode);
        return 1;
    }
    double *x = &r[VR_slider_position], xdot[6];
    memcpy(x, &r[VR_initial_position], 3 * sizeof(double));
    memcpy(x + 3, &r[VR_initial_rate], 3 * sizeof(double));
    int status = mb_m3t_position(PACKED, x, m->mode, &r[VR_platform_position]);
    if (!status) status = mb_m3t_rhs(PACKED, x, &r[VR_slider_force], m->mode, xdot);   /* refuse singular starts, NaN forces */
    if (status) {
        m3t_fail(inst, status, m->mode);
        return 1;
    }
    return 0;
}

static int step(mb_instance *inst, double *r, int *i, void *model, double t, double h)
{
    (void)i;
    Model *m = model;
    int substeps;
    if (mb_substeps(inst, h, m->max_step, &substeps)) return 1;
    int status = mb_m3t_plant_step(PACKED, &r[VR_slider_position], &r[VR_slider_force], m->mode, m->rk4, substeps,
                                   h / substeps, &r[VR_platform_position]);
    if (status == MB_M3T_DIVERGED) {
        mb_error(inst, "ConvergenceError", "integrator %s diverged over [%.6g, %.6g] s (substep %.3g s): "
                 "state is no longer finite", INTEGRATOR_NAMES[m->rk4 ? INTEGRATOR_RK4 : INTEGRATOR_EULER], t, t + h,
                 h < m->max_step ? h : m->max_step);
        return 1;
    }
    if (status) {
        m3t_fail(inst, status, m->mode);
        return 1;
    }
    return 0;
}

const mb_model_info MB_MODEL = {MB_IDENTIFIER, MB_GUID, MB_NVARS, MB_VARS, sizeof(Model), 0, init, step};
