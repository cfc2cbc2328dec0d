/* HexapodPlant, native: the variables of fmu_src/hexapod_plant_fmu.py over the hexapod
   kernel (plant/c/hexapod.h, mb_hexapod_advance_actuated), with the checks and messages of
   plant/hexapod/ode.py HexapodODE.advance. The inputs (leg_force, base_pose, base_rate,
   base_acc, platform_wrench) and the outputs (leg_length, leg_rate, pose_rate,
   leg_force_actual) are consecutive value references, so the kernel reads and writes the
   variable array in place. Radau needs scipy: the native plant refuses it at
   initialization. With an actuator bandwidth the six motor forces are x[12..17].
   start_equilibrium: the leg_force input starts at the forces that hold the platform still
   (as the Python FMU's holding_forces). */
#include <math.h>
#include <string.h>

#ifndef M_PI
#define M_PI 3.14159265358979323846
#endif

#include "HexapodPlant_vars.h"
#include "hexapod.h"

typedef struct {
    double x[18];        /* pose (6), twist (6), motor forces (6, with a bandwidth) */
    double act[MB_ACTUATOR_NDATA];
    double data[MB_HEXAPOD_NDATA];   /* KERNEL_DATA with the payload errors added at init */
    double bounds[12];   /* (2, 6) lowest and highest leg lengths */
    double max_step, tolerance;   /* tolerance > 0: mb_hexapod_advance_controlled */
    int base_mode, legs, rk4;
} Model;

static const char *const INPUT_NAMES[5] = {"leg forces", "base pose", "base rate", "base acc",
                                           "platform wrench"};
#define RK4_STABLE_RATE_STEP 2.5   /* plant/hexapod/ode.py */

/* Advance over [t0, t0 + h] and fill the outputs; 0, or 1 after mb_error. */
static int advance(mb_instance *inst, double *r, Model *m, double t0, double h)
{
    int substeps = 0, counts[2], status;
    double det = 0.0, *outputs = &r[VR_leg_length];
    if (m->tolerance > 0.0) {
        status = mb_hexapod_advance_controlled(m->tolerance, m->max_step, MB_MAX_SUBSTEPS, BASE_JOINTS,
                                               PLATFORM_JOINTS, m->data, m->act, m->x, &r[VR_leg_force], t0, h,
                                               m->base_mode, m->legs, m->bounds, outputs, &det, counts);
    } else {
        if (mb_substeps(inst, h, m->max_step, &substeps)) return 1;
        status = mb_hexapod_advance_actuated(m->rk4, substeps, BASE_JOINTS, PLATFORM_JOINTS, m->data, m->act,
                                             m->x, &r[VR_leg_force], t0, h, m->base_mode, m->legs, m->bounds,
                                             outputs, &det);
    }
    if (status == MB_HEXAPOD_OK && det >= SINGULAR_RATIO * HOME_DET) {
        memcpy(&r[VR_pose], m->x, 6 * sizeof(double));
        return 0;
    }
    if (status == MB_HEXAPOD_BAD_INPUT) {
        char bad[96];
        mb_nonfinite_rows(5, 6, &r[VR_leg_force], INPUT_NAMES, bad, sizeof bad);
        mb_error(inst, "InvalidInputError", "%s input contains NaN or inf", bad);
    } else if (status == MB_HEXAPOD_WORK) {   /* HexapodODE.advance's words */
        char hb[32], tb[32];
        mb_error(inst, "WorkBoundError", "a step of %s s needs more than %d substeps to keep the pose error per "
                 "substep within tolerance %s: take a larger tolerance or shorter communication steps", mb_repr(h, hb),
                 MB_MAX_SUBSTEPS, mb_repr(m->tolerance, tb));
    } else if (status == MB_HEXAPOD_DIVERGED && substeps == 0) {
        mb_error(inst, "ConvergenceError", "integrator rk4 diverged over [%.6g, %.6g] s (substep error-controlled, "
                 "tolerance %g): the state is no longer finite or bounded", t0, t0 + h, m->tolerance);
    } else if (status == MB_HEXAPOD_DIVERGED) {
        mb_error(inst, "ConvergenceError", "integrator %s diverged over [%.6g, %.6g] s (substep %.3g s): "
                 "the state is no longer finite or bounded", INTEGRATOR_NAMES[m->rk4 ? INTEGRATOR_RK4 : INTEGRATOR_EULER],
                 t0, t0 + h, h / substeps);
    } else if (det < SINGULAR_RATIO * HOME_DET) {
        mb_error(inst, "SingularConfigurationError", "singular pose reached: |det J| is %.2e of home (< %s)",
                 det / HOME_DET, SINGULAR_RATIO_TEXT);
    } else {   /* plant.hexapod.model.check_stroke: the first leg outside its stroke */
        for (int leg = 0; leg < 6; leg++) {
            double l = outputs[leg], low = m->bounds[leg], high = m->bounds[6 + leg];
            if (l < low || l > high || !isfinite(l)) {
                mb_error(inst, "StrokeError", "leg %d length %.6f m outside its stroke [%.6f, %.6f] m", leg + 1, l,
                         low, high);
                break;
            }
        }
    }
    return 1;
}

static int init(mb_instance *inst, double *r, int *i, void *model, double start_time)
{
    (void)start_time;
    Model *m = model;
    int fidelity = i[VR_fidelity], integrator = i[VR_integrator];
    if (fidelity < 0 || fidelity >= N_FIDELITY_NAMES) {
        mb_error(inst, "IndexError", "fidelity %d is not one of 0..%d", fidelity, N_FIDELITY_NAMES - 1);
        return 1;
    }
    m->max_step = r[VR_max_step];
    if (mb_check_integrator(inst, "HexapodPlant", integrator, N_INTEGRATOR_NAMES, INTEGRATOR_RADAU, m->max_step))
        return 1;
    m->rk4 = integrator == INTEGRATOR_RK4;
    m->tolerance = r[VR_tolerance];
    if (m->tolerance > 0.0 && !m->rk4) {   /* plant.hexapod.ode.check_tolerance */
        mb_error(inst, "InvalidInputError", "tolerance %g (error-controlled substeps) needs integrator rk4, got '%s'; "
                 "set tolerance 0 for %s", m->tolerance, INTEGRATOR_NAMES[integrator], INTEGRATOR_NAMES[integrator]);
        return 1;
    }
    m->act[MB_ACT_BANDWIDTH] = r[VR_actuator_bandwidth];
    m->act[MB_ACT_REFLECTED_MASS] = r[VR_reflected_mass];
    m->act[MB_ACT_COULOMB] = r[VR_coulomb_friction];
    m->act[MB_ACT_VISCOUS] = r[VR_viscous_friction];
    m->act[MB_ACT_FRICTION_VELOCITY] = r[VR_friction_velocity];
    m->act[MB_ACT_FORCE_LIMIT] = r[VR_actuator_force_limit];
    double bw = m->act[MB_ACT_BANDWIDTH], rate_step = 2 * M_PI * bw * m->max_step;
    double stable = m->rk4 ? RK4_STABLE_RATE_STEP : 1.0;
    if (m->tolerance == 0.0 && rate_step > stable) {   /* Actuator.check_step; the controlled substeps' lag is exact */
        mb_error(inst, "InvalidInputError", "actuator bandwidth %g Hz is too fast for %s at max_step %g s "
                 "(2 pi f max_step = %.3g); lower max_step below %.3g s", bw,
                 INTEGRATOR_NAMES[integrator], m->max_step, rate_step, stable / (2 * M_PI * bw));
        return 1;
    }
    memcpy(m->data, KERNEL_DATA, sizeof m->data);   /* StewartParams.kernel_data: mass, inertia, ..., com */
    m->data[0] += r[VR_payload_mass_error];
    for (int k = 0; k < 3; k++) {
        m->data[1 + k] += r[VR_payload_inertia_error + k];
        m->data[11 + k] += r[VR_payload_com_error + k];
    }
    /* plant.hexapod.model.body_problems: a mass > 0, moments > 0 and the triangle inequalities */
    const double *I = &m->data[1];
    if (!(m->data[0] > 0) || !(I[0] > 0 && I[1] > 0 && I[2] > 0)
        || !(I[2] <= I[0] + I[1] && I[0] <= I[1] + I[2] && I[1] <= I[0] + I[2])) {
        mb_error(inst, "InvalidInputError", "the payload is no rigid body: mass %g kg, principal moments "
                 "[%g, %g, %g] kg.m2 (a mass and moments > 0, each moment at most the sum of the other two)",
                 m->data[0], I[0], I[1], I[2]);
        return 1;
    }
    m->legs = FIDELITY_LEGS[fidelity];
    m->base_mode = i[VR_moving_base] ? FIDELITY_BASE_MODE[fidelity] : MB_HEXAPOD_BASE_NONE;
    double stroke = r[VR_stroke];
    for (int leg = 0; leg < 6; leg++) {   /* params.home_lengths + (-stroke, stroke) */
        m->bounds[leg] = HOME_LENGTHS[leg] + -stroke;
        m->bounds[6 + leg] = HOME_LENGTHS[leg] + stroke;
    }
    memcpy(m->x, &r[VR_initial_pose], 6 * sizeof(double));
    memset(m->x + 6, 0, 12 * sizeof(double));
    if (i[VR_start_equilibrium]) {   /* holding_forces of the Python FMU: the same kernel call */
        static const double zero[6] = {0.0};
        double M[36], h[6], J[36], ldot[6], length[6], det;
        mb_hexapod_kane_ext(BASE_JOINTS, PLATFORM_JOINTS, m->data, 1, m->x, zero, zero, &r[VR_base_pose],
                            &r[VR_base_rate], &r[VR_base_acc], m->base_mode, m->legs, 0, MB_HEXAPOD_ID, 0.0,
                            &r[VR_platform_wrench], M, h, J, ldot, length, &r[VR_leg_force], &det);
    }
    if (bw > 0)   /* HexapodODE.initial_state: the motor forces start at the held, limited command */
        for (int leg = 0; leg < 6; leg++) {
            double f = r[VR_leg_force + leg], limit = m->act[MB_ACT_FORCE_LIMIT];
            m->x[12 + leg] = limit > 0 ? (f > limit ? limit : (f < -limit ? -limit : f)) : f;
        }
    return advance(inst, r, m, 0.0, 0.0);
}

static int step(mb_instance *inst, double *r, int *i, void *model, double t, double h)
{
    (void)i;
    return advance(inst, r, model, t, h);
}

const mb_model_info MB_MODEL = {MB_IDENTIFIER, MB_GUID, MB_NVARS, MB_VARS, sizeof(Model), 0, init, step};
