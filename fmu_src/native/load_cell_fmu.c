/* LoadCell, native: the variables of fmu_src/load_cell_fmu.py over the load-cell kernel
   (plant/c/sensors.h); the model state is the kernel's struct (noise generator included),
   saved by the FMI layer as bytes. leg_force and measured_force are vectors of consecutive
   value references, read and written in place. */
#include "LoadCell_vars.h"
#include "sensors.h"

typedef struct {
    mb_load_cell cell;
} Model;

static int init(mb_instance *inst, double *r, int *i, void *model, double start_time)
{
    (void)inst;
    (void)start_time;
    Model *m = model;
    mb_load_cell_start(&m->cell, (unsigned long long)i[VR_seed], 6, r[VR_resolution], r[VR_noise], &r[VR_leg_force],
                       &r[VR_measured_force]);
    return 0;
}

static int step(mb_instance *inst, double *r, int *i, void *model, double t, double h)
{
    (void)inst;
    (void)t;
    Model *m = model;
    mb_load_cell_sample(&m->cell, 6, r[VR_resolution], r[VR_noise], r[VR_bandwidth], i[VR_delay_steps], h,
                        &r[VR_leg_force], &r[VR_measured_force]);
    return 0;
}

const mb_model_info MB_MODEL = {MB_IDENTIFIER, MB_GUID, MB_NVARS, MB_VARS, sizeof(Model), 0, init, step};
