/* LegSensor, native: the variables of fmu_src/leg_sensor_fmu.py over the sensor kernel
   (plant/c/sensors.h); the model state is the kernel's struct (noise generator included),
   saved by the FMI layer as bytes. leg_length, measured_length and estimated_rate are
   vectors of consecutive value references, read and written in place. */
#include "LegSensor_vars.h"
#include "sensors.h"

typedef struct {
    mb_sensor sensor;
    double sensed[6];   /* l + scale_error (l - l_home): the true length as the encoder's scale sees it */
} Model;

static void sense(const double *r, Model *m)
{
    for (int j = 0; j < 6; j++) {
        double l = r[VR_leg_length + j];
        m->sensed[j] = l + r[VR_scale_error + j] * (l - HOME_LENGTHS[j]);
    }
}

static int init(mb_instance *inst, double *r, int *i, void *model, double start_time)
{
    (void)inst;
    (void)start_time;
    Model *m = model;
    sense(r, m);
    mb_sensor_start(&m->sensor, (unsigned long long)i[VR_seed], 6, r[VR_resolution], r[VR_noise], m->sensed,
                    &r[VR_measured_length], &r[VR_estimated_rate]);
    return 0;
}

static int step(mb_instance *inst, double *r, int *i, void *model, double t, double h)
{
    (void)inst;
    (void)t;
    Model *m = model;
    sense(r, m);
    mb_sensor_sample(&m->sensor, 6, r[VR_resolution], r[VR_noise], r[VR_rate_cutoff], i[VR_delay_steps], h,
                     m->sensed, &r[VR_measured_length], &r[VR_estimated_rate]);
    return 0;
}

const mb_model_info MB_MODEL = {MB_IDENTIFIER, MB_GUID, MB_NVARS, MB_VARS, sizeof(Model), 0, init, step};
