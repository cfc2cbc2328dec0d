/* LegSensor, native: the variables of fmu_src/leg_sensor_fmu.py over the sensor kernel
   (plant/c/sensors.h); the model state is the kernel's struct (noise generator included),
   saved by the FMI layer as bytes. leg_length, measured_length and estimated_rate are
   vectors of consecutive value references, read and written in place. */
#include "LegSensor_vars.h"
#include "sensors.h"

typedef struct {
    mb_sensor sensor;
} Model;

static int init(mb_instance *inst, double *r, int *i, void *model, double start_time)
{
    (void)inst;
    (void)start_time;
    Model *m = model;
    mb_sensor_start(&m->sensor, (unsigned long long)i[VR_seed], 6, r[VR_resolution], r[VR_noise], &r[VR_leg_length],
                    &r[VR_measured_length], &r[VR_estimated_rate]);
    return 0;
}

static int step(mb_instance *inst, double *r, int *i, void *model, double t, double h)
{
    (void)inst;
    (void)t;
    Model *m = model;
    mb_sensor_sample(&m->sensor, 6, r[VR_resolution], r[VR_noise], r[VR_rate_cutoff], i[VR_delay_steps], h,
                     &r[VR_leg_length], &r[VR_measured_length], &r[VR_estimated_rate]);
    return 0;
}

const mb_model_info MB_MODEL = {MB_IDENTIFIER, MB_GUID, MB_NVARS, MB_VARS, sizeof(Model), init, step};
