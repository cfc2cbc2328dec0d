/* Wind, native: the variables of fmu_src/wind_fmu.py over the wind kernel
   (plant/c/wind.h; this file is not wind.c because the kernel's wind.c lands in the same
   flat sources/ folder of the FMU). The gust's components are drawn from the seed at initialization and
   fixed afterwards, the phasors the steps turn (mb_wind_sample_stepped) change: the model struct
   holds both, so an FMU state carries them too; a doStep's backup only the phasors (step_fixed). */
#include <stddef.h>
#include <string.h>

#include "Wind_vars.h"
#include "wind.h"

typedef struct {
    mb_wind wind;
    mb_wind_phasors phasors;
} Model;

static int publish(mb_instance *inst, double *r, Model *m, double t, double h)
{
    double speeds[3];
    if (mb_wind_sample_stepped(&m->wind, &m->phasors, t, h, &r[VR_base_pose], &r[VR_platform_wrench], speeds)) {
        mb_error(inst, "InvalidInputError", "base pose input contains NaN or inf");
        return 1;
    }
    r[VR_gust] = speeds[0];
    r[VR_anemometer_speed] = speeds[1];
    r[VR_drag_speed] = speeds[2];
    return 0;
}

static int init(mb_instance *inst, double *r, int *i, void *model, double start_time)
{
    (void)start_time;
    Model *m = model;
    mb_wind_params p;
    memset(&p, 0, sizeof p);   /* the kernel copies p whole into the saved state: no stack bytes in its padding */
    p.mean_speed = r[VR_mean_speed];
    p.turbulence_intensity = r[VR_turbulence_intensity];
    p.length_scale = r[VR_length_scale];
    p.height = r[VR_height];
    p.air_density = r[VR_air_density];
    p.drag_coefficient = r[VR_drag_coefficient];
    p.drag_area = r[VR_drag_area];
    p.moment_arm = r[VR_moment_arm];
    p.direction = r[VR_direction];
    p.anemometer_distance = r[VR_anemometer_distance];
    p.anemometer_upstream = r[VR_anemometer_upstream];
    p.anemometer_time_constant = r[VR_anemometer_time_constant];
    p.coherence_decay = r[VR_coherence_decay];
    p.spectrum = i[VR_spectrum];
    int status = mb_wind_init(&m->wind, &p, (unsigned long long)i[VR_seed]);
    if (status) {
        mb_error(inst, "ValueError", "%s", mb_wind_status_text(status));
        return 1;
    }
    mb_wind_phasors_reset(&m->phasors);
    return publish(inst, r, m, 0.0, 0.0);
}

static int step(mb_instance *inst, double *r, int *i, void *model, double t, double h)
{
    (void)i;
    return publish(inst, r, model, t + h, h);
}

const mb_model_info MB_MODEL = {MB_IDENTIFIER, MB_GUID, MB_NVARS, MB_VARS, sizeof(Model), offsetof(Model, phasors), init, step};
