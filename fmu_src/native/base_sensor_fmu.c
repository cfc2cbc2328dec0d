/* BaseSensor, native: the variables of fmu_src/base_sensor_fmu.py over the base-estimate
   kernel (plant/c/base_estimate.h; named apart from this file, as the FMU's sources/ are
   flat): the same calls in the same order, so the two agree bit for bit; the kernel's
   state (the generator's 8 bytes with it) lives in the Model, saved with the FMU state. */
#include <math.h>
#include <string.h>

#include "BaseSensor_vars.h"
#include "base_estimate.h"

typedef struct {
    mb_bs_params params;
    mb_bs_state state;
} Model;

static int init(mb_instance *inst, double *r, int *i, void *model, double start_time)
{
    (void)start_time;
    Model *m = model;
    mb_bs_params *p = &m->params;
    p->source = i[VR_source];
    p->encoder_resolution = r[VR_encoder_resolution];
    p->rate_cutoff = r[VR_rate_cutoff];
    p->gyro_noise_density = r[VR_gyro_noise_density];
    p->gyro_bias = r[VR_gyro_bias];
    p->accel_noise_density = r[VR_accel_noise_density];
    p->accel_bias = r[VR_accel_bias];
    p->lever_arm = r[VR_lever_arm];
    for (int k = 0; k < 3; k++) p->imu_alignment[k] = r[VR_imu_alignment + k];
    if (mb_bs_check(p)) {
        mb_error(inst, "InvalidInputError", "BaseSensor parameters must be finite, the densities, resolution, "
                 "cut-off and lever arm >= 0, source 0 or 1");
        return 1;
    }
    mb_bs_start(p, (unsigned long long)i[VR_seed], &r[VR_axis], &r[VR_axis_rate], &r[VR_true_base_pose],
                &r[VR_true_base_rate], &r[VR_true_base_acc], &m->state, &r[VR_base_pose]);
    return 0;
}

/* base_sensor_fmu.py INPUTS: the inputs in value-reference order. */
static const char *const INPUT_NAMES[5] = {"axis", "axis_rate", "true_base_pose", "true_base_rate", "true_base_acc"};
static const int INPUT_SIZES[5] = {2, 2, 6, 6, 6};

static int step(mb_instance *inst, double *r, int *i, void *model, double t, double h)
{
    (void)i; (void)t;
    Model *m = model;
    char bad[160] = "";
    const double *v = &r[VR_axis];
    for (int k = 0, at = 0; k < 5; at += INPUT_SIZES[k++]) {
        int finite = 1;
        for (int j = 0; j < INPUT_SIZES[k]; j++) finite &= isfinite(v[at + j]) != 0;
        if (!finite) {
            if (bad[0]) strcat(bad, ", ");
            strcat(bad, INPUT_NAMES[k]);
        }
    }
    if (bad[0]) {
        mb_error(inst, "InvalidInputError", "inputs must be finite: %s", bad);
        return 1;
    }
    mb_bs_step(&m->params, h, &r[VR_axis], &r[VR_true_base_pose], &r[VR_true_base_rate], &r[VR_true_base_acc],
               &m->state, &r[VR_base_pose]);
    return 0;
}

const mb_model_info MB_MODEL = {MB_IDENTIFIER, MB_GUID, MB_NVARS, MB_VARS, sizeof(Model), 0, init, step};
